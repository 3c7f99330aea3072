//! Seed 001's scenario with the no_std filter of this crate: a unicycle tours
//! 12 beacons at 5 m/s with actuator noise, sees the beacons within 30 m at
//! 1 Hz, and the EKF localises it. Prints the EKF's and dead reckoning's
//! position RMSE. (The truth is simulated with the same generated step plus
//! noise; a deterministic generator keeps the example dependency-free.)
use kinegen_ekf_example::Ekf;
use kinegen_generated::unicycle_ekf as model;

/// Gaussian samples from a 64-bit LCG (Box-Muller): reproducible, no crates.
struct Noise(u64);
impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn gauss(&mut self, s: f64) -> f64 {
        s * (-2.0 * self.uniform().ln()).sqrt() * (std::f64::consts::TAU * self.uniform()).cos()
    }
}

/// Position RMSE of the EKF and of dead reckoning on one simulated tour.
pub fn tour(seed: u64) -> (f64, f64) {
    let beacons: Vec<[f64; 2]> = [
        (4, 0),
        (8, 2),
        (10, 6),
        (8, 10),
        (4, 11),
        (0, 10),
        (-3, 7),
        (-4, 3),
        (-2, -1),
        (2, -3),
        (6, -4),
        (10, -2),
    ]
    .iter()
    .map(|&(x, y)| [5.0 * x as f64, 5.0 * y as f64])
    .collect();
    let (dt, noise, sensor) = (0.05, [0.01, 0.01], [0.05, 0.01]);
    let mut rng = Noise(seed);
    let p = model::PARAM_NOMINAL;
    let (mut truth, mut dr) = ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]);
    let mut ekf = Ekf::new([0.0; 3], [0.05, 0.05, 0.02], noise, sensor);
    let (mut se_ekf, mut se_dr, mut n) = (0.0, 0.0, 0.0);
    let mut next = 0;
    let mut k = 0;
    while next < beacons.len() && k < 20_000 {
        let [bx, by] = beacons[next];
        if (bx - truth[0]).hypot(by - truth[1]) < 3.0 {
            next += 1;
            continue;
        }
        // steer toward the next beacon (the commanded inputs, what the EKF knows)
        let err = (by - truth[1]).atan2(bx - truth[0]) - truth[2];
        let err = err.sin().atan2(err.cos());
        let u = [
            5.0 * (1.0 - 0.8 * err.abs() / std::f64::consts::PI),
            (2.0 * err).clamp(-1.0, 1.0),
        ];
        let w = [rng.gauss(noise[0]), rng.gauss(noise[1])];
        truth = model::step_exact(&truth, &u, &w, &p, dt);
        dr = model::step_exact(&dr, &u, &[0.0; 2], &p, dt);
        ekf.predict(&u, dt);
        k += 1;
        if k % 20 == 0 {
            for lm in &beacons {
                let z = model::obs_landmark(&truth, &u, &p, lm);
                if z[0] < 30.0 {
                    ekf.update(
                        [z[0] + rng.gauss(sensor[0]), z[1] + rng.gauss(sensor[1])],
                        *lm,
                        &u,
                    );
                }
            }
        }
        se_ekf += (ekf.x[0] - truth[0]).powi(2) + (ekf.x[1] - truth[1]).powi(2);
        se_dr += (dr[0] - truth[0]).powi(2) + (dr[1] - truth[1]).powi(2);
        n += 1.0;
    }
    ((se_ekf / n).sqrt(), (se_dr / n).sqrt())
}

fn main() {
    let (ekf, dr) = tour(1);
    println!("beacon tour at 5 m/s, beacons at 1 Hz: EKF position RMSE {ekf:.3} m, dead reckoning {dr:.3} m");
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_filter_beats_dead_reckoning_on_every_seed() {
        for seed in 1..=5 {
            let (ekf, dr) = super::tour(seed);
            assert!(
                ekf < 0.5 * dr,
                "seed {seed}: EKF {ekf} m, dead reckoning {dr} m"
            );
        }
    }
}
