//! Moore-Penrose pseudo-inverse of a symmetric positive semi-definite 3x3 matrix,
//! with a rank check: the numerical core of least-squares kinematics (seed 000
//! eq. 9-10, `[constraints]` specs), where the body twist is S^+ q' = (S^T S)^+ S^T q'.
//!
//! This file is the single source of the routine: the IR evaluator uses it from
//! here, and `kinegen generate` copies it verbatim into the generated crate, so the
//! interpreted and the compiled kernels compute the same thing. It therefore uses
//! only `core` and `libm` (the generated crate is `no_std`).
//!
//! Hand-written rather than taken from nalgebra: the generated crate must stay
//! dependency-light (libm only) and allocation- and panic-free, and a cyclic Jacobi
//! eigen-decomposition of a 3x3 symmetric matrix is a few dozen lines.

/// A tolerance by float type: `for_f64` here. The generated crate's copy of this
/// file takes the `f32` value when built with its `f32` feature (`kinegen
/// generate` replaces this function by `crate::math::tolerance`).
const fn tolerance(for_f64: f64, _for_f32: f64) -> f64 {
    for_f64
}

/// Eigenvalues below `RANK_TOL` times the largest count as zero: the rank check.
/// For M = S^T S this is a singular-value ratio of 1e-5 of S (3e-3 in f32,
/// whose round-off is 5e8 times larger). Directions with a zero eigenvalue are
/// left out, which gives the minimum-norm least-squares solution (seed 000 eq.
/// 11) instead of an infinite one.
pub const RANK_TOL: f64 = tolerance(1e-10, 1e-5);

/// Upper-triangle index of (i, j) in the packed order [m00, m01, m02, m11, m12, m22].
pub const fn packed_index(i: usize, j: usize) -> usize {
    let (a, b) = if i <= j { (i, j) } else { (j, i) };
    match (a, b) {
        (0, 0) => 0,
        (0, 1) => 1,
        (0, 2) => 2,
        (1, 1) => 3,
        (1, 2) => 4,
        _ => 5,
    }
}

/// Eigen-decomposition of a symmetric 3x3 matrix (packed upper triangle) by cyclic
/// Jacobi rotations: returns (eigenvalues, eigenvectors as columns of V).
// Index loops: each rotation updates two rows (p and q) of `a` together.
#[allow(clippy::needless_range_loop)]
pub fn eigen_sym3(m: [f64; 6]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut a = [[m[0], m[1], m[2]], [m[1], m[3], m[4]], [m[2], m[4], m[5]]];
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    // Quadratic convergence: a handful of sweeps reach round-off; 32 is a bound,
    // not an expectation, so the routine always terminates.
    for _ in 0..32 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        let diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        // also stops on NaN input, which would otherwise never converge
        if off <= 1e-36 * diag || off.is_nan() || diag.is_nan() {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            // t = tan of the rotation angle, the smaller root (Numerical Recipes 11.1)
            let t = if libm::fabs(theta) > tolerance(1e150, 1e18) {
                0.5 / theta
            } else {
                let sign = if theta >= 0.0 { 1.0 } else { -1.0 };
                sign / (libm::fabs(theta) + libm::sqrt(theta * theta + 1.0))
            };
            let c = 1.0 / libm::sqrt(t * t + 1.0);
            let s = t * c;
            // A <- J^T A J, V <- V J, with J = [[c, s], [-s, c]] in the (p, q) plane
            for row in a.iter_mut() {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
            for k in 0..3 {
                let (pk, qk) = (a[p][k], a[q][k]);
                a[p][k] = c * pk - s * qk;
                a[q][k] = s * pk + c * qk;
            }
            for row in v.iter_mut() {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2]], v)
}

/// Number of eigenvalues above the rank threshold (0 to 3).
pub fn rank_sym3(m: [f64; 6]) -> usize {
    let (l, _) = eigen_sym3(m);
    let zero: f64 = 0.0; // typed: the generated copy's `Real` may be f32
    let lmax = l.iter().fold(zero, |a, &b| if b > a { b } else { a });
    l.iter()
        .filter(|&&x| lmax > 0.0 && x > RANK_TOL * lmax)
        .count()
}

/// Smallest det / trace^3 taken as well conditioned: then the smallest eigenvalue
/// is at least this fraction of the largest (lmin >= det / lmax^2 and lmax <=
/// trace for a positive semi-definite matrix), far above [`RANK_TOL`], so the
/// matrix has full rank and the closed-form inverse loses at most about 1e-10
/// relative to round-off.
pub const WELL_CONDITIONED: f64 = tolerance(1e-6, 1e-2);

/// The inverse by cofactors (a dozen products and one division, against the
/// Jacobi sweeps' square roots and divisions: 3x faster for seed 000's omni
/// twist), when the matrix is certainly well conditioned; None otherwise, and
/// the eigen-decomposition decides the rank.
fn inverse_well_conditioned(m: [f64; 6]) -> Option<[f64; 6]> {
    let [a, b, c, d, e, f] = m; // [[a b c] [b d e] [c e f]]
    let (c00, c01, c02) = (d * f - e * e, c * e - b * f, b * e - c * d);
    let det = a * c00 + b * c01 + c * c02;
    let trace = a + d + f;
    if !(trace > 0.0 && det > WELL_CONDITIONED * trace * trace * trace) {
        return None; // also NaN
    }
    let r = 1.0 / det;
    Some([
        c00 * r,
        c01 * r,
        c02 * r,
        (a * f - c * c) * r,
        (b * c - a * e) * r,
        (a * d - b * b) * r,
    ])
}

