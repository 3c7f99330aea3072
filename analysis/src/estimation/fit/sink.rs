//! Where a run's weighted residuals go as they are made: kept whole (a
//! covariance, the drift-aware sandwich, the dense Jacobian of a small
//! problem), or folded into the Gauss-Newton sums as they come, so that a
//! million-row run's residuals and Jacobian rows (120 bytes a row for three
//! parameters and a start heading) are never held at once.
use crate::logs::rows::Rows;
use nalgebra::{DMatrix, DVector};

/// The cost (half the sum of squares) of weighted residuals and their count.
#[derive(Debug, Clone, Copy, Default)]
pub struct Sums {
    pub cost: f64,
    pub n: usize,
}

impl Sums {
    pub(super) fn add(&mut self, other: Sums) {
        self.cost += other.cost;
        self.n += other.n;
    }
}

/// Huber loss by iteratively reweighted least squares: a residual r beyond k is
/// scaled by sqrt(k/|r|), so its squared contribution is k|r| (linear growth); its
/// Jacobian row gets the same weight (the weight's own derivative is neglected, as
/// IRLS does). Weights are recomputed at every evaluation.
pub(super) fn huber_weight(r: f64, k: f64) -> f64 {
    if r.abs() > k {
        (k / r.abs()).sqrt()
    } else {
        1.0
    }
}

/// Takes one weighted residual at a time, with its Jacobian row (the free
/// parameters, then the run's start heading when it has one) when the caller
/// computes one.
pub trait Sink {
    /// Whether the sink's result does not depend on the order the
    /// residuals come in (sums do; a series read in time order does not).
    const ORDER_FREE: bool = false;
    fn push(&mut self, res: f64, row: Option<impl Iterator<Item = f64>>);
}

/// Every residual and Jacobian row, in order.
pub struct Kept {
    pub res: Vec<f64>,
    pub jac: Rows,
}

impl Kept {
    pub fn new(width: usize) -> Kept {
        Kept {
            res: Vec::new(),
            jac: Rows::new(width),
        }
    }
}

impl Sink for Kept {
    fn push(&mut self, res: f64, row: Option<impl Iterator<Item = f64>>) {
        self.res.push(res);
        if let Some(row) = row {
            self.jac.push(row);
        }
    }
}

/// The sum of squares and the count of residuals, Huber-weighted where
/// `huber` says. (Half the sum is taken at the end, as the residuals kept
/// whole were summed, so the cost is the same to the last bit.)
#[derive(Default)]
pub struct Squares {
    sum: f64,
    n: usize,
}

impl Squares {
    fn add(&mut self, res: f64) {
        self.sum += res * res;
        self.n += 1;
    }

    pub fn sums(&self) -> Sums {
        Sums {
            cost: 0.5 * self.sum,
            n: self.n,
        }
    }
}

/// The residuals' cost and count only.
pub struct Summed {
    pub squares: Squares,
    huber: Option<f64>,
}

impl Summed {
    pub fn new(huber: Option<f64>) -> Summed {
        Summed {
            squares: Squares::default(),
            huber,
        }
    }
}

impl Sink for Summed {
    const ORDER_FREE: bool = true;
    fn push(&mut self, res: f64, _: Option<impl Iterator<Item = f64>>) {
        let w = self.huber.map_or(1.0, |k| huber_weight(res, k));
        self.squares.add(res * w);
    }
}

/// Rows gathered before they enter A^T A as one matrix product (blocked and
/// vectorised by nalgebra), not as one rank-1 update per residual.
const BLOCK: usize = 256;

/// One run's share of the normal equations, its rows split into A (the
/// parameters' columns) and b (the start heading's): A^T A, A^T b, b^T b,
/// A^T r and b^T r, with the residuals' [`Sums`]; each residual and its row
/// Huber-weighted (IRLS) where `huber` says.
pub struct Folded {
    m: usize,
    nuisance: bool,
    huber: Option<f64>,
    pub squares: Squares,
    pub ata: DMatrix<f64>,
    pub atb: DVector<f64>,
    pub btb: f64,
    pub atr: DVector<f64>,
    pub btr: f64,
    a: DMatrix<f64>,
    b: DVector<f64>,
    r: DVector<f64>,
    filled: usize,
}

impl Folded {
    pub fn new(m: usize, nuisance: bool, huber: Option<f64>) -> Folded {
        Folded {
            m,
            nuisance,
            huber,
            squares: Squares::default(),
            ata: DMatrix::zeros(m, m),
            atb: DVector::zeros(m),
            btb: 0.0,
            atr: DVector::zeros(m),
            btr: 0.0,
            a: DMatrix::zeros(BLOCK, m),
            b: DVector::zeros(BLOCK),
            r: DVector::zeros(BLOCK),
            filled: 0,
        }
    }

    fn flush(&mut self) {
        let n = self.filled;
        let (a, b, r) = (self.a.rows(0, n), self.b.rows(0, n), self.r.rows(0, n));
        self.ata.gemm_tr(1.0, &a, &a, 1.0);
        self.atb.gemv_tr(1.0, &a, &b, 1.0);
        self.btb += b.dot(&b);
        self.atr.gemv_tr(1.0, &a, &r, 1.0);
        self.btr += b.dot(&r);
        self.filled = 0;
    }

    /// The sums, with the last partial block folded in.
    pub fn finish(mut self) -> Folded {
        if self.filled > 0 {
            self.flush();
        }
        self
    }
}

impl Sink for Folded {
    const ORDER_FREE: bool = true;
    fn push(&mut self, res: f64, row: Option<impl Iterator<Item = f64>>) {
        let w = self.huber.map_or(1.0, |k| huber_weight(res, k));
        let res = res * w;
        self.squares.add(res);
        let i = self.filled;
        let row = row.expect("the normal equations are made from Jacobian rows");
        self.b[i] = 0.0;
        for (c, v) in row.enumerate() {
            if c < self.m {
                self.a[(i, c)] = v * w;
            } else if self.nuisance {
                self.b[i] = v * w;
            }
        }
        self.r[i] = res;
        self.filled += 1;
        if self.filled == BLOCK {
            self.flush();
        }
    }
}
