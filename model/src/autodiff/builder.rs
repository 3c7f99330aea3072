//! A tape under construction: every op is folded when its operands are
//! constants, simplified where the algebra is exact (x + 0, x * 1, x * 0,
//! --x), and looked up before it is pushed, so an expression met twice (in
//! two outputs, or in a value and the derivative that reuses it) has one slot.
use crate::ir::Op;
use std::collections::HashMap;

/// An op as a hash key: constants by their bits (f64 is not `Eq`), the rest
/// by their opcode and operand slots.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
enum Key {
    Const(u64),
    Op(String),
}

fn key(op: &Op) -> Key {
    match op {
        Op::Const(c) => Key::Const(c.to_bits()),
        // `{:?}` names the opcode and every operand (and a series switch's
        // threshold): two ops with the same text compute the same value
        other => Key::Op(format!("{other:?}")),
    }
}

#[derive(Default)]
pub struct Builder {
    tape: Vec<Op>,
    seen: HashMap<Key, u32>,
    /// A constant the folding made infinite or NaN (a division by zero at
    /// zero noise): the derivation's error, not a kernel's silent NaN.
    pub nonfinite: bool,
}

impl Builder {
    pub fn len(&self) -> usize {
        self.tape.len()
    }

    pub fn op(&self, slot: u32) -> &Op {
        &self.tape[slot as usize]
    }

    /// The value of `slot` when it is a constant.
    pub fn constant_of(&self, slot: u32) -> Option<f64> {
        match self.tape[slot as usize] {
            Op::Const(c) => Some(c),
            _ => None,
        }
    }

    pub fn into_tape(self) -> Vec<Op> {
        self.tape
    }

    pub fn c(&mut self, value: f64) -> u32 {
        self.push(Op::Const(value))
    }

    pub fn arg(&mut self, arg: usize, index: usize) -> u32 {
        self.push(Op::Arg(arg as u16, index as u16))
    }

    pub fn add(&mut self, a: u32, b: u32) -> u32 {
        self.push(Op::Add(a, b))
    }
    pub fn sub(&mut self, a: u32, b: u32) -> u32 {
        self.push(Op::Sub(a, b))
    }
    pub fn mul(&mut self, a: u32, b: u32) -> u32 {
        self.push(Op::Mul(a, b))
    }
    pub fn div(&mut self, a: u32, b: u32) -> u32 {
        self.push(Op::Div(a, b))
    }
    pub fn neg(&mut self, a: u32) -> u32 {
        self.push(Op::Neg(a))
    }

    /// a^n by squaring and multiplying (at most 2 log2 n products; b^2, b^4
    /// are shared by every power of b in the tape), as the symbolic stage
    /// lowers powers: multiplications are several times cheaper than pow.
    pub fn powi(&mut self, a: u32, n: i32) -> u32 {
        match n {
            0 => self.c(1.0),
            1 => a,
            2 => self.mul(a, a),
            n if n < 0 => {
                let one = self.c(1.0);
                let d = self.powi(a, -n);
                self.div(one, d)
            }
            n => {
                let half = self.powi(a, n / 2);
                let square = self.mul(half, half);
                if n % 2 == 1 {
                    self.mul(square, a)
                } else {
                    square
                }
            }
        }
    }

    /// Push `op` (after folding and simplifying it); returns its slot.
    pub fn push(&mut self, op: Op) -> u32 {
        let op = match self.simplify(op) {
            Ok(slot) => return slot,
            Err(op) => op,
        };
        let op = match op {
            Op::Add(a, b) if a > b => Op::Add(b, a),
            Op::Mul(a, b) if a > b => Op::Mul(b, a),
            o => o,
        };
        let k = key(&op);
        if let Some(&slot) = self.seen.get(&k) {
            return slot;
        }
        let slot = self.tape.len() as u32;
        self.tape.push(op);
        self.seen.insert(k, slot);
        slot
    }

    /// An existing slot that `op` equals, or the op to push (folded to a
    /// constant when its operands are). Only rewrites that hold for every
    /// finite operand value.
    fn simplify(&mut self, op: Op) -> Result<u32, Op> {
        let c = |s: u32| self.constant_of(s);
        let is = |s: u32, v: f64| c(s) == Some(v);
        let operands = op.operands();
        if op.is_arithmetic()
            && !matches!(op, Op::NearZero { .. })
            && operands.iter().all(|&s| c(s).is_some())
        {
            let value = op.apply(|s| c(s).unwrap_or(f64::NAN));
            self.nonfinite |= !value.is_finite();
            return Err(Op::Const(value));
        }
        match op {
            Op::Add(a, b) if is(b, 0.0) => Ok(a),
            Op::Add(a, b) if is(a, 0.0) => Ok(b),
            Op::Sub(a, b) if is(b, 0.0) => Ok(a),
            Op::Sub(a, b) if a == b => Ok(self.c(0.0)),
            Op::Sub(a, b) if is(a, 0.0) => Ok(self.neg(b)),
            Op::Mul(a, b) if is(a, 0.0) || is(b, 0.0) => Ok(self.c(0.0)),
            Op::Mul(a, b) if is(b, 1.0) => Ok(a),
            Op::Mul(a, b) if is(a, 1.0) => Ok(b),
            Op::Mul(a, b) if is(b, -1.0) => Ok(self.neg(a)),
            Op::Mul(a, b) if is(a, -1.0) => Ok(self.neg(b)),
            Op::Div(a, b) if is(b, 1.0) => Ok(a),
            Op::Div(a, _) if is(a, 0.0) => Ok(a),
            Op::Neg(a) => match self.tape[a as usize] {
                Op::Neg(inner) => Ok(inner),
                _ => Err(op),
            },
            Op::NearZero { near, far, .. } if near == far => Ok(near),
            Op::NearZero { x, eps, near, far } => match c(x) {
                Some(v) if v.abs() < eps => Ok(near),
                Some(_) => Ok(far),
                None => Err(op),
            },
            other => Err(other),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folds_shares_and_simplifies() {
        let mut b = Builder::default();
        let x = b.arg(0, 0);
        let two = b.c(2.0);
        let three = b.c(3.0);
        let six = b.mul(two, three);
        assert_eq!(b.constant_of(six), Some(6.0));
        let zero = b.c(0.0);
        assert_eq!(b.add(x, zero), x);
        let one = b.c(1.0);
        assert_eq!(b.mul(one, x), x);
        let x0 = b.mul(x, zero);
        assert_eq!(b.constant_of(x0), Some(0.0));
        let xy = b.mul(x, six);
        assert_eq!(b.mul(six, x), xy, "a product met twice is one slot");
        let n = b.neg(x);
        assert_eq!(b.neg(n), x);
        assert!(!b.nonfinite);
        b.div(one, zero);
        assert!(b.nonfinite, "1/0 folded is an error, not an infinity");
    }
}
