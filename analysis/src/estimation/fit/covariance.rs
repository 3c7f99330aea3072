//! The estimate's uncertainty: the sandwich over windows, the inverse of
//! the information on its determined subspace, correlations, and the
//! variance components of the residual kinds.
use super::{residuals, run_residuals, FitOptions, FitResult};
use crate::model_on_log::linalg;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// Replace a window fit's standard deviations and correlations by the sandwich
/// H^-1 S H^-1, with S summing each window's score J_i^T r_i outer products and
/// the cross terms of neighbouring windows. Consecutive windows share a measured
/// pose (the end of one is the start of the next), so their residuals are
/// negatively correlated (lag 1) and plain least squares overstates the
/// uncertainty (seen: 2-3x over 30 simulated seeds); farther windows share
/// nothing. Directions already found unidentified stay so.
pub(super) fn sandwich(r: &Runner, windows: &[Run], o: &FitOptions, res: &mut FitResult) {
    let free = &res.free;
    let m = free.len();
    if m == 0 || windows.len() < 4 * m {
        return; // too few windows to estimate S: keep least squares
    }
    // each window's score J_i^T r_i and information J_i^T J_i, from one pass
    let (scores, infos): (Vec<DVector<f64>>, Vec<DMatrix<f64>>) = windows
        .par_iter()
        .map(|w| {
            let (rv, jv) = run_residuals(r, &r.p, free, w, o, true, [0.0; 3], false, None);
            let (mut g, mut info) = (DVector::zeros(m), DMatrix::zeros(m, m));
            for (res, row) in rv.iter().zip(jv.iter()) {
                let row = DVector::from_column_slice(&row[..m]);
                g.axpy(*res, &row, 1.0);
                info.ger(1.0, &row, &row, 1.0);
            }
            (g, info)
        })
        .unzip();
    let h: DMatrix<f64> = infos.iter().fold(DMatrix::zeros(m, m), |a, b| a + b);
    let mut s = DMatrix::zeros(m, m);
    for (i, g) in scores.iter().enumerate() {
        s += g * g.transpose();
        let shares_a_row = windows
            .get(i + 1)
            .is_some_and(|n| n.t[0] == *windows[i].t.last().unwrap());
        if shares_a_row {
            // Bartlett weight 1/2 (Newey-West with a lag of 1): keeps S positive
            // semi-definite, which full weights would not guarantee
            let c = g * scores[i + 1].transpose() * 0.5;
            s += &c + c.transpose();
        }
    }
    // small-sample correction of a cluster-robust S (CR1): G clusters, K parameters
    let g = windows.len() as f64;
    s *= g / (g - m as f64);
    let hinv = psd_inverse(&h, |l, lmax| l > 1e-12 * lmax);
    let cov = &hinv * s * &hinv;
    set_covariance(r, res, &cov);
}

/// The inverse of a symmetric positive semi-definite matrix on the subspace of
/// the eigenvalues `keep` accepts (given the largest). A symmetric
/// eigen-decomposition keeps it positive semi-definite: round-off can leave tiny
/// negative eigenvalues (in a Schur complement, say), which an SVD
/// pseudo-inverse would turn into correlations |r| > 1.
pub(super) fn psd_inverse(a: &DMatrix<f64>, keep: impl Fn(f64, f64) -> bool) -> DMatrix<f64> {
    let n = a.nrows();
    let Some(eig) = linalg::symmetric_eigen((a + a.transpose()) * 0.5) else {
        // not finite: nothing is known of any direction
        return DMatrix::from_element(n, n, f64::NAN);
    };
    let lmax = eig.eigenvalues.max();
    let mut inv = DMatrix::zeros(n, n);
    for (k, &l) in eig.eigenvalues.iter().enumerate() {
        if keep(l, lmax) {
            let v = eig.eigenvectors.column(k);
            inv += v * v.transpose() / l;
        }
    }
    inv
}

/// A correlation is worth a warning only while it leaves a parameter
/// uncertain. On a long log two parameters can correlate at 0.999 and both
/// be known to a ten-thousandth of their size (a million-row diff drive log:
/// r_r to 6e-5 of itself, b to 3e-4, r = -1.000), where "this log barely
/// tells them apart" would be false. A thousandth of a wheel radius is a
/// millimetre of odometry per metre driven.
const TOLD_APART: f64 = 1e-3;

