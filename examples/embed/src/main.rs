//! Dead-reckoning with a generated kernel, the way robot firmware would use it:
//! plain arrays in and out, no allocation, no dependency but `kinegen-generated`.
use kinegen_generated::diff_drive;

fn main() {
    // the calibrated values, by name (here the nominal ones with a measured
    // wheelbase), as the kernels' `p` array
    let params = diff_drive::Params {
        b: 0.205,
        ..diff_drive::Params::NOMINAL
    };
    let p = params.to_array();
    let w = [0.0, 0.0]; // no process noise when dead-reckoning
    let dt = 0.05;
    let mut pose = [0.0, 0.0, 0.0];
    // One second straight at ~0.3 m/s, then one second turning left in place.
    let counts_per_s = 0.3 / (params.r_r * 2.0 * core::f64::consts::PI / (64.0 * 43.7));
    for k in 0..40 {
        let u = if k < 20 {
            [counts_per_s, counts_per_s]
        } else {
            [counts_per_s, -counts_per_s]
        };
        pose = diff_drive::step_exact(&pose, &u, &w, &p, dt);
    }
    let jac = diff_drive::step_exact_jac_p(&pose, &[counts_per_s, counts_per_s], &w, &p, dt);
    // The wheel rates that drive 0.3 m straight ahead in one second:
    let rates = diff_drive::inverse_increment(&[0.3, 0.0, 0.0], 1.0, &p);
    println!(
        "pose after 2 s: x = {:.4} m, y = {:.4} m, theta = {:.4} rad",
        pose[0], pose[1], pose[2]
    );
    println!("d(x_next)/d(r_r) = {:.6}", jac[0][0]);
    println!(
        "encoder rates for 0.3 m in 1 s: right {:.1}, left {:.1} counts/s",
        rates[0], rates[1]
    );
}
