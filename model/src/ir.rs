//! The model IR: what the derivation stage hands to everyone else.
//!
//! Each derived function is a straight-line tape of [`Op`]s in SSA form (every op
//! writes a new slot and reads earlier ones), already simplified and with common
//! subexpressions shared. The same tape is emitted as Rust by kinegen-codegen and
//! interpreted here by [`Function::interpret`] (and compiled, once hot, by
//! kinegen-jit, which keeps the machine code beside the IR), so a freshly
//! edited spec can be fitted without compiling anything.
use crate::decl::{
    Input, Noise, ObservationDecl, ObservationRole, Param, DEFAULT_GYRO_COLUMN,
    DEFAULT_POSE_COLUMNS,
};
pub use crate::kernel::{ArgKind, ArgRole, ArgSpec, Kernel, StepForm, Wrt};
use fnv::FnvHashMap;
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
    /// -1, 0 or 1 (0 at 0, unlike `f64::signum`): the derivative of `abs`, so
    /// a kink at 0 (a deadband's) has a slope there instead of 0/0.
    Sign(u32),
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
            | Abs(a)
            | Sign(a) => vec![a],
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
            Sign(a) => Sign(m(a)),
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

    /// The op's value with its operands' values read by `v`: the one
    /// definition of what each op computes, for the interpreter and for
    /// constant folding ([`crate::autodiff`]). An argument reads as NaN here
    /// (the interpreter reads arguments itself).
    #[inline]
    pub fn apply(&self, v: impl Fn(u32) -> f64) -> f64 {
        match *self {
            Op::Const(c) => c,
            Op::Arg(..) => f64::NAN,
            Op::Add(a, b) => v(a) + v(b),
            Op::Sub(a, b) => v(a) - v(b),
            Op::Mul(a, b) => v(a) * v(b),
            Op::Div(a, b) => v(a) / v(b),
            Op::Neg(a) => -v(a),
            Op::PowI(a, n) => v(a).powi(n),
            Op::Pow(a, b) => v(a).powf(v(b)),
            Op::Sqrt(a) => v(a).sqrt(),
            // libm's, as the generated kernels and the JIT call them (and
            // its sincos gives bit for bit the same pair): one result everywhere
            Op::Sin(a) => libm::sin(v(a)),
            Op::Cos(a) => libm::cos(v(a)),
            Op::Tan(a) => v(a).tan(),
            Op::Atan(a) => v(a).atan(),
            Op::Atan2(a, b) => v(a).atan2(v(b)),
            Op::Exp(a) => v(a).exp(),
            Op::Ln(a) => v(a).ln(),
            Op::Abs(a) => v(a).abs(),
            Op::Sign(a) => sign(v(a)),
            Op::NearZero { x, eps, near, far } => {
                if v(x).abs() < eps {
                    v(near)
                } else {
                    v(far)
                }
            }
            Op::PinvSym3 { m, i, j } => crate::linalg::pinv_sym3(m.map(v))
                [crate::linalg::packed_index(i as usize, j as usize)],
        }
    }
}

/// The sign of `x`: -1, 0 at 0 (either zero), or 1; NaN stays NaN. The one
/// definition the interpreter, the spec language and (through `Op::Sign`) the
/// JIT and the generated `math::sign` agree on.
#[inline]
pub fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        // 0 for +-0, NaN for NaN
        x * 0.0
    }
}

/// A derived function: output matrix of `rows x cols` (cols = 1 for vectors),
/// stored row-major in `outputs`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Function {
    /// Which kernel this is; consumers look kernels up by it.
    pub kernel: Kernel,
    /// The emitted name (derived from `kernel`, see [`Kernel::name`]).
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
}

impl Function {
    /// Arithmetic operations on the tape (after CSE).
    pub fn ops_tape(&self) -> usize {
        self.tape.iter().filter(|o| o.is_arithmetic()).count()
    }

    /// Position of the argument playing `role`, if the function takes it.
    pub fn arg(&self, role: ArgRole) -> Option<usize> {
        self.args.iter().position(|a| a.role == role)
    }

