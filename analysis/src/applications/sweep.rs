//! Noise sweep of the EKF (seed 001 Figs 6-7): how much worse localisation gets
//! as one actuator uncertainty grows. For every `[[noise]]` channel and level,
//! the robot of the log is driven again by the log's inputs with that much
//! process noise (the other channels at their spec sigma), the landmarks are
//! observed again at the log's observation times with the sensor's noise, and
//! the filter, told the true noise, localises it; the position error against
//! this simulated truth is averaged over seeds.
use crate::applications::localize::{localize, EkfOptions};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::LandmarkObs;
use crate::model_on_log::run::Run;
use kinegen_model::decl::ObservationRole::RangeBearing;
use kinegen_model::ir::StepForm;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use serde::Serialize;

/// Noise levels of the sweep (seed 001: actuator uncertainty from 0.001 to 0.1).
pub const LEVELS: [f64; 5] = [0.001, 0.003, 0.01, 0.03, 0.1];
/// Simulated repetitions per level.
pub const SEEDS: u64 = 4;

#[derive(Debug, Clone, Serialize)]
pub struct SweepPoint {
    pub noise: String,
    pub sigma: f64,
    /// Mean over the seeds of the EKF's position RMSE against the simulated truth.
    pub position_rmse_m: f64,
    pub heading_rmse_rad: f64,
    /// Mean over the seeds of the mean NEES (3 dof: 3 when consistent).
    pub nees_mean: f64,
}

fn normal(s: f64) -> Normal<f64> {
    Normal::new(0.0, s.max(0.0)).expect("a finite, non-negative sigma")
}

/// One simulated run: the log's inputs, observation times and landmarks, with
/// process noise `sigmas` (one per `[[noise]]`) and the sensor's noise.
fn resimulate(r: &Runner, run: &Run, sigmas: &[f64], seed: u64) -> Run {
    let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
    let step = r.ir.step(StepForm::Exact).value;
    let h =
        r.ir.observation_kernels(RangeBearing)
            .map(|o| o.value)
            .expect("checked by the caller");
    // the sigmas the filter weighs the sightings with
    let sig = crate::model_on_log::landmarks::sigma(r);
    let mut x = run.start_pose();
    let mut truth = vec![x];
    for k in 0..run.steps() {
        let w: Vec<f64> = sigmas.iter().map(|s| normal(*s).sample(&mut rng)).collect();
        let w = if w.is_empty() { vec![0.0] } else { w };
        let next = r.eval(
            step,
            &Runner::step_args(step, &x, &run.u[k], &r.p, &[run.dt[k]], &w),
        );
        x = [next[0], next[1], next[2]];
        truth.push(x);
    }
    // observed from the pose at the end of the step the filter updates in
    let landmarks = run
        .landmarks
        .iter()
        .map(|z| {
            let k = run.t.partition_point(|t| *t < z.t).min(run.t.len() - 1);
            let k = k.max(1);
            let pred = r.eval(
                h,
                &Runner::obs_args(h, &truth[k], &run.u[k - 1], &r.p, &[z.xl, z.yl]),
            );
            LandmarkObs {
                range: pred[0] + normal(sig[0]).sample(&mut rng),
                bearing: crate::logs::log::wrap(pred[1] + normal(sig[1]).sample(&mut rng)),
                ..z.clone()
            }
        })
        .collect();
    Run {
        gt: Some(truth.into()),
        landmarks,
        ..run.clone()
    }
}

/// Why the sweep cannot run.
#[derive(Debug, Clone, thiserror::Error)]
pub enum SweepError {
    #[error("model `{0}` declares no [[noise]]: there is nothing to sweep")]
    NoNoise(String),
    #[error("{0}: the sweep re-observes the log's landmark observations, and it has none")]
    NoSightings(String),
    #[error(transparent)]
    Filter(#[from] crate::applications::localize::LocalizeError),
}

/// The sweep over every `[[noise]]` channel and level in `levels`.
pub fn sweep(
    r: &Runner,
    run: &Run,
    levels: &[f64],
    base: &EkfOptions,
) -> Result<Vec<SweepPoint>, SweepError> {
    if r.ir.noise.is_empty() {
        return Err(SweepError::NoNoise(r.ir.name.clone()));
    }
    if run.landmarks.is_empty() {
        return Err(SweepError::NoSightings(run.path.clone()));
    }
    let spec_sigma: Vec<f64> =
        r.ir.noise
            .iter()
            .map(|n| {
                base.noise_sigma
                    .iter()
                    .find(|(m, _)| *m == n.name)
                    .map_or(n.sigma, |(_, s)| *s)
            })
            .collect();
    let cases: Vec<(usize, usize)> = (0..r.ir.noise.len())
        .flat_map(|c| (0..levels.len()).map(move |l| (c, l)))
        .collect();
    cases
        .par_iter()
        .map(|&(c, l)| {
            let mut sigmas = spec_sigma.clone();
            sigmas[c] = levels[l];
            let o = EkfOptions {
                noise_sigma: r
                    .ir
                    .noise
                    .iter()
                    .map(|n| n.name.clone())
                    .zip(sigmas.iter().copied())
                    .collect(),
                smooth: false,
                ..base.clone()
            };
            let (mut pos, mut head, mut nees) = (0.0, 0.0, 0.0);
            for s in 0..SEEDS {
                let sim = resimulate(r, run, &sigmas, 1000 * (c as u64 + 1) + 100 * l as u64 + s);
                let loc = localize(r, &sim, &o)?;
                let g = sim.gt.as_ref().unwrap();
                let n = g.len() as f64;
                pos += (loc
                    .track
                    .iter()
                    .zip(g)
                    .map(|(x, g)| (x[0] - g[0]).powi(2) + (x[1] - g[1]).powi(2))
                    .sum::<f64>()
                    / n)
                    .sqrt();
                head += (loc
                    .track
                    .iter()
                    .zip(g)
                    .map(|(x, g)| crate::logs::log::wrap(x[2] - g[2]).powi(2))
                    .sum::<f64>()
                    / n)
                    .sqrt();
                nees += loc.nees.iter().map(|n| n.pose).sum::<f64>() / loc.nees.len().max(1) as f64;
            }
            let m = SEEDS as f64;
            Ok(SweepPoint {
                noise: r.ir.noise[c].name.clone(),
                sigma: levels[l],
                position_rmse_m: pos / m,
                heading_rmse_rad: head / m,
                nees_mean: nees / m,
            })
        })
        .collect()
}