/// The warnings of the pairs of parameters (named `names`) correlated beyond
/// 0.98 in `corr`, those with standard deviations `std`, unless both are
/// known within [`TOLD_APART`] of their `scale` (`Runner::param_scale`: the
/// value's size, or a hundredth of the spec's range for a value near 0). A
/// pair of undetermined parameters (infinite standard deviations) is left
/// out: the undetermined direction's own warning names them.
pub(super) fn correlation_warnings(
    names: &[&str],
    scale: &[f64],
    corr: &DMatrix<f64>,
    std: &[f64],
) -> Vec<String> {
    // a NaN standard deviation is not "known"
    let known = |k: usize| std[k] <= TOLD_APART * scale[k];
    let mut warnings = Vec::new();
    for a in 0..names.len() {
        for b in a + 1..names.len() {
            let undetermined = std[a].is_infinite() && std[b].is_infinite();
            let matters = !known(a) || !known(b);
            if corr[(a, b)].abs() > 0.98 && !undetermined && matters {
                warnings.push(format!(
                    "{} and {} are strongly correlated (r = {:.3}): this log barely tells them apart",
                    names[a],
                    names[b],
                    corr[(a, b)]
                ));
            }
        }
    }
    warnings
}

/// The sizes of the free parameters `free` at `p`, against which
/// [`correlation_warnings`] judges their standard deviations.
pub(super) fn sizes(r: &Runner, free: &[usize], p: &[f64]) -> Vec<f64> {
    free.iter().map(|&i| r.param_scale(i, p[i])).collect()
}

/// Replace `res`'s standard deviations (of the parameters it determines)
/// and correlations by those of `cov` (a covariance of its free
/// parameters), and its correlation warnings with them: the stage that made
/// `res` warned of the correlations of plain least squares, which a
/// sandwich replaces (on an OptiOdom square session the warning read 0.997
/// where the reported matrix had 0.963).
pub(super) fn set_covariance(r: &Runner, res: &mut FitResult, cov: &DMatrix<f64>) {
    let names: Vec<&str> = res.free.iter().map(|&i| r.names[i].as_str()).collect();
    let scale = sizes(r, &res.free, &res.p);
    set_covariance_named(&names, &scale, res, cov);
}

/// [`set_covariance`], the free parameters named `names`, of sizes `scale`.
fn set_covariance_named(names: &[&str], scale: &[f64], res: &mut FitResult, cov: &DMatrix<f64>) {
    for (k, std) in res.std.iter_mut().enumerate() {
        if std.is_finite() {
            *std = cov[(k, k)].max(0.0).sqrt();
        }
    }
    res.corr = correlation(cov);
    let old = std::mem::take(&mut res.correlated);
    res.warnings.retain(|w| !old.contains(w));
    res.correlated = correlation_warnings(names, scale, &res.corr, &res.std);
    res.warnings.extend(res.correlated.iter().cloned());
}

/// Correlations of a covariance matrix, within [-1, 1]; a parameter without
/// variance is uncorrelated with the others.
pub(super) fn correlation(cov: &DMatrix<f64>) -> DMatrix<f64> {
    let m = cov.nrows();
    DMatrix::from_fn(m, m, |a, b| {
        let d = (cov[(a, a)] * cov[(b, b)]).sqrt();
        if a == b {
            1.0
        } else if d > 0.0 {
            (cov[(a, b)] / d).clamp(-1.0, 1.0)
        } else {
            0.0
        }
    })
}

