//! The kernels the analysis uses, each built on its own tape: the twist
//! (explicit, or seed 000's least squares over constraint rows, eq. 9-10),
//! gyrodometry (eq. 17), the Euler and exact steps (seed 003; seed 001 eq. 3),
//! the observations, and their Jacobians by [`super::forward`]. Kernel
//! names, arguments and row/column names are the symbolic stage's, so either
//! IR serves every consumer.
use super::builder::Builder;
use super::forward::jacobian;
use super::lower::Scope;
use crate::ir::{ArgRole, ArgSpec, Function, Kernel, Op, StepForm, Wrt};
use crate::linalg::packed_index;
use crate::options::GenOptions;
use crate::spec::{Kinematics, Model, STATE};
use crate::SourceError;

/// The arguments kernels take, by role, in the order the symbolic stage
/// gives them.
struct Args {
    state: ArgSpec,
    inputs: ArgSpec,
    noise: ArgSpec,
    params: ArgSpec,
    dt: ArgSpec,
}

fn spec(role: ArgRole, names: impl IntoIterator<Item = impl Into<String>>) -> ArgSpec {
    ArgSpec {
        role,
        names: names.into_iter().map(Into::into).collect(),
    }
}

impl Args {
    fn new(model: &Model) -> Args {
        Args {
            state: spec(ArgRole::State, STATE),
            inputs: spec(ArgRole::Inputs, model.inputs.iter().map(|i| i.name.clone())),
            noise: spec(ArgRole::Noise, model.noise.iter().map(|n| n.name.clone())),
            params: spec(
                ArgRole::Params,
                model.runtime_params().map(|p| p.name.clone()),
            ),
            dt: spec(ArgRole::Dt, ["dt"]),
        }
    }

    /// A step's arguments (the noise where the model has some).
    fn step(&self) -> Vec<ArgSpec> {
        let mut v = vec![self.state.clone(), self.inputs.clone()];
        if !self.noise.names.is_empty() {
            v.push(self.noise.clone());
        }
        v.extend([self.params.clone(), self.dt.clone()]);
        v
    }
}

/// How a kernel's outputs are written, in the names its arguments bind.
type Outputs<'r> = dyn Fn(&mut Builder, &mut Scope) -> Result<Vec<u32>, SourceError> + 'r;

/// One kernel to build: what it is, its arguments, and how its outputs are
/// written in the names the arguments bind.
struct Recipe<'r> {
    kernel: Kernel,
    doc: String,
    args: Vec<ArgSpec>,
    row_names: Vec<String>,
    /// Differentiate the outputs with respect to this argument.
    wrt: Option<ArgRole>,
    outputs: &'r Outputs<'r>,
}

/// Every kernel of `model`, in the symbolic stage's order.
pub fn all(model: &Model, options: &GenOptions) -> Result<Vec<Function>, SourceError> {
    let args = Args::new(model);
    let mut functions = Vec::new();
    let mut make = |r: Recipe| -> Result<(), SourceError> {
        functions.push(build(model, r)?);
        Ok(())
    };
    make(Recipe {
        kernel: Kernel::Twist,
        doc: format!("Body twist [vx, vy, omega] (m/s, m/s, rad/s) from the inputs: the forward kinematics. {}", model.motion_doc),
        args: vec![args.inputs.clone(), args.params.clone()],
        row_names: names(["vx", "vy", "omega"]),
        wrt: None,
        outputs: &|b, s| Ok(twist(model, b, s, false)?.to_vec()),
    })?;
    make(Recipe {
        kernel: Kernel::TwistGyro,
        doc: "Gyrodometry (seed 000 eq. 13-18): body velocity [vx, vy] with the yaw rate `omega` measured.".into(),
        args: vec![
            args.inputs.clone(),
            spec(ArgRole::YawRate, ["omega"]),
            args.params.clone(),
        ],
        row_names: names(["vx", "vy"]),
        wrt: None,
        outputs: &|b, s| gyro_twist(model, b, s),
    })?;
    let groups = [
        (Wrt::State, &args.state),
        (Wrt::Inputs, &args.inputs),
        (Wrt::Noise, &args.noise),
        (Wrt::Params, &args.params),
    ];
    for form in [StepForm::Euler, StepForm::Exact] {
        let outputs = |b: &mut Builder, s: &mut Scope| step(model, options, form, b, s);
        let value = Kernel::Step(form, None);
        let jacobians = groups.iter().filter(|(_, a)| !a.names.is_empty());
        for wrt in std::iter::once(None).chain(jacobians.map(|(w, _)| Some(*w))) {
            make(Recipe {
                kernel: wrt.map_or(value, |w| value.jacobian(w)),
                doc: step_doc(form, wrt),
                args: args.step(),
                row_names: names(["x", "y", "theta"]),
                wrt: wrt.map(Wrt::role),
                outputs: &outputs,
            })?;
        }
    }
    for (index, o) in model.observations.iter().enumerate() {
        let mut obs_args = vec![args.state.clone(), args.inputs.clone(), args.params.clone()];
        if o.landmark {
            obs_args.push(spec(ArgRole::Landmark, ["xl", "yl"]));
        }
        let outputs = |b: &mut Builder, s: &mut Scope| {
            let [vx, vy, omega] = twist(model, b, s, false)?;
            for (n, slot) in [("vx", vx), ("vy", vy), ("omega", omega)] {
                s.bind(n, slot);
            }
            o.exprs.iter().map(|e| s.lower(b, e)).collect()
        };
        let value = Kernel::Observation(index as u16, None);
        let mut wrts = vec![None, Some(Wrt::State)];
        if !args.params.names.is_empty() {
            wrts.push(Some(Wrt::Params));
        }
        for wrt in wrts {
            make(Recipe {
                kernel: wrt.map_or(value, |w| value.jacobian(w)),
                doc: match wrt {
                    None if o.doc.is_empty() => format!("Observation `{}`.", o.name),
                    None => o.doc.clone(),
                    Some(w) => format!(
                        "Jacobian of `obs_{}` with respect to the {}.",
                        o.name,
                        what(w)
                    ),
                },
                args: obs_args.clone(),
                row_names: o.columns.clone(),
                wrt: wrt.map(Wrt::role),
                outputs: &outputs,
            })?;
        }
    }
    Ok(functions)
}