    /// Whether the tape reads element `index` of the argument playing `role`
    /// (a parameter the function does not read cannot change its outputs).
    pub fn reads(&self, role: ArgRole, index: usize) -> bool {
        self.arg(role).is_some_and(|a| {
            self.tape.iter().any(
                |op| matches!(op, Op::Arg(x, k) if usize::from(*x) == a && usize::from(*k) == index),
            )
        })
    }

    /// The |x| thresholds at which the tape's removable-singularity branches
    /// switch to their series (derivation's [`GenOptions`](crate::options::GenOptions)),
    /// each once.
    pub fn series_switches(&self) -> Vec<f64> {
        let mut switches: Vec<f64> = Vec::new();
        for op in &self.tape {
            if let Op::NearZero { eps, .. } = op {
                if !switches.contains(eps) {
                    switches.push(*eps);
                }
            }
        }
        switches
    }

    /// Is the output a matrix (Jacobian) rather than a vector?
    pub fn is_matrix(&self) -> bool {
        self.cols > 1
    }

    /// Evaluate by interpreting the tape (the reference kinegen-jit's machine code
    /// compiles).
    #[inline]
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
                Op::Arg(a, i) => args[a as usize][i as usize],
                ref other => other.apply(v),
            };
            scratch.push(val);
        }
        for (o, &slot) in out.iter_mut().zip(&self.outputs) {
            *o = scratch[slot as usize];
        }
    }

    /// Interpret into a new vector (the analysis evaluates through
    /// kinegen-jit, which compiles hot tapes to the same results).
    pub fn interpret(&self, args: &[&[f64]]) -> Vec<f64> {
        let mut out = vec![0.0; self.rows * self.cols];
        self.interpret_into(args, &mut out, &mut Vec::new());
        out
    }
}

/// Everything the analysis side needs to know about a derived model: the
/// declarations and the kernels, indexed by [`Kernel`] once, when the IR is built
/// or loaded (a loaded IR is checked to have every kernel a model must have).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(try_from = "IrFile", into = "IrFile")]
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
    observations: Vec<ObservationDecl>,
    pub effects: Vec<String>,
    /// Why the model has no inverse kinematics (the twist is not linear in
    /// the inputs and the spec declares no `[inverse]`); `None` when it has.
    pub no_inverse: Option<String>,
    functions: Vec<Function>,
    index: FnvHashMap<Kernel, usize>,
}

/// A model without inverse kinematics, asked for them (`inverse`, `navigate`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("model `{model}` has no inverse kinematics: {reason}")]
pub struct NoInverse {
    pub model: String,
    pub reason: String,
}

/// The IR as stored in `generated/ir/*.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct IrFile {
    pub name: String,
    pub doc: String,
    pub seed: String,
    pub spec_fingerprint: String,
    pub inputs: Vec<Input>,
    pub params: Vec<Param>,
    pub noise: Vec<Noise>,
    pub observations: Vec<ObservationDecl>,
    pub effects: Vec<String>,
    /// See [`ModelIr::no_inverse`] (absent from the file when the model has them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub no_inverse: Option<String>,
    pub functions: Vec<Function>,
}

/// An IR that lacks a kernel every model has, or holds one twice.
#[derive(Debug, thiserror::Error)]
pub enum IrError {
    #[error("model `{0}`: the IR lacks the kernel `{1}` (regenerate it)")]
    Missing(String, String),
    #[error("model `{0}`: the IR holds the kernel `{1}` twice")]
    Duplicate(String, String),
    #[error("model `{0}`: `{1}` is a fused kernel, which an IR never holds")]
    Fused(String, String),
    #[error("model `{0}`: kernel `{1}` refers to observation {2}, which the IR lacks")]
    NoObservation(String, String, u16),
}

impl TryFrom<IrFile> for ModelIr {
    type Error = IrError;

