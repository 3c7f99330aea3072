//! The seeds' own calibration methods, so users can compare them with `fit`'s
//! Levenberg-Marquardt:
//!
//! * [`gradient_descent`]: seed 000 eq. 19-21, gradient descent on the mean squared
//!   yaw-rate error V(lambda) = 1/(K-1) sum (omega_k - omega_hat_k(lambda))^2.
//! * [`ekf`]: seed 000 eq. 22-26, an extended Kalman filter over constant
//!   parameters with the measurement variance inflated by mu^2 (eq. 26).
//! * [`umbmark`]: Borenstein & Feng's UMBMark (used by seed 004): Ed (wheel diameter
//!   ratio) and Eb (wheelbase) from the return-position errors of clockwise and
//!   counter-clockwise square runs (differential drive).
//!
//! The yaw-rate methods use the gyro column when the log has one; otherwise the
//! yaw rate measured by the ground-truth heading, (theta_{k+1} - theta_k)/dt: the
//! reference heading that seed 000 takes from its laser gyro.
use crate::logs::log::wrap;
use crate::model_on_log::deadreckon;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::decl::ObservationRole::YawRate;
use nalgebra::{DMatrix, DVector};

/// Measured yaw rate per step (gyro row k+1, or ground-truth heading rate).
fn yaw_rates(run: &Run) -> Option<Vec<f64>> {
    if let Some(g) = &run.gyro {
        return Some(g[1..].to_vec());
    }
    let gt = run.gt.as_ref()?;
    Some(
        (0..run.steps())
            .map(|k| wrap(gt[k + 1][2] - gt[k][2]) / run.dt[k])
            .collect(),
    )
}

/// Model yaw rate per step and its gradient w.r.t. the free parameters.
fn predicted(r: &Runner, p: &[f64], run: &Run, free: &[usize]) -> (Vec<f64>, Vec<Vec<f64>>) {
    let h =
        r.ir.observation_kernels(YawRate)
            .map(|o| o.value)
            .unwrap_or(r.ir.twist());
    let jp = r.ir.observation_kernels(YawRate).and_then(|o| o.jac_p);
    let tw = r.ir.twist();
    let mut w = Vec::new();
    let mut g = Vec::new();
    let x = [0.0; 3];
    for k in 0..run.steps() {
        let u = &run.u[k];
        match jp {
            Some(jp) => {
                w.push(r.eval(h, &Runner::obs_args(h, &x, u, p, &[]))[0]);
                let d = r.eval(jp, &Runner::obs_args(jp, &x, u, p, &[]));
                g.push(free.iter().map(|&i| d[i]).collect());
            }
            None => {
                // no gyro model: differentiate the twist's yaw rate numerically
                let w0 = r.eval(tw, &[u, p])[2];
                w.push(w0);
                g.push(
                    free.iter()
                        .map(|&i| {
                            let mut q = p.to_vec();
                            let hh = 1e-6 * q[i].abs().max(1e-6);
                            q[i] += hh;
                            (r.eval(tw, &[u, &q])[2] - w0) / hh
                        })
                        .collect(),
                );
            }
        }
    }
    (w, g)
}

pub struct SeedFit {
    pub p: Vec<f64>,
    pub std: Vec<f64>,
    pub iterations: usize,
    pub cost_before: f64,
    pub cost_after: f64,
}

fn gyro_cost(
    r: &Runner,
    p: &[f64],
    runs: &[Run],
    free: &[usize],
) -> (f64, DVector<f64>, DMatrix<f64>) {
    let (mut v, mut n) = (0.0, 0usize);
    let m = free.len();
    let mut grad = DVector::zeros(m);
    let mut gn = DMatrix::zeros(m, m);
    for run in runs {
        let Some(meas) = yaw_rates(run) else { continue };
        let (w, g) = predicted(r, p, run, free);
        for k in 0..w.len() {
            let e = w[k] - meas[k];
            v += e * e;
            n += 1;
            let gk = DVector::from_vec(g[k].clone());
            grad += &gk * (2.0 * e);
            gn += &gk * gk.transpose() * 2.0;
        }
    }
    let d = (n.max(2) - 1) as f64;
    (v / d, grad / d, gn / d)
}