/// `o` with each residual kind's sigma (position, heading, gyro) scaled by the
/// RMS of its weighted residuals at `r.p`, so that each kind's weighted residuals
/// have unit variance. A kind with too few residuals to tell keeps its sigma.
pub(super) fn variance_components(r: &Runner, runs: &[Run], o: &FitOptions) -> FitOptions {
    let only = |pose: bool, gyro: bool| FitOptions {
        use_pose: pose && o.use_pose,
        use_gyro: gyro && o.use_gyro,
        use_landmarks: false,
        huber: None,
        ..o.clone()
    };
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let scaled = |sigma: f64, v: &[f64]| {
        if v.len() >= 10 && rms(v) > 0.0 && rms(v).is_finite() {
            sigma * rms(v)
        } else {
            sigma
        }
    };
    let pose = residuals(r, &r.p, &[], runs, &only(true, false), false, &[]).0;
    let gyro = residuals(r, &r.p, &[], runs, &only(false, true), false, &[]).0;
    // pose residuals come as (x, y, heading) triples
    let position: Vec<f64> = pose
        .iter()
        .enumerate()
        .filter(|(i, _)| i % 3 != 2)
        .map(|x| *x.1)
        .collect();
    let heading: Vec<f64> = pose.iter().skip(2).step_by(3).copied().collect();
    FitOptions {
        pos_sigma: scaled(o.pos_sigma, &position),
        heading_sigma: scaled(o.heading_sigma, &heading),
        gyro_sigma: scaled(o.gyro_sigma, &gyro),
        ..o.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A covariance of three parameters whose first two correlate `r`.
    fn cov(r: f64) -> DMatrix<f64> {
        DMatrix::from_row_slice(3, 3, &[1.0, r, 0.0, r, 1.0, 0.0, 0.0, 0.0, 1.0])
    }

    const NAMES: [&str; 3] = ["r_r", "r_l", "b"];
    const SCALE: [f64; 3] = [0.042, 0.042, 0.2];

    /// A covariance of three parameters with standard deviations `std`
    /// whose first two correlate `r`.
    fn cov_of(std: [f64; 3], r: f64) -> DMatrix<f64> {
        let d = DMatrix::from_diagonal(&DVector::from_row_slice(&std));
        &d * cov(r) * &d
    }

    /// A fit as the solver leaves it: correlations `r` with standard
    /// deviations `std`, warned of, beside another warning.
    fn warned(std: [f64; 3], r: f64) -> FitResult {
        let mut res = FitResult {
            corr: correlation(&cov(r)),
            ..FitResult::of_three(std, &["another warning"])
        };
        res.correlated = correlation_warnings(&NAMES, &SCALE, &res.corr, &res.std);
        res.warnings.extend(res.correlated.iter().cloned());
        res
    }

    #[test]
    fn a_sandwich_replaces_the_correlation_warnings_with_the_correlations() {
        let mut res = warned([1e-4; 3], 0.997);
        assert_eq!(res.warnings.len(), 2, "{:?}", res.warnings);
        set_covariance_named(&NAMES, &SCALE, &mut res, &cov_of([1e-4; 3], 0.963));
        assert_eq!(res.warnings, vec!["another warning".to_string()]);
        assert!((res.corr[(0, 1)] - 0.963).abs() < 1e-12);
        set_covariance_named(&NAMES, &SCALE, &mut res, &cov_of([1e-4; 3], -0.99));
        assert_eq!(res.warnings.len(), 2);
        assert!(res.warnings[1].contains("r = -0.990"), "{:?}", res.warnings);
    }

    #[test]
    fn a_sandwich_that_tells_them_apart_takes_back_the_solvers_warning() {
        // plain least squares: r_r and r_l known to 2% and correlated; the
        // sandwich: known to 6e-5 of themselves, correlated still
        let mut res = warned([1e-3, 1e-3, 1e-3], 0.999);
        assert_eq!(res.warnings.len(), 2, "{:?}", res.warnings);
        set_covariance_named(
            &NAMES,
            &SCALE,
            &mut res,
            &cov_of([2.7e-6, 2.7e-6, 6e-5], -0.9999),
        );
        assert_eq!(res.warnings, vec!["another warning".to_string()]);
        assert!((res.std[0] - 2.7e-6).abs() < 1e-15, "{:?}", res.std);
        // an undetermined parameter stays undetermined
        let mut res = warned([1e-3, 1e-3, f64::INFINITY], 0.0);
        set_covariance_named(&NAMES, &SCALE, &mut res, &cov_of([1e-3; 3], 0.0));
        assert!(res.std[2].is_infinite());
    }

    #[test]
    fn a_correlation_is_not_warned_of_where_both_are_known_to_a_thousandth() {
        // r_r known to 6e-5 of itself, r_l to 9e-4: told apart
        let corr = correlation(&cov(-0.9999));
        let std = [2.7e-6, 3.9e-5, 1e-3];
        assert_eq!(
            correlation_warnings(&NAMES, &SCALE, &corr, &std),
            Vec::<String>::new()
        );
        // r_l to 1.1e-3 of itself: the correlation is why
        let std = [2.7e-6, 4.7e-5, 1e-3];
        assert_eq!(correlation_warnings(&NAMES, &SCALE, &corr, &std).len(), 1);
        // a NaN standard deviation is not "known"
        let std = [2.7e-6, f64::NAN, 1e-3];
        assert_eq!(correlation_warnings(&NAMES, &SCALE, &corr, &std).len(), 1);
    }
}