    fn try_from(f: IrFile) -> Result<ModelIr, IrError> {
        let mut index = FnvHashMap::default();
        for (i, k) in f.functions.iter().enumerate() {
            if let Kernel::Observation(o, _) = k.kernel {
                if o as usize >= f.observations.len() {
                    return Err(IrError::NoObservation(f.name, k.name.clone(), o));
                }
            }
            if k.kernel == Kernel::Fused {
                return Err(IrError::Fused(f.name, k.name.clone()));
            }
            if index.insert(k.kernel, i).is_some() {
                return Err(IrError::Duplicate(f.name, k.name.clone()));
            }
        }
        let mut required = vec![Kernel::Twist, Kernel::TwistGyro];
        if f.no_inverse.is_none() {
            required.extend([Kernel::InverseTwist, Kernel::InverseIncrement]);
        }
        for form in [StepForm::Exact, StepForm::Euler] {
            required.push(Kernel::Step(form, None));
            required.push(Kernel::Step(form, Some(Wrt::State)));
        }
        for o in 0..f.observations.len() as u16 {
            required.push(Kernel::Observation(o, None));
            required.push(Kernel::Observation(o, Some(Wrt::State)));
        }
        if let Some(k) = required.into_iter().find(|k| !index.contains_key(k)) {
            let name = k.name(|o| f.observations[o as usize].name.clone());
            return Err(IrError::Missing(f.name, name));
        }
        Ok(ModelIr {
            name: f.name,
            doc: f.doc,
            seed: f.seed,
            spec_fingerprint: f.spec_fingerprint,
            inputs: f.inputs,
            params: f.params,
            noise: f.noise,
            observations: f.observations,
            effects: f.effects,
            no_inverse: f.no_inverse,
            functions: f.functions,
            index,
        })
    }
}

impl From<ModelIr> for IrFile {
    fn from(ir: ModelIr) -> IrFile {
        IrFile {
            name: ir.name,
            doc: ir.doc,
            seed: ir.seed,
            spec_fingerprint: ir.spec_fingerprint,
            inputs: ir.inputs,
            params: ir.params,
            noise: ir.noise,
            observations: ir.observations,
            effects: ir.effects,
            no_inverse: ir.no_inverse,
            functions: ir.functions,
        }
    }
}

/// The kernels of one discretisation: the step and its Jacobians.
#[derive(Debug, Clone, Copy)]
pub struct StepKernels<'a> {
    pub value: &'a Function,
    pub jac_x: &'a Function,
    /// Absent when the model has no inputs, noise or runtime parameters.
    pub jac_u: Option<&'a Function>,
    pub jac_w: Option<&'a Function>,
    pub jac_p: Option<&'a Function>,
}

/// An observation with its prediction and Jacobians.
#[derive(Debug, Clone, Copy)]
pub struct ObservationKernels<'a> {
    pub decl: &'a ObservationDecl,
    pub value: &'a Function,
    pub jac_x: &'a Function,
    /// Absent when the model has no runtime parameters.
    pub jac_p: Option<&'a Function>,
}

impl ModelIr {
    /// The kernel `k`, if the model has it.
    pub fn kernel(&self, k: Kernel) -> Option<&Function> {
        self.index.get(&k).map(|&i| &self.functions[i])
    }

    /// A kernel every model has (checked when the IR was built or loaded).
    fn required(&self, k: Kernel) -> &Function {
        self.kernel(k).expect("checked by ModelIr::try_from")
    }

    /// Every kernel, in derivation order.
    pub fn functions(&self) -> &[Function] {
        &self.functions
    }

    /// The emitted name of kernel `k` (also for kernels the model lacks).
    pub fn kernel_name(&self, k: Kernel) -> String {
        k.name(|o| {
            self.observations
                .get(o as usize)
                .map_or_else(|| format!("#{o}"), |d| d.name.clone())
        })
    }

    /// Body twist from the inputs.
    pub fn twist(&self) -> &Function {
        self.required(Kernel::Twist)
    }

    /// Body velocity with a measured yaw rate.
    pub fn twist_gyro(&self) -> &Function {
        self.required(Kernel::TwistGyro)
    }

