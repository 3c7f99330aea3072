//! Forward-mode automatic differentiation by source transformation: for each
//! variable, every slot's tangent is written onto the same tape as more ops,
//! so a Jacobian is again a straight-line tape (interpreted, compiled by
//! kinegen-jit, folded and shared like any other).
//!
//! Forward rather than reverse mode: a kernel's Jacobian has 2-8 columns and
//! 1-3 rows, and forward mode needs no adjoint tape; its cost is one pass
//! per column. The builder's sharing makes the tangents reuse the value's
//! sines, cosines and reciprocals.
use super::builder::Builder;
use crate::ir::Op;
use crate::linalg::packed_index;

/// d outputs / d variables, row-major (rows = outputs, columns = `wrt`), where
/// each variable is the slot of an argument element (or of any value the
/// outputs are written in: it is then held fixed as an independent variable).
pub fn jacobian(b: &mut Builder, outputs: &[u32], wrt: &[u32]) -> Vec<u32> {
    // only the value's slots are differentiated: a tangent op written for
    // one column is never differentiated for the next (which would build
    // second derivatives nobody reads, and grow with every column)
    let n = b.len();
    let columns: Vec<Vec<Option<u32>>> = wrt.iter().map(|&v| tangents(b, v, n)).collect();
    let mut j = Vec::with_capacity(outputs.len() * wrt.len());
    for &o in outputs {
        for column in &columns {
            j.push(column[o as usize].unwrap_or_else(|| b.c(0.0)));
        }
    }
    j
}

/// The derivative of each of the first `n` slots with respect to `seed`
/// (None: identically zero).
fn tangents(b: &mut Builder, seed: u32, n: usize) -> Vec<Option<u32>> {
    let mut t: Vec<Option<u32>> = vec![None; n];
    for i in 0..n {
        t[i] = if i == seed as usize {
            Some(b.c(1.0))
        } else {
            let op = b.op(i as u32).clone();
            tangent(b, i as u32, &op, &t)
        };
    }
    t
}

