//! Lowering symbolica atoms to IR tapes, with common-subexpression elimination.
//!
//! CSE is hash-consing: every op is looked up by its opcode and operand slots
//! before it is pushed, so identical subexpressions anywhere in a function (across
//! all its outputs) share one slot. Commutative operands are put in a canonical
//! order first so `a*b` and `b*a` meet. Built with `cse = false` the same lowering
//! gives the "before CSE" operation count.
use crate::symbolic::{as_f64, Funcs, SymbolicError};
use kinegen_model::ir::Op;
use std::collections::HashMap;
use symbolica::atom::representation::FunView;
use symbolica::atom::{AddView, AtomView, MulView, PowView, Symbol};

pub struct TapeBuilder {
    pub tape: Vec<Op>,
    dedup: HashMap<String, u32>,
    leaves: HashMap<Symbol, u32>,
    fx: Funcs,
    cse: bool,
    /// |x| below which a `NearZero` takes its series branch ([`GenOptions`](kinegen_model::options::GenOptions)).
    series_switch: f64,
}

impl TapeBuilder {
    pub fn new(fx: Funcs, cse: bool, series_switch: f64) -> Self {
        TapeBuilder {
            tape: Vec::new(),
            dedup: HashMap::new(),
            leaves: HashMap::new(),
            fx,
            cse,
            series_switch,
        }
    }

    /// Push an op, reusing an identical earlier one when CSE is on.
    pub fn push(&mut self, op: Op) -> u32 {
        let op = match op {
            Op::Add(a, b) if a > b => Op::Add(b, a),
            Op::Mul(a, b) if a > b => Op::Mul(b, a),
            o => o,
        };
        let key = match &op {
            Op::Const(c) => format!("c{}", c.to_bits()),
            o => format!("{o:?}"),
        };
        if self.cse || !op.is_arithmetic() {
            if let Some(&slot) = self.dedup.get(&key) {
                return slot;
            }
        }
        let slot = self.tape.len() as u32;
        self.tape.push(op);
        self.dedup.insert(key, slot);
        slot
    }

    /// Make `sym` read from `slot` (function arguments, let-bound intermediates).
    pub fn bind(&mut self, sym: Symbol, slot: u32) {
        self.leaves.insert(sym, slot);
    }

    pub fn constant(&mut self, c: f64) -> u32 {
        self.push(Op::Const(c))
    }

    /// Lower one atom; returns the slot holding its value.
    pub fn atom(&mut self, a: AtomView) -> Result<u32, SymbolicError> {
        match a {
            AtomView::Num(_) => self.number(a),
            AtomView::Var(v) => self.variable(v.get_symbol(), a),
            AtomView::Fun(f) if f.get_symbol() == self.fx.lsq => self.least_squares(f, a),
            AtomView::Fun(f) => self.function(f, a),
            AtomView::Pow(p) => self.power(p),
            AtomView::Mul(m) => self.product(m),
            AtomView::Add(add) => self.sum(add),
        }
    }

    fn number(&mut self, a: AtomView) -> Result<u32, SymbolicError> {
        let v = as_f64(a).ok_or_else(|| {
            // symbolica's infinity: a division by zero in a kernel,
            // which in a valid spec only the zero-noise point makes
            let why = if a.to_string().contains('⧞') {
                ": an expression divides by zero where the kernels evaluate it, at zero noise (a noise input in a denominator, such as `w/dv`); noise must leave the model defined at zero (add it, or scale by 1 + noise)"
            } else {
                ""
            };
            SymbolicError(format!("non-real constant `{a}`{why}"))
        })?;
        Ok(self.constant(v))
    }

    /// A leaf, or pi or e.
    fn variable(&mut self, s: Symbol, a: AtomView) -> Result<u32, SymbolicError> {
        if s == Symbol::PI {
            Ok(self.constant(std::f64::consts::PI))
        } else if s == Symbol::E {
            Ok(self.constant(std::f64::consts::E))
        } else {
            self.leaves
                .get(&s)
                .copied()
                .ok_or_else(|| SymbolicError(format!("unbound symbol `{a}` in derived code")))
        }
    }

