//! Normal equations of an "arrow" shape: the model's parameters first, then one
//! start-heading nuisance per run, which only its own run's residuals see, so
//! the nuisance block is diagonal. Solving through the Schur complement costs
//! O(m^2 k) for m parameters and k nuisances instead of O((m + k)^3): a
//! 1,000,000-sample log cut into 60 s segments has k = 833, and a dense
//! eigen-decomposition and Cholesky factorisation of that size took most of
//! the fit's time.
use crate::model_on_log::linalg;
use nalgebra::{DMatrix, DVector};

/// A nuisance with less information than this is left where it is (its
/// diagonal entry is the information about it given the parameters).
const NO_INFORMATION: f64 = 1e-300;

/// The parameters' information with the nuisances marginalised out:
/// A - B C^-1 B^T for the blocks [[A, B], [B^T, C]] of `full`, C diagonal
/// (a nuisance the data do not see at all contributes nothing).
pub fn marginal(full: &DMatrix<f64>, m: usize) -> DMatrix<f64> {
    let mut s = full.view((0, 0), (m, m)).into_owned();
    for k in m..full.nrows() {
        let c = full[(k, k)];
        if c > NO_INFORMATION {
            let b = full.view((0, k), (m, 1)).column(0).into_owned();
            s.ger(-1.0 / c, &b, &b, 1.0);
        }
    }
    s
}

/// The Levenberg-Marquardt step for the normal equations `full` x = -`g`
/// damped by `lambda` times their diagonal, with no component of the
/// parameter step along the `undetermined` directions (unit vectors of
/// parameter space): those stay where they are, and the nuisances follow the
/// parameter step. None when the damped system cannot be solved.
pub fn damped_step(
    full: &DMatrix<f64>,
    g: &DVector<f64>,
    m: usize,
    lambda: f64,
    undetermined: &[DVector<f64>],
) -> Option<DVector<f64>> {
    let n = full.nrows();
    let damped = |k: usize| full[(k, k)] + lambda * full[(k, k)].max(1e-12);
    // Schur complement of the damped nuisance block, and its right-hand side
    let mut s = full.view((0, 0), (m, m)).into_owned();
    for d in 0..m {
        s[(d, d)] = damped(d);
    }
    let mut rhs = -g.rows(0, m).into_owned();
    for k in m..n {
        let c = damped(k);
        let b = full.view((0, k), (m, 1)).column(0).into_owned();
        s.ger(-1.0 / c, &b, &b, 1.0);
        rhs.axpy(g[k] / c, &b, 1.0);
    }
    // nalgebra's SVD does not return on a NaN: a non-finite system has no step
    if !s.iter().chain(rhs.iter()).all(|v| v.is_finite()) {
        return None;
    }
    let mut dp = if m == 0 {
        DVector::zeros(0) // only nuisances
    } else {
        match s.clone().cholesky() {
            Some(ch) => ch.solve(&rhs),
            None => linalg::svd(s)?.solve(&rhs, 1e-14).ok()?,
        }
    };
    for v in undetermined {
        dp -= v * v.dot(&dp);
    }
    let mut step = DVector::zeros(n);
    step.rows_mut(0, m).copy_from(&dp);
    for k in m..n {
        let b = full.view((0, k), (m, 1)).column(0).into_owned();
        step[k] = (-g[k] - b.dot(&dp)) / damped(k);
    }
    step.iter().all(|v| v.is_finite()).then_some(step)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random arrow system: the structured step equals the dense solve.
    #[test]
    fn the_schur_step_is_the_dense_step() {
        let (m, k) = (3, 7);
        let n = m + k;
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        // J with rows that see the parameters and one nuisance each
        let mut j = DMatrix::zeros(40, n);
        for r in 0..40 {
            for c in 0..m {
                j[(r, c)] = rnd();
            }
            j[(r, m + r % k)] = rnd() + 1.0;
        }
        let full = j.transpose() * &j;
        let g = DVector::from_fn(n, |_, _| rnd());
        let lambda = 0.3;
        let mut a = full.clone();
        for d in 0..n {
            a[(d, d)] += lambda * full[(d, d)];
        }
        let dense = a.cholesky().unwrap().solve(&(-&g));
        let arrow = damped_step(&full, &g, m, lambda, &[]).unwrap();
        assert!((dense - arrow).norm() < 1e-10);
        // the marginal information is the inverse of the covariance block
        // only nuisances: each its own 1-d problem
        let only = full.view((m, m), (k, k)).into_owned();
        let gs = g.rows(m, k).into_owned();
        let step = damped_step(&only, &gs, 0, lambda, &[]).unwrap();
        for i in 0..k {
            assert!((step[i] + gs[i] / (only[(i, i)] * (1.0 + lambda))).abs() < 1e-12);
        }
        let cov = full.clone().try_inverse().unwrap();
        let marg_inv = marginal(&full, m).try_inverse().unwrap();
        assert!((cov.view((0, 0), (m, m)) - marg_inv).norm() < 1e-9);
    }
}
