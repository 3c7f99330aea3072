//! The model IR: what the derivation stage hands to everyone else.
//!
//! Each derived function is a straight-line tape of [`Op`]s in SSA form (every op
//! writes a new slot and reads earlier ones), already simplified and with common
//! subexpressions shared. The same tape is emitted as Rust by kinegen-codegen and
//! interpreted here by [`Function::eval`], so a freshly edited spec can be fitted
//! without compiling anything.
use crate::jit::NativeCache;
use crate::spec::{
    Input, Noise, Observation, ObservationRole, Param, DEFAULT_GYRO_COLUMN, DEFAULT_POSE_COLUMNS,
};
use serde::{Deserialize, Serialize};

/// One tape instruction. Operands are indices of earlier slots.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Op {
    Const(f64),
    /// Element `index` of argument `arg` of the function.
    Arg(u16, u16),
    Add(u32, u32),
    Sub(u32, u32),
    Mul(u32, u32),
    Div(u32, u32),
    Neg(u32),
    PowI(u32, i32),
    Pow(u32, u32),
    Sqrt(u32),
    Sin(u32),
    Cos(u32),
    Tan(u32),
    Atan(u32),
    Atan2(u32, u32),
    Exp(u32),
    Ln(u32),
    Abs(u32),
    /// `if |x| < eps { near } else { far }`: the series branch that replaces a
    /// removable singularity at x = 0.
    NearZero {
        x: u32,
        eps: f64,
        near: u32,
        far: u32,
    },
    /// Entry (i, j) of the pseudo-inverse of the symmetric positive semi-definite
    /// 3x3 matrix whose packed upper triangle is in `m` ([`crate::linalg::pinv_sym3`],
    /// with its rank check). Least-squares kinematics (seed 000 eq. 9-10).
    PinvSym3 {
        m: [u32; 6],
        i: u8,
        j: u8,
    },
}

impl Op {
    /// Slots this op reads.
    pub fn operands(&self) -> Vec<u32> {
        use Op::*;
        match *self {
            Const(_) | Arg(..) => vec![],
            Add(a, b) | Sub(a, b) | Mul(a, b) | Div(a, b) | Pow(a, b) | Atan2(a, b) => vec![a, b],
            Neg(a)
            | PowI(a, _)
            | Sqrt(a)
            | Sin(a)
            | Cos(a)
            | Tan(a)
            | Atan(a)
            | Exp(a)
            | Ln(a)
            | Abs(a) => vec![a],
            NearZero { x, near, far, .. } => vec![x, near, far],
            PinvSym3 { m, .. } => m.to_vec(),
        }
    }

    /// The same op reading slot `m(r)` wherever it read `r`.
    pub fn remap(&self, m: impl Fn(u32) -> u32) -> Op {
        use Op::*;
        match *self {
            Add(a, b) => Add(m(a), m(b)),
            Sub(a, b) => Sub(m(a), m(b)),
            Mul(a, b) => Mul(m(a), m(b)),
            Div(a, b) => Div(m(a), m(b)),
            Pow(a, b) => Pow(m(a), m(b)),
            Atan2(a, b) => Atan2(m(a), m(b)),
            Neg(a) => Neg(m(a)),
            PowI(a, n) => PowI(m(a), n),
            Sqrt(a) => Sqrt(m(a)),
            Sin(a) => Sin(m(a)),
            Cos(a) => Cos(m(a)),
            Tan(a) => Tan(m(a)),
            Atan(a) => Atan(m(a)),
            Exp(a) => Exp(m(a)),
            Ln(a) => Ln(m(a)),
            Abs(a) => Abs(m(a)),
            NearZero { x, eps, near, far } => NearZero {
                x: m(x),
                eps,
                near: m(near),
                far: m(far),
            },
            PinvSym3 { m: mm, i, j } => PinvSym3 { m: mm.map(m), i, j },
            Const(c) => Const(c),
            Arg(a, k) => Arg(a, k),
        }
    }