    fn least_squares(&mut self, f: FunView, a: AtomView) -> Result<u32, SymbolicError> {
        // lowered as what it stands for, so its pseudo-inverse is the
        // very `kg_pinv` its derivatives read (one decomposition)
        let args: Vec<_> = f.iter().map(|x| x.to_owned()).collect();
        let (k, s, q) = crate::symbolic::lsq_parts(&args)
            .ok_or_else(|| SymbolicError(format!("malformed least-squares solution `{a}`")))?;
        self.atom(crate::symbolic::lsq_expanded(k, &s, &q).as_view())
    }

    /// A function call: sin, cos, exp, ln, sqrt, abs, sign, tan, atan, atan2, the
    /// pseudo-inverse entry and the series switch.
    fn function(&mut self, f: FunView, a: AtomView) -> Result<u32, SymbolicError> {
        let s = f.get_symbol();
        let args: Vec<u32> = f.iter().map(|x| self.atom(x)).collect::<Result<_, _>>()?;
        let op = if s == Symbol::SIN {
            Op::Sin(args[0])
        } else if s == Symbol::COS {
            Op::Cos(args[0])
        } else if s == Symbol::EXP {
            Op::Exp(args[0])
        } else if s == Symbol::LOG {
            Op::Ln(args[0])
        } else if s == Symbol::SQRT {
            Op::Sqrt(args[0])
        } else if s == Symbol::ABS || s == self.fx.abs {
            Op::Abs(args[0])
        } else if s == self.fx.sign {
            Op::Sign(args[0])
        } else if s == self.fx.tan {
            Op::Tan(args[0])
        } else if s == self.fx.atan {
            Op::Atan(args[0])
        } else if s == self.fx.atan2 {
            Op::Atan2(args[0], args[1])
        } else if s == self.fx.pinv {
            let index = |k: usize| {
                as_f64(f.iter().nth(k).unwrap())
                    .map(|v| v as u8)
                    .ok_or_else(|| {
                        SymbolicError(format!("pseudo-inverse index is not a number in `{a}`"))
                    })
            };
            if args.len() != 8 {
                return Err(SymbolicError(format!(
                    "pseudo-inverse with {} arguments",
                    args.len()
                )));
            }
            let m = [args[2], args[3], args[4], args[5], args[6], args[7]];
            Op::PinvSym3 {
                m,
                i: index(0)?,
                j: index(1)?,
            }
        } else if s == self.fx.near {
            Op::NearZero {
                x: args[0],
                eps: self.series_switch,
                near: args[1],
                far: args[2],
            }
        } else {
            return Err(SymbolicError(format!(
                "no code for function `{a}` (a derivative placeholder?)"
            )));
        };
        Ok(self.push(op))
    }

    /// A power: exp for e^x, integer and half-integer powers by
    /// multiplication and square roots, pow otherwise.
    fn power(&mut self, p: PowView) -> Result<u32, SymbolicError> {
        let (base, exp) = p.get_base_exp();
        if let AtomView::Var(v) = base {
            if v.get_symbol() == Symbol::E {
                let e = self.atom(exp)?;
                return Ok(self.push(Op::Exp(e)));
            }
        }
        let b = self.atom(base)?;
        match as_f64(exp) {
            Some(n) if n.fract() == 0.0 => Ok(self.powi(b, n as i32)),
            Some(h) if (2.0 * h).fract() == 0.0 => {
                let s = self.push(Op::Sqrt(b));
                Ok(self.powi(s, (2.0 * h) as i32))
            }
            _ => {
                let e = self.atom(exp)?;
                Ok(self.push(Op::Pow(b, e)))
            }
        }
    }