/// Parameter directions the yaw rate cannot see at `p`: eigenvectors of the
/// Gauss-Newton Hessian of the yaw-rate cost (parameters scaled by their size)
/// with an eigenvalue below 1e-9 of the largest. For seed 000's robot the yaw rate
/// is blind to a common scale of every length (the twist's translation scales
/// with it, omega does not), which is why eq. 19-26 cannot fix that scale and
/// pose measurements are needed. Each direction is described by its largest
/// components, e.g. "e1 +0.29, r1 +0.29, ...".
pub fn yaw_rate_blind_directions(r: &Runner, p: &[f64], runs: &[Run]) -> Vec<String> {
    let free = r.free.clone();
    let mut out = Vec::new();
    for v in blind_basis(r, p, runs).0 {
        let mut comps: Vec<(usize, f64)> = v
            .iter()
            .copied()
            .enumerate()
            .filter(|(_, c)| c.abs() > 0.05)
            .collect();
        comps.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
        let sign = if comps.first().is_some_and(|c| c.1 < 0.0) {
            -1.0
        } else {
            1.0
        };
        out.push(
            comps
                .iter()
                .take(6)
                .map(|(a, c)| format!("{} {:+.2}", r.names[free[*a]], sign * c))
                .collect::<Vec<_>>()
                .join(", "),
        );
    }
    out
}

/// Unit vectors (in parameters scaled by [`prior_std`], over the free
/// parameters) spanning what the yaw rate cannot see at `p`, and the scales.
fn blind_basis(r: &Runner, p: &[f64], runs: &[Run]) -> (Vec<DVector<f64>>, DVector<f64>) {
    let free = &r.free;
    let scale = DVector::from_iterator(free.len(), free.iter().map(|&i| prior_std(r, i) * 10.0));
    if free.is_empty() {
        return (vec![], scale);
    }
    let (_, _, h) = gyro_cost(r, p, runs, free);
    let hs = DMatrix::from_fn(free.len(), free.len(), |a, b| {
        h[(a, b)] * scale[a] * scale[b]
    });
    let Some(eig) = crate::model_on_log::linalg::symmetric_eigen(hs) else {
        return (vec![], scale);
    };
    let lmax = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
    let basis = (0..free.len())
        .filter(|&k| lmax > 0.0 && eig.eigenvalues[k] < 1e-9 * lmax)
        .map(|k| eig.eigenvectors.column(k).into_owned())
        .collect();
    (basis, scale)
}

/// `p` with its move away from `from` taken out of the directions the yaw rate
/// cannot see (at `from`): gradient descent and the EKF would otherwise drift
/// along them (round-off, nonlinearity, prior correlations), which no data
/// supports and which makes held-out runs worse. Like LM, they keep such
/// directions at their starting values.
fn without_blind_moves(r: &Runner, from: &[f64], p: Vec<f64>, runs: &[Run]) -> Vec<f64> {
    let (basis, scale) = blind_basis(r, from, runs);
    let mut d = DVector::from_iterator(
        r.free.len(),
        r.free
            .iter()
            .enumerate()
            .map(|(k, &i)| (p[i] - from[i]) / scale[k]),
    );
    for v in &basis {
        d -= v * v.dot(&d);
    }
    let mut out = p;
    for (k, &i) in r.free.iter().enumerate() {
        out[i] = from[i] + d[k] * scale[k];
    }
    out
}