    /// The step of one discretisation with its Jacobians.
    pub fn step(&self, form: StepForm) -> StepKernels<'_> {
        let k = |w| self.kernel(Kernel::Step(form, w));
        StepKernels {
            value: self.required(Kernel::Step(form, None)),
            jac_x: self.required(Kernel::Step(form, Some(Wrt::State))),
            jac_u: k(Some(Wrt::Inputs)),
            jac_w: k(Some(Wrt::Noise)),
            jac_p: k(Some(Wrt::Params)),
        }
    }

    /// Inputs from a body twist, where the model has inverse kinematics.
    pub fn inverse_twist(&self) -> Result<&Function, NoInverse> {
        self.inverse(Kernel::InverseTwist)
    }

    /// Inputs from a pose increment over dt, where the model has inverse kinematics.
    pub fn inverse_increment(&self) -> Result<&Function, NoInverse> {
        self.inverse(Kernel::InverseIncrement)
    }

    fn inverse(&self, k: Kernel) -> Result<&Function, NoInverse> {
        self.kernel(k).ok_or_else(|| NoInverse {
            model: self.name.clone(),
            reason: self
                .no_inverse
                .clone()
                .unwrap_or_else(|| "the IR lacks it (regenerate it)".into()),
        })
    }

    /// Every observation the spec declares.
    pub fn observations(&self) -> &[ObservationDecl] {
        &self.observations
    }

    /// The kernels of observation number `i`.
    pub fn observation_kernels_at(&self, i: usize) -> ObservationKernels<'_> {
        let k = |w| Kernel::Observation(i as u16, w);
        ObservationKernels {
            decl: &self.observations[i],
            value: self.required(k(None)),
            jac_x: self.required(k(Some(Wrt::State))),
            jac_p: self.kernel(k(Some(Wrt::Params))),
        }
    }

    /// The observation that plays `role`, if the model has one.
    pub fn observation(&self, role: ObservationRole) -> Option<&ObservationDecl> {
        self.observations.iter().find(|o| o.role == role)
    }

    /// The kernels of the observation that plays `role`, if the model has one.
    pub fn observation_kernels(&self, role: ObservationRole) -> Option<ObservationKernels<'_>> {
        let i = self.observations.iter().position(|o| o.role == role)?;
        Some(self.observation_kernels_at(i))
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
            kernel: Kernel::Twist,
            name: "sinc".into(),
            doc: String::new(),
            args: vec![ArgSpec {
                role: ArgRole::Values,
                names: vec!["a".into()],
            }],
            rows: 1,
            cols: 1,
            row_names: vec![],
            col_names: vec![],
            tape,
            outputs: vec![8],
            ops_tree: 0,
        };
        assert_eq!(f.interpret(&[&[0.0]])[0], 1.0);
        assert!((f.interpret(&[&[0.5]])[0] - 0.5f64.sin() / 0.5).abs() < 1e-15);
        assert_eq!(f.ops_tape(), 6);
    }

    /// `reads` sees which elements of which argument the tape loads: p[1]
    /// of (x, p), not p[0], not x[1], and nothing of a role it does not take.
    #[test]
    fn reads_names_the_loaded_elements() {
        let arg = |role, n: usize| ArgSpec {
            role,
            names: (0..n).map(|i| format!("a{i}")).collect(),
        };
        let f = Function {
            kernel: Kernel::Twist,
            name: "f".into(),
            doc: String::new(),
            args: vec![arg(ArgRole::State, 3), arg(ArgRole::Params, 2)],
            rows: 1,
            cols: 1,
            row_names: vec![],
            col_names: vec![],
            tape: vec![Op::Arg(0, 0), Op::Arg(1, 1), Op::Mul(0, 1)],
            outputs: vec![2],
            ops_tree: 0,
        };
        assert!(f.reads(ArgRole::Params, 1));
        assert!(!f.reads(ArgRole::Params, 0));
        assert!(f.reads(ArgRole::State, 0));
        assert!(!f.reads(ArgRole::State, 1));
        assert!(!f.reads(ArgRole::Inputs, 0));
    }
}