    /// A product: numerator and denominator collected separately: x*y/z costs
    /// two ops, not a reciprocal and two multiplications.
    fn product(&mut self, m: MulView) -> Result<u32, SymbolicError> {
        // numerator and denominator collected separately: x*y/z costs two ops,
        // not a reciprocal and two multiplications.
        let mut coef = 1.0;
        let mut num = Vec::new();
        let mut den = Vec::new();
        for f in m.iter() {
            if let Some(c) = as_f64(f) {
                coef *= c;
                continue;
            }
            // pi and e are numbers too: folded into the coefficient
            // (2*pi*r*n/cpr is one constant factor, not two products)
            if let AtomView::Var(v) = f {
                let s = v.get_symbol();
                if s == Symbol::PI || s == Symbol::E {
                    coef *= if s == Symbol::PI {
                        std::f64::consts::PI
                    } else {
                        std::f64::consts::E
                    };
                    continue;
                }
            }
            if let AtomView::Pow(p) = f {
                let (base, exp) = p.get_base_exp();
                if let Some(n) = as_f64(exp) {
                    if n < 0.0 && (2.0 * n).fract() == 0.0 {
                        let b = self.atom(base)?;
                        let d = if n.fract() == 0.0 {
                            self.powi(b, (-n) as i32)
                        } else {
                            let s = self.push(Op::Sqrt(b));
                            self.powi(s, (-2.0 * n) as i32)
                        };
                        den.push(d);
                        continue;
                    }
                }
            }
            num.push(self.atom(f)?);
        }
        let mut acc = num.into_iter().reduce(|a, b| self.push(Op::Mul(a, b)));
        if coef.abs() != 1.0 {
            let c = self.constant(coef.abs());
            acc = Some(match acc {
                Some(a) => self.push(Op::Mul(c, a)),
                None => c,
            });
        }
        let mut v = acc.unwrap_or_else(|| self.constant(1.0));
        if let Some(d) = den.into_iter().reduce(|a, b| self.push(Op::Mul(a, b))) {
            v = self.push(Op::Div(v, d));
        }
        if coef < 0.0 {
            v = self.push(Op::Neg(v));
        }
        Ok(v)
    }

    /// A sum, with `-` for negative terms instead of negating them.
    fn sum(&mut self, add: AddView) -> Result<u32, SymbolicError> {
        let mut acc: Option<u32> = None;
        let mut pending_neg = Vec::new();
        for t in add.iter() {
            let (neg, slot) = self.term(t)?;
            if neg {
                match acc {
                    Some(a) => acc = Some(self.push(Op::Sub(a, slot))),
                    None => pending_neg.push(slot),
                }
            } else {
                acc = Some(match acc {
                    Some(a) => self.push(Op::Add(a, slot)),
                    None => slot,
                });
            }
        }
        let mut v = match acc {
            Some(a) => a,
            None => {
                let first = pending_neg.remove(0);
                self.push(Op::Neg(first))
            }
        };
        for s in pending_neg {
            v = self.push(Op::Sub(v, s));
        }
        Ok(v)
    }

    /// A sum term as (is_negative, slot of its absolute value), so sums use `-`
    /// instead of negating.
    fn term(&mut self, t: AtomView) -> Result<(bool, u32), SymbolicError> {
        if let Some(c) = as_f64(t) {
            return Ok((c < 0.0, self.constant(c.abs())));
        }
        if let AtomView::Mul(m) = t {
            let negative = m.iter().filter_map(as_f64).product::<f64>() < 0.0;
            if negative {
                let s = self.atom(t)?;
                // atom() ends a negative product with Neg(x): take x back.
                if let Some(Op::Neg(inner)) = self.tape.get(s as usize) {
                    return Ok((true, *inner));
                }
                return Ok((false, s));
            }
        }
        Ok((false, self.atom(t)?))
    }

    fn powi(&mut self, b: u32, n: i32) -> u32 {
        match n {
            0 => self.constant(1.0),
            1 => b,
            2 => self.push(Op::Mul(b, b)),
            n if n < 0 => {
                let one = self.constant(1.0);
                let d = self.powi(b, -n);
                self.push(Op::Div(one, d))
            }
            // Square-and-multiply: b^n from b^(n/2) squared, times b when n is odd.
            // Multiplications instead of libm::pow (4x faster in the exact step's
            // series terms), and with hash-consing b^2, b^4, ... are shared by
            // every power of b in the function (the series of t^5..t^8 costs a few
            // products in all). At most 2 log2(n) products, so even a huge
            // exponent stays cheap.
            n => {
                let half = self.powi(b, n / 2);
                let square = self.push(Op::Mul(half, half));
                if n % 2 == 1 {
                    self.push(Op::Mul(square, b))
                } else {
                    square
                }
            }
        }
    }

    /// Drop ops no output needs, share reciprocals; returns (tape, outputs).
    pub fn finish(self, outputs: &[u32]) -> (Vec<Op>, Vec<u32>) {
        kinegen_model::passes::finish(self.tape, outputs)
    }
}
