//! A sum of weighted outer products, sum_k w_k v_k v_k^T, kept as its square
//! root: the upper-triangular R with R^T R equal to the sum, updated one row
//! at a time by Givens rotations (the streamed QR of the rows sqrt(w_k) v_k,
//! as a square-root information filter keeps its information).
//!
//! Why not the sum itself: forming J^T J squares the rows' condition number.
//! On a 9,100 s simulated log the wheel radii carried 1e13 times the
//! information of their weakest combination with the track width, so that
//! combination's eigenvalue (4e-13 of the largest, in units of each
//! parameter's own information) sat at the round-off of a sum over 180,000
//! rows: the drift-aware sandwich dropped it and reported the radii 20,000
//! times too precisely, and keeping it left negative variances. The rotations
//! are backward stable column by column, so R's weakest singular value in the
//! same units (6e-7) comes out with about 1e-13 absolute error.
//!
//! nalgebra's `GivensRotation` rotates two rows of one matrix; here one row
//! is R's and the other a separate vector, so the rotation is applied by hand.
use crate::model_on_log::linalg;
use nalgebra::{DMatrix, DVector};

/// R with R^T R = sum of the rows' w v v^T (see the module doc).
#[derive(Debug, Clone)]
pub(super) struct SquareRoot {
    r: DMatrix<f64>,
    /// scratch for the row being rotated in
    row: DVector<f64>,
}

impl SquareRoot {
    pub(super) fn zeros(n: usize) -> SquareRoot {
        SquareRoot {
            r: DMatrix::zeros(n, n),
            row: DVector::zeros(n),
        }
    }

    pub(super) fn dim(&self) -> usize {
        self.r.nrows()
    }

    /// Add w v v^T (w >= 0). A NaN goes on as one, so that it shows.
    pub(super) fn add(&mut self, w: f64, v: &DVector<f64>) {
        if w == 0.0 {
            return;
        }
        self.row.copy_from(v);
        self.row *= w.sqrt();
        self.rotate_in();
    }

    /// Add w times the sum `other` holds (a square root over `other.dim()`
    /// columns), its column c placed at column `place(c)` of `self`.
    pub(super) fn merge(&mut self, w: f64, other: &SquareRoot, place: impl Fn(usize) -> usize) {
        if w == 0.0 {
            return;
        }
        let scale = w.sqrt();
        for i in 0..other.dim() {
            self.row.fill(0.0);
            for c in i..other.dim() {
                self.row[place(c)] = scale * other.r[(i, c)];
            }
            self.rotate_in();
        }
    }

    /// Rotate `self.row` into R: column by column, the rotation that zeroes
    /// the row's entry against R's diagonal.
    fn rotate_in(&mut self) {
        let n = self.dim();
        // R is column-major: entry (i, j) at i + j n
        let r = self.r.as_mut_slice();
        let row = self.row.as_mut_slice();
        for i in 0..n {
            let b = row[i];
            if b == 0.0 {
                continue;
            }
            let a = r[i + i * n];
            // hypot only where the squares overflow (a fit from b = 1e308):
            // everywhere it cost a tenth of a million-row fit's time
            let h = match (a * a + b * b).sqrt() {
                h if h.is_finite() => h,
                _ => a.hypot(b),
            };
            let inv = 1.0 / h;
            let (c, s) = (a * inv, b * inv);
            r[i + i * n] = h;
            for (j, y) in row.iter_mut().enumerate().skip(i + 1) {
                let x = r[i + j * n];
                r[i + j * n] = c * x + s * *y;
                *y = c * *y - s * x;
            }
        }
    }

    /// The sum itself, R^T R (the tests compare it with the sum).
    #[cfg(test)]
    fn gram(&self) -> DMatrix<f64> {
        self.r.transpose() * &self.r
    }

    /// (R^T R)^-1 on the subspace where R, its columns scaled to unit norm
    /// (each unknown in units of its own information), has singular values
    /// above `rel` times its largest; the rest is left out (0). The scaling
    /// keeps unknowns of very different sizes from reading as round-off.
    pub(super) fn inverse(&self, rel: f64) -> DMatrix<f64> {
        let n = self.dim();
        let d = DVector::from_iterator(
            n,
            self.r.column_iter().map(|c| {
                let norm = c.norm();
                if norm > 0.0 {
                    1.0 / norm
                } else {
                    0.0
                }
            }),
        );
        let scaled = &self.r * DMatrix::from_diagonal(&d);
        // bounded: nalgebra's own SVD never ends on a matrix with a NaN
        let Some((svd, vt)) = linalg::svd(scaled).and_then(|s| s.v_t.clone().map(|v| (s, v)))
        else {
            return DMatrix::from_element(n, n, f64::NAN);
        };
        let smax = svd.singular_values.max();
        let mut inv = DMatrix::zeros(n, n);
        for (k, &s) in svd.singular_values.iter().enumerate() {
            if s.is_finite() && s > rel * smax {
                let v = vt.row(k).transpose().component_mul(&d);
                inv += &v * v.transpose() / (s * s);
            }
        }
        inv
    }