    /// Whether the op costs a floating-point operation (constants and argument
    /// reads do not).
    pub fn is_arithmetic(&self) -> bool {
        !matches!(self, Op::Const(_) | Op::Arg(..))
    }
}

/// A named argument of a derived function: a vector of `names.len()` values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ArgSpec {
    /// Rust-side argument name (`x`, `u`, `w`, `p`, `dt`, `lm`, `twist`, `dpose`).
    pub name: String,
    pub names: Vec<String>,
}

/// A derived function: output matrix of `rows x cols` (cols = 1 for vectors),
/// stored row-major in `outputs`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Function {
    pub name: String,
    pub doc: String,
    pub args: Vec<ArgSpec>,
    pub rows: usize,
    pub cols: usize,
    pub row_names: Vec<String>,
    pub col_names: Vec<String>,
    pub tape: Vec<Op>,
    pub outputs: Vec<u32>,
    /// Arithmetic operations if every output were evaluated as its own tree
    /// (before common-subexpression elimination).
    pub ops_tree: usize,
    /// The tape compiled to machine code once it is hot (see [`crate::jit`]);
    /// derived from `tape`, so never serialised.
    #[serde(skip)]
    pub native: NativeCache,
}

impl Function {
    /// Arithmetic operations on the tape (after CSE).
    pub fn ops_tape(&self) -> usize {
        self.tape.iter().filter(|o| o.is_arithmetic()).count()
    }

    /// Is the output a matrix (Jacobian) rather than a vector?
    pub fn is_matrix(&self) -> bool {
        self.cols > 1
    }

    /// Evaluate into `out` (length rows*cols, row-major). `scratch` is reused
    /// between calls to avoid allocation in loops. A hot tape runs as machine
    /// code ([`crate::jit`]), with the interpreter's results to the last bit.
    pub fn eval_into(&self, args: &[&[f64]], out: &mut [f64], scratch: &mut Vec<f64>) {
        if let Some(native) = self.native.get(self) {
            if native.eval_into(args, out).is_some() {
                return;
            }
        }
        self.interpret_into(args, out, scratch)
    }

    /// Evaluate by interpreting the tape (the reference [`Function::eval_into`]
    /// compiles).
    pub fn interpret_into(&self, args: &[&[f64]], out: &mut [f64], scratch: &mut Vec<f64>) {
        debug_assert_eq!(args.len(), self.args.len());
        scratch.clear();
        scratch.reserve(self.tape.len());
        // the pseudo-inverse of one matrix is read entry by entry: decompose it once
        let mut pinv_cache: Option<([u32; 6], [f64; 6])> = None;
        for op in &self.tape {
            let s = &*scratch;
            let v = |i: u32| s[i as usize];
            let val = match *op {
                Op::Const(c) => c,
                Op::Arg(a, i) => args[a as usize][i as usize],
                Op::Add(a, b) => v(a) + v(b),
                Op::Sub(a, b) => v(a) - v(b),
                Op::Mul(a, b) => v(a) * v(b),
                Op::Div(a, b) => v(a) / v(b),
                Op::Neg(a) => -v(a),
                Op::PowI(a, n) => v(a).powi(n),
                Op::Pow(a, b) => v(a).powf(v(b)),
                Op::Sqrt(a) => v(a).sqrt(),
                Op::Sin(a) => v(a).sin(),
                Op::Cos(a) => v(a).cos(),
                Op::Tan(a) => v(a).tan(),
                Op::Atan(a) => v(a).atan(),
                Op::Atan2(a, b) => v(a).atan2(v(b)),
                Op::Exp(a) => v(a).exp(),
                Op::Ln(a) => v(a).ln(),
                Op::Abs(a) => v(a).abs(),
                Op::NearZero { x, eps, near, far } => {
                    if v(x).abs() < eps {
                        v(near)
                    } else {
                        v(far)
                    }
                }
                Op::PinvSym3 { m, i, j } => {
                    let p = match pinv_cache {
                        Some((key, p)) if key == m => p,
                        _ => {
                            let p = crate::linalg::pinv_sym3(m.map(v));
                            pinv_cache = Some((m, p));
                            p
                        }
                    };
                    p[crate::linalg::packed_index(i as usize, j as usize)]
                }
            };
            scratch.push(val);
        }
        for (o, &slot) in out.iter_mut().zip(&self.outputs) {
            *o = scratch[slot as usize];
        }
    }

