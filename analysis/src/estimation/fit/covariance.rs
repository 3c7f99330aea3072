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
    for k in 0..m {
        if res.std[k].is_finite() {
            res.std[k] = cov[(k, k)].max(0.0).sqrt();
        }
    }
    set_correlation(r, res, &cov);
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

/// The warnings of the pairs of parameters (named `names`) correlated beyond
/// 0.98 in `corr`, those with standard deviations `std`. A pair of
/// undetermined parameters (infinite standard deviations) is left out: the
/// undetermined direction's own warning names them.
pub(super) fn correlation_warnings(
    names: &[&str],
    corr: &DMatrix<f64>,
    std: &[f64],
) -> Vec<String> {
    let mut warnings = Vec::new();
    for a in 0..names.len() {
        for b in a + 1..names.len() {
            let undetermined = std[a].is_infinite() && std[b].is_infinite();
            if corr[(a, b)].abs() > 0.98 && !undetermined {
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

/// Replace `res`'s correlations by those of `cov` (a covariance of its
/// free parameters) and its correlation warnings with them: the stage that
/// made `res` warned of the correlations of plain least squares, which a
/// sandwich replaces (on an OptiOdom square session the warning read 0.997
/// where the reported matrix had 0.963).
pub(super) fn set_correlation(r: &Runner, res: &mut FitResult, cov: &DMatrix<f64>) {
    let names: Vec<&str> = res.free.iter().map(|&i| r.names[i].as_str()).collect();
    set_correlation_named(&names, res, cov);
}

/// [`set_correlation`], the free parameters named `names`.
fn set_correlation_named(names: &[&str], res: &mut FitResult, cov: &DMatrix<f64>) {
    let corr = correlation(cov);
    let old = correlation_warnings(names, &res.corr, &res.std);
    res.warnings.retain(|w| !old.contains(w));
    res.warnings
        .extend(correlation_warnings(names, &corr, &res.std));
    res.corr = corr;
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

    #[test]
    fn a_sandwich_replaces_the_correlation_warnings_with_the_correlations() {
        let names = ["r_r", "r_l", "b"];
        let mut res = FitResult {
            corr: correlation(&cov(0.997)),
            ..FitResult::of_three([1e-4; 3], &["another warning"])
        };
        res.warnings
            .extend(correlation_warnings(&names, &res.corr, &res.std));
        assert_eq!(res.warnings.len(), 2, "{:?}", res.warnings);
        set_correlation_named(&names, &mut res, &cov(0.963));
        assert_eq!(res.warnings, vec!["another warning".to_string()]);
        assert!((res.corr[(0, 1)] - 0.963).abs() < 1e-12);
        set_correlation_named(&names, &mut res, &cov(-0.99));
        assert_eq!(res.warnings.len(), 2);
        assert!(res.warnings[1].contains("r = -0.990"), "{:?}", res.warnings);
    }
}