fn names<const N: usize>(v: [&str; N]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

fn what(w: Wrt) -> &'static str {
    match w {
        Wrt::State => "state",
        Wrt::Inputs => "inputs",
        Wrt::Noise => "noise inputs",
        Wrt::Params => "parameters",
    }
}

fn step_doc(form: StepForm, wrt: Option<Wrt>) -> String {
    let name = Kernel::Step(form, None).name(|_| String::new());
    match (form, wrt) {
        (StepForm::Euler, None) => "Euler step (seed 003; seed 001 eq. 3): pose advanced along the body twist held at the start-of-step heading.".into(),
        (StepForm::Exact, None) => "Exact step: the pose after moving with the constant body twist for dt along an arc on SE(2) (seed 003). Finite and continuous at omega = 0 (series branch).".into(),
        (_, Some(w)) => format!("Jacobian of `{name}` with respect to the {}; rows x, y, theta.", what(w)),
    }
}

/// Build one kernel: bind its arguments, write its outputs, differentiate
/// them if asked, and finish the tape.
fn build(model: &Model, r: Recipe) -> Result<Function, SourceError> {
    let mut b = Builder::default();
    let mut scope = Scope::new(model);
    for p in model.params.iter().filter(|p| p.constant) {
        let slot = b.c(p.nominal);
        scope.bind(&p.name, slot);
    }
    let mut wrt_slots = Vec::new();
    for (ai, a) in r.args.iter().enumerate() {
        for (k, name) in a.names.iter().enumerate() {
            let slot = b.arg(ai, k);
            scope.bind(name, slot);
            if Some(a.role) == r.wrt {
                wrt_slots.push(slot);
            }
        }
    }
    for n in &model.noise {
        if scope.slot(&n.name).is_none() {
            scope.refuse(&n.name, "noise enters the motion only");
        }
    }
    let values = (r.outputs)(&mut b, &mut scope)?;
    let (rows, cols, col_names, outputs) = match r.wrt {
        None => (values.len(), 1, vec![], values),
        Some(role) => {
            let col_names = r
                .args
                .iter()
                .find(|a| a.role == role)
                .map(|a| a.names.clone())
                .unwrap_or_default();
            let j = jacobian(&mut b, &values, &wrt_slots);
            (values.len(), wrt_slots.len(), col_names, j)
        }
    };
    let name = r
        .kernel
        .name(|o| model.observations[o as usize].name.clone());
    if b.nonfinite {
        return Err(SourceError::new(
            &model.path,
            None,
            format!(
                "{}: an expression divides by zero where the kernels evaluate it, at zero noise (a noise input in a denominator, such as `w/dv`); noise must leave the model defined at zero (add it, or scale by 1 + noise)",
                name
            ),
        ));
    }
    let (tape, outputs) = crate::passes::finish(b.into_tape(), &outputs);
    let ops_tree = crate::passes::tree_size(&tape, &outputs);
    Ok(Function {
        kernel: r.kernel,
        name,
        doc: r.doc,
        args: r.args,
        rows,
        cols,
        row_names: r.row_names,
        col_names,
        tape,
        outputs,
        ops_tree,
    })
}

