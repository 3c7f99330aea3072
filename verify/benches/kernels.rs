//! `cargo bench -p kinegen-verify --bench kernels`
//!
//! Nanoseconds per call of the generated kernels that calibration, the EKF and
//! least-squares kinematics spend their time in (issue #13's table), on 300,000
//! random inputs, median of 7 repetitions. The sum of the outputs is printed so
//! that two builds (or a peer's code on the same inputs) can be checked to agree.
use kinegen_generated::{diff_drive, omni_caster, unicycle_ekf};
use rand::{Rng, SeedableRng};
use std::hint::black_box;
use std::time::Instant;

const N: usize = 300_000;
const REPS: usize = 7;

fn uniform<const K: usize>(rng: &mut rand::rngs::SmallRng, lo: f64, hi: f64) -> [f64; K] {
    std::array::from_fn(|_| rng.gen_range(lo..hi))
}

/// Median ns per call of `f` over the inputs, and the sum of its outputs.
fn time<I>(label: &str, inputs: &[I], f: impl Fn(&I) -> f64) {
    let mut per_call = Vec::new();
    let mut check = 0.0;
    for _ in 0..REPS {
        let t = Instant::now();
        let mut s = 0.0;
        for x in inputs {
            s += f(black_box(x));
        }
        per_call.push(t.elapsed().as_secs_f64() * 1e9 / inputs.len() as f64);
        check = black_box(s);
    }
    per_call.sort_by(f64::total_cmp);
    println!(
        "{label:<48} {:>9.1} ns/call   (checksum {check:.12e})",
        per_call[REPS / 2]
    );
}

fn main() {
    let mut rng = rand::rngs::SmallRng::seed_from_u64(13);
    // diff_drive: wheel rates up to +-20 rad/s, so omega dt covers both sides of
    // the series switch
    let dd: Vec<_> = (0..N)
        .map(|_| {
            let mut p = diff_drive::PARAM_NOMINAL;
            for v in &mut p {
                *v *= rng.gen_range(0.9..1.1);
            }
            (
                uniform::<3>(&mut rng, -2.0, 2.0),
                uniform::<2>(&mut rng, -20.0, 20.0),
                uniform::<2>(&mut rng, -0.01, 0.01),
                p,
                rng.gen_range(0.005..0.05),
            )
        })
        .collect();
    time(
        "diff_drive step_exact + jac_x + jac_p",
        &dd,
        |(x, u, w, p, dt)| {
            let a = diff_drive::step_exact(x, u, w, p, *dt);
            let b = diff_drive::step_exact_jac_x(x, u, w, p, *dt);
            let c = diff_drive::step_exact_jac_p(x, u, w, p, *dt);
            a[0] + b[0][2] + c[1][0]
        },
    );
    let lm: Vec<_> = (0..N)
        .map(|_| {
            (
                uniform::<3>(&mut rng, -5.0, 5.0),
                uniform::<2>(&mut rng, -1.0, 1.0),
                unicycle_ekf::PARAM_NOMINAL,
                uniform::<2>(&mut rng, -10.0, 10.0),
            )
        })
        .collect();
    time("unicycle_ekf obs_landmark + jac_x", &lm, |(x, u, p, l)| {
        let a = unicycle_ekf::obs_landmark(x, u, p, l);
        let b = unicycle_ekf::obs_landmark_jac_x(x, u, p, l);
        a[0] + b[1][2]
    });
    let oc: Vec<_> = (0..N)
        .map(|_| {
            let mut u = uniform::<9>(&mut rng, -3.0, 3.0);
            // caster angles (absolute inputs) anywhere on the circle
            for a in &mut u[6..] {
                *a = rng.gen_range(-3.1..3.1);
            }
            (
                uniform::<3>(&mut rng, -2.0, 2.0),
                u,
                uniform::<3>(&mut rng, -0.01, 0.01),
                omni_caster::PARAM_NOMINAL,
                rng.gen_range(0.005..0.05),
            )
        })
        .collect();
    time(
        "omni_caster twist (least squares)",
        &oc,
        |(_, u, _, p, _)| omni_caster::twist(u, p)[2],
    );
    time("omni_caster step_exact + jac_p", &oc, |(x, u, w, p, dt)| {
        let a = omni_caster::step_exact(x, u, w, p, *dt);
        let c = omni_caster::step_exact_jac_p(x, u, w, p, *dt);
        a[0] + c[1][0]
    });
}