/// The tangent of slot `at` (which holds `op`), from its operands' tangents.
fn tangent(b: &mut Builder, at: u32, op: &Op, t: &[Option<u32>]) -> Option<u32> {
    let d = |s: u32| t[s as usize];
    if op.operands().iter().all(|&s| d(s).is_none()) {
        return None;
    }
    let zero_or = |b: &mut Builder, s: u32| d(s).unwrap_or_else(|| b.c(0.0));
    Some(match *op {
        Op::Const(_) | Op::Arg(..) => return None,
        Op::Add(x, y) => {
            let (dx, dy) = (zero_or(b, x), zero_or(b, y));
            b.add(dx, dy)
        }
        Op::Sub(x, y) => {
            let (dx, dy) = (zero_or(b, x), zero_or(b, y));
            b.sub(dx, dy)
        }
        Op::Mul(x, y) => {
            let (dx, dy) = (zero_or(b, x), zero_or(b, y));
            let (l, r) = (b.mul(dx, y), b.mul(x, dy));
            b.add(l, r)
        }
        // (x/y)' = x'/y - (x/y) y'/y
        Op::Div(x, y) => {
            let (dx, dy) = (zero_or(b, x), zero_or(b, y));
            let l = b.div(dx, y);
            let q = b.mul(at, dy);
            let r = b.div(q, y);
            b.sub(l, r)
        }
        Op::Neg(x) => b.neg(d(x)?),
        Op::PowI(x, n) => {
            let lower = b.powi(x, n - 1);
            let n = b.c(f64::from(n));
            let k = b.mul(n, lower);
            b.mul(k, d(x)?)
        }
        // (x^y)' = x^y (y' ln x + y x'/x)
        Op::Pow(x, y) => {
            let (dx, dy) = (zero_or(b, x), zero_or(b, y));
            let ln = b.push(Op::Ln(x));
            let l = b.mul(dy, ln);
            let yx = b.mul(y, dx);
            let r = b.div(yx, x);
            let s = b.add(l, r);
            b.mul(at, s)
        }
        Op::Sqrt(x) => {
            let two = b.c(2.0);
            let den = b.mul(two, at);
            b.div(d(x)?, den)
        }
        Op::Sin(x) => {
            let c = b.push(Op::Cos(x));
            b.mul(c, d(x)?)
        }
        Op::Cos(x) => {
            let s = b.push(Op::Sin(x));
            let m = b.mul(s, d(x)?);
            b.neg(m)
        }
        // tan' = 1 + tan^2
        Op::Tan(x) => {
            let one = b.c(1.0);
            let sq = b.mul(at, at);
            let k = b.add(one, sq);
            b.mul(k, d(x)?)
        }
        Op::Atan(x) => {
            let one = b.c(1.0);
            let sq = b.mul(x, x);
            let den = b.add(one, sq);
            b.div(d(x)?, den)
        }
        // atan2(y, x)' = (x y' - y x') / (x^2 + y^2)
        Op::Atan2(y, x) => {
            let (dy, dx) = (zero_or(b, y), zero_or(b, x));
            let (l, r) = (b.mul(x, dy), b.mul(y, dx));
            let num = b.sub(l, r);
            let (xx, yy) = (b.mul(x, x), b.mul(y, y));
            let den = b.add(xx, yy);
            b.div(num, den)
        }
        Op::Exp(x) => b.mul(at, d(x)?),
        Op::Ln(x) => b.div(d(x)?, x),
        // |x|' = sign(x), 0 at the kink: x/|x| would make every derivative
        // through |x| NaN where x = 0 (a deadband at a stopped robot)
        Op::Abs(x) => {
            let s = b.push(Op::Sign(x));
            b.mul(s, d(x)?)
        }
        // piecewise constant: its jump at 0 has no derivative
        Op::Sign(_) => return None,
        // each branch differentiated as itself: the series' derivative is
        // the derivative's series (to one order less)
        Op::NearZero { x, eps, near, far } => {
            let (dn, df) = (zero_or(b, near), zero_or(b, far));
            b.push(Op::NearZero {
                x,
                eps,
                near: dn,
                far: df,
            })
        }
        // dP = -P dM P, entry (i, j): -sum_ab P_ia dM_ab P_bj (dM symmetric)
        Op::PinvSym3 { m, i, j } => {
            let p = |b: &mut Builder, r: usize, c: usize| {
                let (r, c) = if r <= c { (r, c) } else { (c, r) };
                b.push(Op::PinvSym3 {
                    m,
                    i: r as u8,
                    j: c as u8,
                })
            };
            let mut acc = b.c(0.0);
            for a in 0..3 {
                for c in 0..3 {
                    let Some(dm) = d(m[packed_index(a, c)]) else {
                        continue;
                    };
                    let (pia, pcj) = (p(b, i as usize, a), p(b, c, j as usize));
                    let prod = b.mul(pia, dm);
                    let term = b.mul(prod, pcj);
                    acc = b.add(acc, term);
                }
            }
            b.neg(acc)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::{ArgRole, ArgSpec, Function, Kernel};

    fn evaluate(b: Builder, outs: &[u32], x: &[f64]) -> Vec<f64> {
        let f = Function {
            kernel: Kernel::Twist,
            name: "f".into(),
            doc: String::new(),
            args: vec![ArgSpec {
                role: ArgRole::Values,
                names: vec![String::new(); x.len()],
            }],
            rows: outs.len(),
            cols: 1,
            row_names: vec![],
            col_names: vec![],
            tape: b.into_tape(),
            outputs: outs.to_vec(),
            ops_tree: 0,
        };
        f.interpret(&[x])
    }

    /// Each rule against a central difference, at a point away from kinks.
    #[test]
    fn every_rule_matches_a_central_difference() {
        type Make = fn(&mut Builder, u32, u32) -> u32;
        let cases: Vec<(&str, Make)> = vec![
            ("mul", |b, x, y| b.mul(x, y)),
            ("div", |b, x, y| b.div(x, y)),
            ("powi", |b, x, _| b.powi(x, -3)),
            ("pow", |b, x, y| b.push(Op::Pow(x, y))),
            ("sqrt", |b, x, _| b.push(Op::Sqrt(x))),
            ("sin", |b, x, _| b.push(Op::Sin(x))),
            ("cos", |b, x, _| b.push(Op::Cos(x))),
            ("tan", |b, x, _| b.push(Op::Tan(x))),
            ("atan", |b, x, _| b.push(Op::Atan(x))),
            ("atan2", |b, x, y| b.push(Op::Atan2(y, x))),
            ("exp", |b, x, _| b.push(Op::Exp(x))),
            ("ln", |b, x, _| b.push(Op::Ln(x))),
            ("abs", |b, x, y| {
                let s = b.sub(y, x);
                b.push(Op::Abs(s))
            }),
            ("pinv", |b, x, y| {
                // positive definite near the point: x^2 + 2, y + 2, 3 on
                // the diagonal, small off it
                let (two, three, tenth) = (b.c(2.0), b.c(3.0), b.c(0.1));
                let xx = b.mul(x, x);
                let (m00, m11) = (b.add(xx, two), b.add(y, two));
                let xy = b.mul(x, y);
                let (m01, m12) = (b.mul(xy, tenth), b.mul(x, tenth));
                let m = [m00, m01, tenth, m11, m12, three];
                b.push(Op::PinvSym3 { m, i: 0, j: 2 })
            }),
        ];
        for (name, make) in cases {
            let mut b = Builder::default();
            let (x, y) = (b.arg(0, 0), b.arg(0, 1));
            let f = make(&mut b, x, y);
            let j = jacobian(&mut b, &[f], &[x, y]);
            let point = [0.7, 1.3];
            let analytic = evaluate(b, &j, &point);
            for (k, &a) in analytic.iter().enumerate() {
                let h = 1e-6;
                let at = |s: f64| {
                    let mut b = Builder::default();
                    let (x, y) = (b.arg(0, 0), b.arg(0, 1));
                    let f = make(&mut b, x, y);
                    let mut p = point;
                    p[k] += s;
                    evaluate(b, &[f], &p)[0]
                };
                let numeric = (at(h) - at(-h)) / (2.0 * h);
                assert!(
                    (a - numeric).abs() < 1e-6 * (1.0 + numeric.abs()),
                    "{name}: d/dv{k} {a} against {numeric}"
                );
            }
        }
    }
}