/// The body twist [vx, vy, omega]; with the noise inputs as the scope binds
/// them when `noisy`, at zero otherwise.
fn twist(
    model: &Model,
    b: &mut Builder,
    scope: &Scope,
    noisy: bool,
) -> Result<[u32; 3], SourceError> {
    let mut s = motion_scope(model, scope);
    for n in &model.noise {
        match scope.slot(&n.name) {
            Some(slot) if noisy => s.bind(&n.name, slot),
            _ => {
                let zero = b.c(0.0);
                s.bind(&n.name, zero);
            }
        }
    }
    match &model.kinematics {
        Kinematics::Twist(t) => {
            let [vx, vy, om] = t;
            Ok([s.lower(b, vx)?, s.lower(b, vy)?, s.lower(b, om)?])
        }
        Kinematics::Constraints(c) => {
            let rows = constraint_rows(b, &mut s, c)?;
            let m = normal_matrix(b, &rows, 3);
            let stq: Vec<u32> = (0..3)
                .map(|a| sum(b, rows.iter().map(|(q, r)| (r[a], *q))))
                .collect();
            let mut z = [0; 3];
            for (k, zk) in z.iter_mut().enumerate() {
                let terms: Vec<(u32, u32)> = (0..3).map(|j| (pinv(b, m, k, j), stq[j])).collect();
                let solved = sum(b, terms.into_iter());
                *zk = match &c.noise[k] {
                    Some(n) => {
                        let w = s.slot(n).unwrap_or_else(|| b.c(0.0));
                        b.add(solved, w)
                    }
                    None => solved,
                };
            }
            Ok(z)
        }
    }
}

/// A scope of its own for the twist, with `scope`'s inputs and parameters:
/// a definition lowered there that reads the noise has one value with it
/// and another without.
fn motion_scope<'m>(model: &'m Model, scope: &Scope) -> Scope<'m> {
    let mut s = Scope::new(model);
    for n in model
        .inputs
        .iter()
        .map(|i| &i.name)
        .chain(model.params.iter().map(|p| &p.name))
    {
        if let Some(slot) = scope.slot(n) {
            s.bind(n, slot);
        }
    }
    s
}

/// Each constraint row's measured rate and coefficients [S_vx, S_vy, S_omega]
/// (seed 000 eq. 7).
fn constraint_rows(
    b: &mut Builder,
    s: &mut Scope,
    c: &crate::spec::Constraints,
) -> Result<Vec<(u32, [u32; 3])>, SourceError> {
    c.rows
        .iter()
        .map(|(rate, co)| {
            let q = s.slot(rate).unwrap_or_else(|| b.c(0.0));
            Ok((
                q,
                [
                    s.lower(b, &co[0])?,
                    s.lower(b, &co[1])?,
                    s.lower(b, &co[2])?,
                ],
            ))
        })
        .collect()
}

/// The packed upper triangle of S^T S over the first `n` columns (the
/// others zero, with a 1 on the diagonal: gyrodometry's 2-column problem
/// embedded in the 3x3 pseudo-inverse).
fn normal_matrix(b: &mut Builder, rows: &[(u32, [u32; 3])], n: usize) -> [u32; 6] {
    [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)].map(|(i, j)| {
        if i < n && j < n {
            sum(b, rows.iter().map(|(_, r)| (r[i], r[j])))
        } else {
            b.c(if i == j { 1.0 } else { 0.0 })
        }
    })
}

/// Entry (i, j) of the pseudo-inverse of the packed symmetric `m`.
fn pinv(b: &mut Builder, m: [u32; 6], i: usize, j: usize) -> u32 {
    let (i, j) = if i <= j { (i, j) } else { (j, i) };
    debug_assert!(packed_index(i, j) < 6);
    b.push(Op::PinvSym3 {
        m,
        i: i as u8,
        j: j as u8,
    })
}

/// sum of a_k * b_k.
fn sum(b: &mut Builder, terms: impl Iterator<Item = (u32, u32)>) -> u32 {
    let mut acc = b.c(0.0);
    for (x, y) in terms {
        let p = b.mul(x, y);
        acc = b.add(acc, p);
    }
    acc
}