    /// The sandwich A M A with A symmetric and M = S^T S this square root's
    /// sum, as (S A)^T (S A): positive semi-definite by construction.
    pub(super) fn sandwiched(&self, a: &DMatrix<f64>) -> DMatrix<f64> {
        let x = &self.r * a;
        x.transpose() * x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows() -> Vec<(f64, DVector<f64>)> {
        (0..50)
            .map(|k| {
                let t = f64::from(k);
                let v = vec![t.sin(), (0.3 * t).cos(), 1.0, 0.01 * t];
                (1.0 + 0.1 * t, DVector::from_vec(v))
            })
            .collect()
    }

    #[test]
    fn its_gram_is_the_sum_of_outer_products() {
        let mut sq = SquareRoot::zeros(4);
        let mut sum = DMatrix::zeros(4, 4);
        for (w, v) in rows() {
            sq.add(w, &v);
            sum.ger(w, &v, &v, 1.0);
        }
        assert!((sq.gram() - &sum).norm() < 1e-12 * sum.norm());
        let inv = sq.inverse(1e-12);
        assert!((inv * &sum - DMatrix::identity(4, 4)).norm() < 1e-9);
        let a = DMatrix::from_fn(4, 4, |i, j| 1.0 / (1.0 + (i + j) as f64));
        assert!((sq.sandwiched(&a) - &a * &sum * &a).norm() < 1e-12 * sum.norm());
    }

    #[test]
    fn merging_places_columns() {
        let mut whole = SquareRoot::zeros(5);
        let (mut a, mut b) = (SquareRoot::zeros(4), SquareRoot::zeros(4));
        for (k, (w, v)) in rows().into_iter().enumerate() {
            let mut wide = DVector::from_vec(vec![v[0], v[1], v[2], 0.0, 0.0]);
            if k % 2 == 0 {
                a.add(w, &v);
                wide[3] = v[3];
            } else {
                b.add(w, &v);
                wide[4] = v[3];
            }
            whole.add(w, &wide);
        }
        let mut merged = SquareRoot::zeros(5);
        merged.merge(1.0, &a, |c| c);
        merged.merge(1.0, &b, |c| if c == 3 { 4 } else { c });
        let g = whole.gram();
        assert!((merged.gram() - &g).norm() < 1e-12 * g.norm());
    }

    /// A fit from b = 1e308 (the hostile campaign's): the squares overflow
    /// and the inverse of an information holding a NaN is all NaN, at once.
    #[test]
    fn overflowing_rows_end_in_a_nan_not_a_hang() {
        let mut sq = SquareRoot::zeros(2);
        sq.add(1.0, &DVector::from_vec(vec![1e200, 1.0]));
        sq.add(1.0, &DVector::from_vec(vec![1e200, 2.0]));
        assert!((sq.r[(0, 0)] / 1e200 - 2f64.sqrt()).abs() < 1e-12);
        sq.add(1.0, &DVector::from_vec(vec![f64::NAN, 1.0]));
        assert!(sq.inverse(1e-10).iter().all(|v| v.is_nan()));
    }

    /// Two unknowns whose difference has 1e-16 of the information of their
    /// sum: the sum of outer products loses the difference to round-off, the
    /// square root keeps it.
    #[test]
    fn keeps_a_combination_the_sum_of_outer_products_loses() {
        let (eps, n) = (1e-7, 200_000);
        let (mut sq, mut sum) = (SquareRoot::zeros(2), DMatrix::<f64>::zeros(2, 2));
        // the information in the unknowns u = x1 + x2 and d = x2 - x1, where
        // the rows are well conditioned: x1 + (1 + e) x2 = (1 + e/2) u + e/2 d
        let mut exact = DMatrix::<f64>::zeros(2, 2);
        for k in 0..n {
            let t = f64::from(k) / f64::from(n);
            let (big, e) = (1e6 * (1.0 + t), eps * (t - 0.5));
            let v = DVector::from_vec(vec![big, big * (1.0 + e)]);
            sq.add(1.0, &v);
            sum.ger(1.0, &v, &v, 1.0);
            let w = DVector::from_vec(vec![big * (1.0 + e / 2.0), big * e / 2.0]);
            exact.ger(1.0, &w, &w, 1.0);
        }
        let var_d = exact[(0, 0)] / exact.determinant();
        let weak = DVector::from_vec(vec![-1.0, 1.0]);
        let var = (weak.transpose() * sq.inverse(1e-12) * &weak)[(0, 0)];
        // the rotations' round-off, about 1e-16 x sqrt(rows) of each
        // column's norm, against a weak singular value of 3e-8 of it
        assert!((var / var_d - 1.0).abs() < 1e-4, "{}", var / var_d);
        // the sum of outer products: its weakest eigenvalue is round-off
        let eig = sum.symmetric_eigen();
        let var_sum: f64 = (0..2)
            .filter(|&k| eig.eigenvalues[k] > 0.0)
            .map(|k| weak.dot(&eig.eigenvectors.column(k)).powi(2) / eig.eigenvalues[k])
            .sum();
        assert!((var_sum / var_d - 1.0).abs() > 0.5, "{}", var_sum / var_d);
    }
}