    /// Convenience allocation-per-call evaluation.
    pub fn eval(&self, args: &[&[f64]]) -> Vec<f64> {
        let mut out = vec![0.0; self.rows * self.cols];
        self.eval_into(args, &mut out, &mut Vec::new());
        out
    }
}

/// Everything the analysis side needs to know about a derived model.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelIr {
    pub name: String,
    pub doc: String,
    pub seed: String,
    /// Fingerprint of the spec text this IR was derived from.
    pub spec_fingerprint: String,
    pub inputs: Vec<Input>,
    /// All parameters; `constant` ones are folded into the tapes.
    pub params: Vec<Param>,
    pub noise: Vec<Noise>,
    pub observations: Vec<Observation>,
    pub effects: Vec<String>,
    pub functions: Vec<Function>,
}

impl ModelIr {
    pub fn function(&self, name: &str) -> Option<&Function> {
        self.functions.iter().find(|f| f.name == name)
    }

    /// The observation that plays `role`, if the model has one.
    pub fn observation(&self, role: ObservationRole) -> Option<&Observation> {
        self.observations.iter().find(|o| o.role == role)
    }

    /// The derived function of the observation that plays `role`: `part` is ""
    /// for the prediction, "_jac_x" or "_jac_p" for its Jacobians.
    pub fn observation_fn(&self, role: ObservationRole, part: &str) -> Option<&Function> {
        self.observation(role)
            .and_then(|o| self.function(&format!("obs_{}{part}", o.name)))
    }

    /// Log columns of the measured pose: the pose observation's, or the contract's
    /// default `gt_x, gt_y, gt_theta` when the model measures the body origin.
    pub fn pose_columns(&self) -> [String; 3] {
        match self.observation(ObservationRole::Pose) {
            Some(o) => [0, 1, 2].map(|i| o.columns[i].clone()),
            None => DEFAULT_POSE_COLUMNS.map(String::from),
        }
    }

    /// Log column of the measured yaw rate (the yaw-rate observation's, or `gyro_z`).
    pub fn gyro_column(&self) -> String {
        self.observation(ObservationRole::YawRate)
            .map_or(DEFAULT_GYRO_COLUMN.to_string(), |o| o.columns[0].clone())
    }

    /// Parameters passed at run time (non-const), in argument order.
    pub fn runtime_params(&self) -> Vec<&Param> {
        self.params.iter().filter(|p| !p.constant).collect()
    }

    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("IR serialises")
    }

    pub fn from_json(text: &str) -> Result<ModelIr, serde_json::Error> {
        serde_json::from_str(text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn near_zero_picks_branch() {
        // f(x) = sin(x)/x with series 1 - x^2/6 near zero
        let tape = vec![
            Op::Arg(0, 0),
            Op::Sin(0),
            Op::Div(1, 0),
            Op::PowI(0, 2),
            Op::Const(-1.0 / 6.0),
            Op::Mul(3, 4),
            Op::Const(1.0),
            Op::Add(5, 6),
            Op::NearZero {
                x: 0,
                eps: 1e-3,
                near: 7,
                far: 2,
            },
        ];
        let f = Function {
            name: "sinc".into(),
            doc: String::new(),
            args: vec![ArgSpec {
                name: "a".into(),
                names: vec!["a".into()],
            }],
            rows: 1,
            cols: 1,
            row_names: vec![],
            col_names: vec![],
            tape,
            outputs: vec![8],
            ops_tree: 0,
            native: Default::default(),
        };
        assert_eq!(f.eval(&[&[0.0]])[0], 1.0);
        assert!((f.eval(&[&[0.5]])[0] - 0.5f64.sin() / 0.5).abs() < 1e-15);
        assert_eq!(f.ops_tape(), 6);
    }
}