/// Why a seed paper's calibration cannot run on the runs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SeedError {
    #[error("no yaw-rate measurement (gyro_z or ground-truth heading) in the logs")]
    NoYawRate,
    #[error("UMBMark needs a differential drive with parameters r_r, r_l and b")]
    NotDifferential,
    #[error("{0}: UMBMark needs ground truth")]
    NoGroundTruth(String),
    #[error("{path}: UMBMark needs a bidirectional square test (one square of side --side per run, cw and ccw runs); {why}")]
    NotASquare { path: String, why: String },
    #[error("UMBMark needs clockwise and counter-clockwise square runs (got {cw} cw, {ccw} ccw)")]
    OneDirection { cw: usize, ccw: usize },
}

/// Seed 000 eq. 21: lambda_n = lambda_{n-1} - eta dV/dlambda. eta is fixed, set
/// once to 1/L with L the largest eigenvalue of the Gauss-Newton Hessian of V at
/// the start (the classical stable step for gradient descent).
pub fn gradient_descent(r: &Runner, runs: &[Run], max_iter: usize) -> Result<SeedFit, SeedError> {
    let free = r.free.clone();
    let mut p = r.p.clone();
    let (v0, _, h0) = gyro_cost(r, &p, runs, &free);
    if !v0.is_finite() {
        return Err(SeedError::NoYawRate);
    }
    let lmax = h0.symmetric_eigenvalues().max().max(1e-300);
    let eta = 1.0 / lmax;
    let mut v = v0;
    let mut it = 0;
    for i in 0..max_iter {
        it = i + 1;
        let (vc, g, _) = gyro_cost(r, &p, runs, &free);
        v = vc;
        if g.norm() * eta < 1e-12 * p.iter().map(|x| x.abs()).fold(0.0, f64::max) {
            break;
        }
        for (k, &j) in free.iter().enumerate() {
            p[j] -= eta * g[k];
        }
    }
    let p = without_blind_moves(r, &r.p, p, runs);
    let (vf, _, h) = gyro_cost(r, &p, runs, &free);
    let n: usize = runs.iter().map(|x| x.steps()).sum();
    let cov = h
        .pseudo_inverse(1e-12)
        .unwrap_or_else(|_| DMatrix::zeros(free.len(), free.len()))
        * (2.0 * vf / n as f64);
    let _ = v;
    Ok(SeedFit {
        std: (0..free.len())
            .map(|k| cov[(k, k)].max(0.0).sqrt())
            .collect(),
        p,
        iterations: it,
        cost_before: v0,
        cost_after: vf,
    })
}

/// Prior standard deviation of a parameter for the EKF: 10% of its nominal value;
/// for a parameter whose nominal is 0 (an axis on the centre line), 10% of the
/// typical size of the parameters with the same unit (seed 000 used 5 cm for all
/// its lengths of 5-38 cm, eq. 27), so it is not frozen at 0.
fn prior_std(r: &Runner, i: usize) -> f64 {
    let own = 0.1 * r.p[i].abs();
    if own > 0.0 {
        return own;
    }
    let unit = &r
        .ir
        .params
        .iter()
        .find(|p| p.name == r.names[i])
        .map(|p| p.unit.clone())
        .unwrap_or_default();
    let mut same: Vec<f64> =
        r.ir.params
            .iter()
            .filter(|p| !p.constant && &p.unit == unit && p.nominal != 0.0)
            .map(|p| p.nominal.abs())
            .collect();
    same.sort_by(f64::total_cmp);
    0.1 * same.get(same.len() / 2).copied().unwrap_or(0.01)
}