/// Gyrodometry's body velocity [vx, vy] with the yaw rate measured: the
/// twist's rows for an explicit twist; for constraints, eq. 17's least
/// squares with theta' imposed.
fn gyro_twist(model: &Model, b: &mut Builder, scope: &mut Scope) -> Result<Vec<u32>, SourceError> {
    let Kinematics::Constraints(c) = &model.kinematics else {
        return Ok(twist(model, b, scope, false)?[..2].to_vec());
    };
    let omega = scope.slot("omega").expect("the yaw-rate argument is bound");
    let mut s = motion_scope(model, scope);
    let rows = constraint_rows(b, &mut s, c)?;
    let m = normal_matrix(b, &rows, 2);
    let rhs: Vec<u32> = (0..2)
        .map(|a| {
            let terms: Vec<(u32, u32)> = rows
                .iter()
                .map(|(q, r)| {
                    let turn = b.mul(r[2], omega);
                    (r[a], b.sub(*q, turn))
                })
                .collect();
            sum(b, terms.into_iter())
        })
        .collect();
    Ok((0..2)
        .map(|k| {
            let terms: Vec<(u32, u32)> = (0..2).map(|j| (pinv(b, m, k, j), rhs[j])).collect();
            sum(b, terms.into_iter())
        })
        .collect())
}

/// The pose after one step of `form` with the noisy twist.
fn step(
    model: &Model,
    options: &GenOptions,
    form: StepForm,
    b: &mut Builder,
    s: &mut Scope,
) -> Result<Vec<u32>, SourceError> {
    let [vx, vy, om] = twist(model, b, s, true)?;
    let [x, y, th, dt] = ["x", "y", "theta", "dt"].map(|n| s.slot(n).expect("bound argument"));
    let (c, sn) = (b.push(Op::Cos(th)), b.push(Op::Sin(th)));
    let turn = b.mul(om, dt);
    // the displacement in the start-of-step body frame
    let (bx, by) = match form {
        StepForm::Euler => (b.mul(vx, dt), b.mul(vy, dt)),
        StepForm::Exact => {
            let sinc = near_zero(b, options, turn, Arc::Sinc);
            let cosc = near_zero(b, options, turn, Arc::Cosc);
            let (a, d) = (b.mul(vx, dt), b.mul(vy, dt));
            let (sa, cd) = (b.mul(sinc, a), b.mul(cosc, d));
            let (ca, sd) = (b.mul(cosc, a), b.mul(sinc, d));
            (b.sub(sa, cd), b.add(ca, sd))
        }
    };
    let (cbx, sby) = (b.mul(c, bx), b.mul(sn, by));
    let (sbx, cby) = (b.mul(sn, bx), b.mul(c, by));
    let (dx, dy) = (b.sub(cbx, sby), b.add(sbx, cby));
    Ok(vec![b.add(x, dx), b.add(y, dy), b.add(th, turn)])
}

/// The two functions of the exact step with a removable singularity at 0.
#[derive(Clone, Copy)]
enum Arc {
    /// sin(d)/d
    Sinc,
    /// (1 - cos d)/d
    Cosc,
}

/// `f(d)` in closed form, and below the series switch its Taylor series
/// (sin d / d = sum (-1)^k d^2k/(2k+1)!, (1 - cos d)/d = sum (-1)^k
/// d^(2k+1)/(2k+2)!), two orders beyond the symbolic stage's so its
/// derivative (the series of the derivative, one order less) is as
/// accurate as the value there.
fn near_zero(b: &mut Builder, options: &GenOptions, d: u32, f: Arc) -> u32 {
    let far = match f {
        Arc::Sinc => {
            let s = b.push(Op::Sin(d));
            b.div(s, d)
        }
        Arc::Cosc => {
            let one = b.c(1.0);
            let c = b.push(Op::Cos(d));
            let num = b.sub(one, c);
            b.div(num, d)
        }
    };
    let order = options.series_order.max(2) + 2;
    let first = match f {
        Arc::Sinc => 1u32,
        Arc::Cosc => 2,
    };
    // coefficients of d^(first-1+2k): (-1)^k / (first+2k)!
    let mut coefficients = Vec::new();
    let mut k = 0u32;
    while i64::from(first - 1 + 2 * k) <= order {
        let n = first + 2 * k;
        let factorial: f64 = (1..=n).map(f64::from).product();
        coefficients.push(if k.is_multiple_of(2) { 1.0 } else { -1.0 } / factorial);
        k += 1;
    }
    // Horner in d^2
    let d2 = b.mul(d, d);
    let mut acc = b.c(*coefficients.last().expect("at least one term"));
    for &cf in coefficients.iter().rev().skip(1) {
        let scaled = b.mul(acc, d2);
        let c = b.c(cf);
        acc = b.add(c, scaled);
    }
    let near = match f {
        Arc::Sinc => acc,
        Arc::Cosc => b.mul(d, acc),
    };
    b.push(Op::NearZero {
        x: d,
        eps: options.series_switch,
        near,
        far,
    })
}