/// Pseudo-inverse of a symmetric positive semi-definite 3x3 matrix, packed upper
/// triangle in and out. Full rank: the inverse. Rank deficient: the eigen-directions
/// below the rank threshold are dropped (see [`RANK_TOL`]).
pub fn pinv_sym3(m: [f64; 6]) -> [f64; 6] {
    if let Some(inv) = inverse_well_conditioned(m) {
        return inv;
    }
    let (l, v) = eigen_sym3(m);
    let zero: f64 = 0.0; // typed: the generated copy's `Real` may be f32
    let lmax = l.iter().fold(zero, |a, &b| if b > a { b } else { a });
    let mut out = [0.0; 6];
    if l.iter().any(|x| x.is_nan()) {
        return [f64::NAN; 6];
    }
    for k in 0..3 {
        if !(lmax > 0.0 && l[k] > RANK_TOL * lmax) {
            continue;
        }
        let inv = 1.0 / l[k];
        for (i, j, slot) in [
            (0, 0, 0),
            (0, 1, 1),
            (0, 2, 2),
            (1, 1, 3),
            (1, 2, 4),
            (2, 2, 5),
        ] {
            out[slot] += v[i][k] * v[j][k] * inv;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn full(m: [f64; 6]) -> [[f64; 3]; 3] {
        [[m[0], m[1], m[2]], [m[1], m[3], m[4]], [m[2], m[4], m[5]]]
    }

    fn mul(a: [[f64; 3]; 3], b: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
        let mut c = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    c[i][j] += a[i][k] * b[k][j];
                }
            }
        }
        c
    }

    /// The closed-form path agrees with the eigen-decomposition path on well
    /// conditioned matrices, and hands the badly conditioned ones to it.
    #[test]
    fn closed_form_inverse_agrees_with_the_eigen_path() {
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for _ in 0..1000 {
            // M = S^T S for a random 4x3 S (full rank with probability 1)
            let s: [[f64; 3]; 4] = core::array::from_fn(|_| core::array::from_fn(|_| next()));
            let dot = |i: usize, j: usize| (0..4).map(|k| s[k][i] * s[k][j]).sum::<f64>();
            let m = [
                dot(0, 0),
                dot(0, 1),
                dot(0, 2),
                dot(1, 1),
                dot(1, 2),
                dot(2, 2),
            ];
            let (l, v) = eigen_sym3(m);
            let mut by_eigen = [0.0; 6];
            for k in 0..3 {
                for (i, j, slot) in [
                    (0, 0, 0),
                    (0, 1, 1),
                    (0, 2, 2),
                    (1, 1, 3),
                    (1, 2, 4),
                    (2, 2, 5),
                ] {
                    by_eigen[slot] += v[i][k] * v[j][k] / l[k];
                }
            }
            match inverse_well_conditioned(m) {
                Some(inv) => {
                    let scale = by_eigen.iter().fold(0.0, |a: f64, b| a.max(b.abs()));
                    for k in 0..6 {
                        assert!((inv[k] - by_eigen[k]).abs() <= 1e-9 * scale, "{m:?}");
                    }
                }
                None => {
                    let lmax = l.iter().fold(0.0, |a: f64, &b| a.max(b));
                    let lmin = l.iter().fold(f64::INFINITY, |a, &b| a.min(b));
                    assert!(lmin < 1e-2 * lmax, "well conditioned yet refused: {l:?}");
                }
            }
        }
        // rank-deficient matrices never take the closed form
        assert!(inverse_well_conditioned([1.0, 1.0, 0.0, 1.0, 0.0, 0.0]).is_none());
        assert!(inverse_well_conditioned([f64::NAN; 6]).is_none());
    }

    #[test]
    fn inverse_of_full_rank_matrix() {
        let m = [4.0, 1.0, 0.5, 3.0, -0.2, 2.0];
        let p = pinv_sym3(m);
        let id = mul(full(m), full(p));
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((id[i][j] - want).abs() < 1e-14, "{id:?}");
            }
        }
        assert_eq!(rank_sym3(m), 3);
    }

    #[test]
    fn rank_deficient_gives_moore_penrose() {
        // M = a a^T + b b^T has rank 2
        let (a, b) = ([1.0, 2.0, -1.0], [0.5, -1.0, 3.0]);
        let mut m = [0.0; 6];
        for (i, j, s) in [
            (0, 0, 0),
            (0, 1, 1),
            (0, 2, 2),
            (1, 1, 3),
            (1, 2, 4),
            (2, 2, 5),
        ] {
            m[s] = a[i] * a[j] + b[i] * b[j];
        }
        assert_eq!(rank_sym3(m), 2);
        let p = pinv_sym3(m);
        // Penrose conditions for symmetric M, P: M P M = M and P M P = P
        let (mf, pf) = (full(m), full(p));
        let mpm = mul(mul(mf, pf), mf);
        let pmp = mul(mul(pf, mf), pf);
        for i in 0..3 {
            for j in 0..3 {
                assert!((mpm[i][j] - mf[i][j]).abs() < 1e-12);
                assert!((pmp[i][j] - pf[i][j]).abs() < 1e-12);
            }
        }
        assert!(p.iter().all(|x| x.is_finite()));
    }

    #[test]
    fn zero_matrix_has_zero_pseudo_inverse() {
        assert_eq!(pinv_sym3([0.0; 6]), [0.0; 6]);
        assert_eq!(rank_sym3([0.0; 6]), 0);
    }

    #[test]
    fn ill_conditioned_still_inverts_accurately() {
        let m = [1e4, 0.0, 0.0, 1.0, 0.0, 1e-4];
        let p = pinv_sym3(m);
        assert!(
            (p[0] - 1e-4).abs() < 1e-18 && (p[3] - 1.0).abs() < 1e-14 && (p[5] - 1e4).abs() < 1e-8
        );
    }
}
