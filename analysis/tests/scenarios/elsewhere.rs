//! A simulator written here, not kinegen's, for clean logs as a user's own
//! simulator would make them (issue #35.2 as its reporter made it): wheel
//! speeds and steering that wander smoothly, the pose integrated in exact
//! arcs at 1 kHz, sampled at 50 Hz, motion capture with 1 mm and 2 mrad of
//! white noise.
use rand::{rngs::SmallRng, Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use std::f64::consts::TAU;

/// A smooth random signal: a base drawn from `base` (none: 0) plus four
/// sines of random frequency (drawn from `hz`), phase and amplitude
/// (drawn from `amplitude`), one draw per run.
fn wander(
    rng: &mut SmallRng,
    base: Option<(f64, f64)>,
    (amplitude, hz): ((f64, f64), (f64, f64)),
) -> impl Fn(f64) -> f64 {
    let base = base.map_or(0.0, |(lo, hi)| rng.gen_range(lo..hi));
    let parts: Vec<[f64; 3]> = (0..4)
        .map(|_| {
            let f = rng.gen_range(hz.0..hz.1);
            [
                f,
                rng.gen_range(0.0..TAU),
                rng.gen_range(amplitude.0..amplitude.1),
            ]
        })
        .collect();
    move |t: f64| {
        base + (parts.iter())
            .map(|[f, ph, a]| a * (TAU * f * t + ph).sin())
            .sum::<f64>()
    }
}

/// Drive `seconds` at 50 Hz from the origin: `step(wheels, t, dt)` moves
/// the wheel angles `wheels` over a millisecond and gives the body's (v,
/// omega) then; `row(wheels, t)` the logged inputs, as text. Writes
/// `header` and one row every 20 ms.
fn drive(
    path: &std::path::Path,
    (rng, header, seconds): (&mut SmallRng, &str, usize),
    mut step: impl FnMut(&mut [f64; 2], f64, f64) -> (f64, f64),
    row: impl Fn(&[f64; 2], f64) -> String,
) {
    let (pos, head) = (
        Normal::new(0.0, 0.001).unwrap(),
        Normal::new(0.0, 0.002).unwrap(),
    );
    let (mut x, mut y, mut th, mut t) = (0.0f64, 0.0f64, 0.0f64, 0.0);
    let mut wheels = [0.0; 2];
    let dt = 0.001;
    let mut text = format!("{header},gt_x,gt_y,gt_theta\n");
    for _ in 0..=seconds * 50 {
        text += &format!(
            "{},{:.6},{:.6},{:.6}\n",
            row(&wheels, t),
            x + pos.sample(rng),
            y + pos.sample(rng),
            th + head.sample(rng)
        );
        for _ in 0..20 {
            let (v, w) = step(&mut wheels, t, dt);
            x += v / w * ((th + w * dt).sin() - th.sin());
            y -= v / w * ((th + w * dt).cos() - th.cos());
            (th, t) = (th + w * dt, t + dt);
        }
    }
    std::fs::write(path, text).unwrap();
}

/// spec/diff_drive.toml at its nominal values for `seconds`, the
/// encoders' cumulative counts floored to whole counts.
pub fn diff_drive(path: &std::path::Path, seed: u64, seconds: usize) {
    let mut rng = SmallRng::seed_from_u64(seed);
    let (r, b, counts_per_rev) = (0.042, 0.2, 64.0 * 43.7);
    let right = wander(&mut rng, Some((3.0, 6.0)), ((1.0, 4.0), (0.02, 0.2)));
    let left = wander(&mut rng, Some((3.0, 6.0)), ((1.0, 4.0), (0.02, 0.2)));
    let count = |a: f64| (a / TAU * counts_per_rev).floor();
    drive(
        path,
        (&mut rng, "t,enc_r,enc_l", seconds),
        |wheels, t, dt| {
            let (wr, wl) = (right(t), left(t));
            (wheels[0], wheels[1]) = (wheels[0] + wr * dt, wheels[1] + wl * dt);
            (r * (wr + wl) / 2.0, r * (wr - wl) / b)
        },
        |wheels, t| format!("{t:.4},{},{}", count(wheels[0]), count(wheels[1])),
    );
}

/// spec/benchmarks/optiodom/tricycle.toml at its nominal values for 200 s, the
/// drive wheel's angle floored to a 2048-count encoder, the steering
/// rounded to a `steering_steps`-step encoder.
pub fn tricycle(path: &std::path::Path, seed: u64, steering_steps: f64) {
    let mut rng = SmallRng::seed_from_u64(seed);
    let (r, l) = (0.0325, 0.15);
    let wheel = wander(&mut rng, Some((4.0, 8.0)), ((0.5, 2.0), (0.02, 0.2)));
    // a steering that swings at most 0.1 Hz (see the rounding test)
    let steer = wander(&mut rng, None, ((0.1, 0.3), (0.01, 0.1)));
    let q = TAU / steering_steps;
    drive(
        path,
        (&mut rng, "t,phi,alpha", 200),
        |wheels, t, dt| {
            let (w, a) = (wheel(t), steer(t));
            wheels[0] += w * dt;
            (r * w * a.cos(), r * w * a.sin() / l)
        },
        |wheels, t| {
            let phi = (wheels[0] / TAU * 2048.0).floor() * TAU / 2048.0;
            format!("{t:.4},{phi:.9},{:.9}", (steer(t) / q).round() * q)
        },
    );
}
