//! A spec expression onto a tape: each name read from what the kernel binds
//! it to (an argument's element, a constant parameter's number, a twist
//! component), each definition lowered once, where first used.
use super::builder::Builder;
use crate::expr::{BinOp, Expr, ExprKind};
use crate::ir::Op;
use crate::spec::Model;
use crate::{SourceError, SourcePos};
use std::collections::HashMap;

/// What the names of one kernel stand for.
pub struct Scope<'m> {
    model: &'m Model,
    bound: HashMap<String, u32>,
    /// Names the kernel does not have (a twist reads no state, an
    /// observation no noise), with why, for the error.
    absent: HashMap<String, &'static str>,
}

impl<'m> Scope<'m> {
    pub fn new(model: &'m Model) -> Self {
        Scope {
            model,
            bound: HashMap::new(),
            absent: HashMap::new(),
        }
    }

    pub fn bind(&mut self, name: &str, slot: u32) {
        self.bound.insert(name.to_string(), slot);
    }

    pub fn refuse(&mut self, name: &str, why: &'static str) {
        self.absent.insert(name.to_string(), why);
    }

    pub fn slot(&self, name: &str) -> Option<u32> {
        self.bound.get(name).copied()
    }

    fn error(&self, e: &Expr, msg: String) -> SourceError {
        SourceError::new(
            &self.model.path,
            Some(SourcePos::from_offset(&self.model.source, e.span.0)),
            msg,
        )
    }

    /// The slot holding `e`'s value.
    pub fn lower(&mut self, b: &mut Builder, e: &Expr) -> Result<u32, SourceError> {
        Ok(match &e.kind {
            ExprKind::Num(text) => {
                let v: f64 = text
                    .parse()
                    .map_err(|_| self.error(e, format!("malformed number `{text}`")))?;
                b.c(v)
            }
            ExprKind::Var(v) => self.variable(b, e, v)?,
            ExprKind::Neg(a) => {
                let a = self.lower(b, a)?;
                b.neg(a)
            }
            ExprKind::Bin(op, l, r) => {
                let (l, r) = (self.lower(b, l)?, self.lower(b, r)?);
                match op {
                    BinOp::Add => b.add(l, r),
                    BinOp::Sub => b.sub(l, r),
                    BinOp::Mul => b.mul(l, r),
                    BinOp::Div => b.div(l, r),
                    BinOp::Pow => power(b, l, r),
                }
            }
            ExprKind::Call(f, args) => {
                let a = args
                    .iter()
                    .map(|x| self.lower(b, x))
                    .collect::<Result<Vec<u32>, _>>()?;
                let op = match (f.as_str(), a.as_slice()) {
                    ("sin", &[x]) => Op::Sin(x),
                    ("cos", &[x]) => Op::Cos(x),
                    ("tan", &[x]) => Op::Tan(x),
                    ("atan", &[x]) => Op::Atan(x),
                    ("atan2", &[y, x]) => Op::Atan2(y, x),
                    ("sqrt", &[x]) => Op::Sqrt(x),
                    ("exp", &[x]) => Op::Exp(x),
                    ("ln", &[x]) => Op::Ln(x),
                    ("abs", &[x]) => Op::Abs(x),
                    ("sign", &[x]) => Op::Sign(x),
                    _ => {
                        return Err(self.error(
                            e,
                            format!(
                                "`{f}` with {} arguments is no function of the language",
                                a.len()
                            ),
                        ))
                    }
                };
                b.push(op)
            }
        })
    }

    fn variable(&mut self, b: &mut Builder, e: &Expr, name: &str) -> Result<u32, SourceError> {
        if let Some(slot) = self.slot(name) {
            return Ok(slot);
        }
        if name == "pi" {
            return Ok(b.c(std::f64::consts::PI));
        }
        if let Some((_, def, _)) = self.model.defines.iter().find(|(n, _, _)| n == name) {
            let slot = self.lower(b, def)?;
            self.bind(name, slot);
            return Ok(slot);
        }
        Err(self.error(
            e,
            match self.absent.get(name) {
                Some(why) => format!("`{name}` cannot be used here: {why}"),
                None => format!("unbound symbol `{name}`"),
            },
        ))
    }
}

/// l^r: integer and half-integer constant powers by products and square
/// roots (as the symbolic stage lowers them), `pow` otherwise.
fn power(b: &mut Builder, l: u32, r: u32) -> u32 {
    match b.constant_of(r) {
        Some(n) if n.fract() == 0.0 && n.abs() <= 64.0 => b.powi(l, n as i32),
        Some(h) if (2.0 * h).fract() == 0.0 && h.abs() <= 64.0 => {
            let s = b.push(Op::Sqrt(l));
            b.powi(s, (2.0 * h) as i32)
        }
        _ => b.push(Op::Pow(l, r)),
    }
}