/// Seed 000 eq. 22-26: lambda_k = lambda_{k-1}; omega_k = h_k(lambda) + v_k, with
/// sigma_v^2 = sigma_omega^2 + mu^2. P0 = diag(prior_std^2) (10% of each value;
/// seed 000 used (5 cm)^2 for parameters of about 5-38 cm).
#[allow(clippy::needless_range_loop)] // k indexes several per-row arrays of the run together
pub fn ekf(r: &Runner, runs: &[Run], sigma_omega: f64, mu: f64) -> Result<SeedFit, SeedError> {
    let free = r.free.clone();
    let m = free.len();
    let mut p = r.p.clone();
    let mut cov = DMatrix::from_diagonal(&DVector::from_iterator(
        m,
        free.iter().map(|&i| prior_std(r, i).powi(2)),
    ));
    let sv2 = sigma_omega * sigma_omega + mu * mu;
    let (v0, _, _) = gyro_cost(r, &p, runs, &free);
    let mut steps = 0;
    for run in runs {
        let Some(meas) = yaw_rates(run) else { continue };
        for k in 0..run.steps() {
            let one = Run {
                name: String::new(),
                path: String::new(),
                t: vec![0.0, run.dt[k]].into(),
                dt: vec![run.dt[k]].into(),
                u: std::iter::once(&run.u[k]).collect(),
                gt: None,
                gyro: None,
                landmarks: Vec::new(),
                rate_inputs: Vec::new(),
                swing: run.swing.as_ref().map(|s| std::iter::once(&s[k]).collect()),
                first_line: run.first_line + k,
            };
            let (w, g) = predicted(r, &p, &one, &free);
            let hgrad = DVector::from_vec(g[0].clone());
            let s = (hgrad.transpose() * &cov * &hgrad)[(0, 0)] + sv2;
            let gain = &cov * &hgrad / s; // eq. 25
            let innov = meas[k] - w[0];
            for (a, &i) in free.iter().enumerate() {
                p[i] += gain[a] * innov; // eq. 24
            }
            cov = (DMatrix::identity(m, m) - &gain * hgrad.transpose()) * &cov; // eq. 24
            steps += 1;
        }
    }
    if steps == 0 {
        return Err(SeedError::NoYawRate);
    }
    let p = without_blind_moves(r, &r.p, p, runs);
    let (vf, _, _) = gyro_cost(r, &p, runs, &free);
    Ok(SeedFit {
        std: (0..m).map(|k| cov[(k, k)].max(0.0).sqrt()).collect(),
        p,
        iterations: steps,
        cost_before: v0,
        cost_after: vf,
    })
}

/// UMBMark's formulas hold only for a closed square of the given side driven
/// once in one direction: four 90 degree turns (a full turn in all), a path of
/// four sides, and a return to the start. Anything else (a circle, a free path,
/// a wrong `--side`) would give corrections that look precise and mean nothing.
fn square_check(run: &Run, gt: &[[f64; 3]], side: f64) -> Result<(), SeedError> {
    let turn = (gt.last().unwrap()[2] - gt[0][2]).abs().to_degrees();
    // every n/200-th row, so measurement noise does not add length
    let every = (gt.len() / 200).max(1);
    let length = crate::model_on_log::metrics::path_length(gt.iter().map(|p| (p[0], p[1])), every);
    let pts: Vec<&[f64; 3]> = gt.iter().step_by(every).collect();
    // a square's sides are driven at four headings 90 degrees apart; a circle
    // or a free path spreads its heading evenly (20 degrees each side of the
    // four: 44% of a circle's length)
    let on_a_side: f64 = pts
        .windows(2)
        .filter(|w| {
            let off = (w[0][2] - gt[0][2]).to_degrees().rem_euclid(90.0);
            off.min(90.0 - off) < 20.0
        })
        .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
        .sum();
    let (a, b) = (gt[0], gt.last().unwrap());
    let gap = (b[0] - a[0]).hypot(b[1] - a[1]);
    let problem = if (turn - 360.0).abs() > 45.0 {
        Some(format!("it turns {turn:.0} degrees in all, not 360"))
    } else if (length - 4.0 * side).abs() > 0.2 * 4.0 * side {
        Some(format!(
            "its path is {length:.2} m long, not about 4 x --side {side} m (a square of side {:.2} m? say so with --side)",
            length / 4.0
        ))
    } else if on_a_side < 0.7 * length {
        Some(format!(
            "only {:.0}% of its path runs along the four sides of a square",
            100.0 * on_a_side / length.max(1e-12)
        ))
    } else if gap > side {
        Some(format!("it ends {gap:.2} m from where it started"))
    } else {
        None
    };
    match problem {
        Some(why) => Err(SeedError::NotASquare {
            path: run.path.clone(),
            why,
        }),
        None => Ok(()),
    }
}

