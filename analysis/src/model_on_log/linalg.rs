//! nalgebra's SVD and symmetric eigendecomposition, bounded. Their plain
//! forms iterate until they converge, which a matrix holding an infinity or
//! a NaN never does: a fit started from `--set b=1e308` spun in the SVD of
//! its identifiability check for hours (found by scripts/hostile_campaign.py).
//! These refuse non-finite input and stop after `MAX_SWEEPS`; callers say
//! what a failed decomposition means for them.
use nalgebra::{DMatrix, Dyn, SymmetricEigen, SVD};

/// Far beyond what a finite matrix of the analysis's sizes (tens of
/// columns) needs: nalgebra's QR sweeps converge in a few per column.
pub const MAX_SWEEPS: usize = 10_000;

/// The SVD of `m` with U and V^T, or None when `m` is not finite or the
/// iteration does not converge.
pub fn svd(m: DMatrix<f64>) -> Option<SVD<f64, Dyn, Dyn>> {
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    m.try_svd(true, true, f64::EPSILON, MAX_SWEEPS)
}

/// The eigendecomposition of the symmetric `m`, or None when `m` is not
/// finite or the iteration does not converge.
pub fn symmetric_eigen(m: DMatrix<f64>) -> Option<SymmetricEigen<f64, Dyn>> {
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    SymmetricEigen::try_new(m, f64::EPSILON, MAX_SWEEPS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_matrix_with_an_infinity_or_a_nan_is_refused_at_once() {
        let mut m = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 5.0]);
        assert!(svd(m.clone()).is_some() && symmetric_eigen(m.clone()).is_some());
        m[(1, 1)] = f64::INFINITY;
        assert!(svd(m.clone()).is_none() && symmetric_eigen(m.clone()).is_none());
        m[(1, 1)] = f64::NAN;
        assert!(svd(m.clone()).is_none() && symmetric_eigen(m).is_none());
    }

    #[test]
    fn the_bounded_forms_agree_with_nalgebras() {
        let m = DMatrix::from_fn(5, 5, |i, j| 1.0 / (1.0 + i as f64 + j as f64));
        let ours = svd(m.clone()).unwrap().singular_values;
        let theirs = m.clone().svd(true, true).singular_values;
        assert!((ours - theirs).amax() < 1e-15);
        let ours = symmetric_eigen(m.clone()).unwrap().eigenvalues;
        let theirs = m.symmetric_eigen().eigenvalues;
        assert!((ours - theirs).amax() < 1e-15);
    }
}