/// Result of UMBMark: corrected parameters and the intermediate quantities.
pub struct Umbmark {
    pub p: Vec<f64>,
    pub ed: f64,
    pub eb: f64,
    pub alpha_deg: f64,
    pub beta_deg: f64,
    pub cw_runs: usize,
    pub ccw_runs: usize,
}

/// UMBMark (Borenstein & Feng): for each run, the return-position error
/// eps = true end - odometry end in the start frame; x centres of gravity of the
/// clockwise and counter-clockwise runs give alpha = (x_cw + x_ccw)/(-4L) and
/// beta = (x_cw - x_ccw)/(-4L); R = (L/2)/sin(beta/2); Ed = (R + b/2)/(R - b/2);
/// Eb = 90 deg/(90 deg - alpha). Corrections: b' = Eb b, r_l' = 2/(Ed + 1) r_l,
/// r_r' = 2/(1/Ed + 1) r_r. Needs parameters named r_r, r_l and b.
pub fn umbmark(r: &Runner, runs: &[Run], side: f64) -> Result<Umbmark, SeedError> {
    let (ir_, il, ib) = match (
        r.param_index("r_r"),
        r.param_index("r_l"),
        r.param_index("b"),
    ) {
        (Some(a), Some(b), Some(c)) => (a, b, c),
        _ => return Err(SeedError::NotDifferential),
    };
    let (mut cw, mut ccw) = (Vec::new(), Vec::new());
    for run in runs {
        let gt = run
            .gt
            .as_ref()
            .ok_or_else(|| SeedError::NoGroundTruth(run.name.clone()))?;
        square_check(run, gt, side)?;
        let start = run.start_pose();
        let tr = deadreckon::run(r, &r.p, run, false);
        let (e_true, e_odo) = (gt.last().unwrap(), tr.pose.last().unwrap());
        let (c, s) = (start[2].cos(), start[2].sin());
        let rot = |v: [f64; 3]| {
            [
                c * (v[0] - start[0]) + s * (v[1] - start[1]),
                -s * (v[0] - start[0]) + c * (v[1] - start[1]),
            ]
        };
        let (a, b) = (rot(*e_true), rot(*e_odo));
        let eps = [a[0] - b[0], a[1] - b[1]];
        let turn = gt.last().unwrap()[2] - gt[0][2];
        if turn > 0.0 {
            ccw.push(eps);
        } else {
            cw.push(eps);
        }
    }
    if cw.is_empty() || ccw.is_empty() {
        return Err(SeedError::OneDirection {
            cw: cw.len(),
            ccw: ccw.len(),
        });
    }
    let mean = |v: &[[f64; 2]]| v.iter().map(|e| e[0]).sum::<f64>() / v.len() as f64;
    let (xcw, xccw) = (mean(&cw), mean(&ccw));
    let alpha = (xcw + xccw) / (-4.0 * side);
    let beta = (xcw - xccw) / (-4.0 * side);
    let b = r.p[ib];
    let radius = (side / 2.0) / (beta / 2.0).sin();
    let ed = (radius + b / 2.0) / (radius - b / 2.0);
    let eb = 90.0 / (90.0 - alpha.to_degrees());
    let mut p = r.p.clone();
    p[ib] = eb * b;
    p[il] = 2.0 / (ed + 1.0) * r.p[il];
    p[ir_] = 2.0 / (1.0 / ed + 1.0) * r.p[ir_];
    Ok(Umbmark {
        p,
        ed,
        eb,
        alpha_deg: alpha.to_degrees(),
        beta_deg: beta.to_degrees(),
        cw_runs: cw.len(),
        ccw_runs: ccw.len(),
    })
}
