//! The derivation stage: spec -> symbolica -> model IR.
//!
//! Everything symbolic in kinegen happens here, on the calling thread. The result,
//! a [`ModelIr`], is symbolica-free and is what the emitter and the analysis use.
//!
//! Removable singularities are handled generically: every derived expression is
//! scanned for a denominator that vanishes when a designated increment symbol is 0
//! (the exact-integration rotation `dth = omega*dt`, the pose increment `dtheta` of
//! the integrated inverse). Such an output gets a Taylor series in that symbol,
//! computed by symbolica, and a `NearZero` branch that uses it below the
//! [`GenOptions`]' switch (the options are a value the caller passes). If the
//! series still has negative powers the singularity is not removable and derivation
//! fails instead of emitting code that blows up.
use crate::symbolic::{
    check_no_placeholder, lsq_entry, number_f64, pinv_entry, to_atom, Funcs, SymbolicError,
};
use crate::tape::TapeBuilder;
use kinegen_model::expr::Expr;
use kinegen_model::ir::{ArgRole, ArgSpec, Function, Kernel, ModelIr, Op, StepForm, Wrt};
use kinegen_model::options::GenOptions;
use kinegen_model::spec::{Constraints, InputKind, Kinematics, Model, STATE};
use kinegen_model::{SourceError, SourcePos};
use std::collections::HashMap;
use symbolica::atom::{Atom, AtomCore, AtomView, Symbol};
use symbolica::poly::series::SeriesDepth;
use symbolica::symbol;

struct Sym {
    fx: Funcs,
    by_name: HashMap<String, Atom>,
    /// Where the series branches switch and their order.
    options: GenOptions,
}

impl Sym {
    fn s(&self, name: &str) -> Symbol {
        self.by_name[name].get_symbol().expect("symbol")
    }
    fn a(&self, name: &str) -> Atom {
        self.by_name[name].clone()
    }
}

/// One argument group of a derived function: its spec and its symbols.
#[derive(Clone)]
struct Arg {
    spec: ArgSpec,
    syms: Vec<Symbol>,
}

fn arg(sym: &Sym, role: ArgRole, names: &[String]) -> Arg {
    Arg {
        spec: ArgSpec {
            role,
            names: names.to_vec(),
        },
        syms: names.iter().map(|n| sym.s(n)).collect(),
    }
}

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

fn err_at(model: &Model, e: &Expr, msg: impl Into<String>) -> SourceError {
    SourceError::new(
        &model.path,
        Some(SourcePos::from_offset(&model.source, e.span.0)),
        msg,
    )
}

fn err_kin(model: &Model, msg: impl Into<String>) -> SourceError {
    SourceError::new(
        &model.path,
        Some(SourcePos::from_offset(&model.source, model.kinematics_at)),
        msg,
    )
}

fn sym_err(model: &Model, e: SymbolicError) -> SourceError {
    SourceError::new(&model.path, None, e.0)
}

fn is_zero(a: &Atom) -> bool {
    a.expand().is_zero()
}

fn substitute(a: &Atom, s: Symbol, by: &Atom) -> Atom {
    a.replace(Atom::var(s).to_pattern()).with(by.to_pattern())
}

/// Does `a` divide by something that vanishes at s = 0? (The closed form inside
/// a `kg_near` already has its series: it does not count.)
fn has_vanishing_denominator(a: AtomView, s: Symbol) -> bool {
    match a {
        AtomView::Pow(p) => {
            let (base, exp) = p.get_base_exp();
            let negative = crate::symbolic::as_f64(exp).is_some_and(|n| n < 0.0);
            if negative
                && base.contains_symbol(s)
                && is_zero(&substitute(&base.to_owned(), s, &Atom::num(0)))
            {
                return true;
            }
            has_vanishing_denominator(base, s) || has_vanishing_denominator(exp, s)
        }
        AtomView::Mul(m) => m.iter().any(|x| has_vanishing_denominator(x, s)),
        AtomView::Add(m) => m.iter().any(|x| has_vanishing_denominator(x, s)),
        AtomView::Fun(f) if f.get_symbol() == Funcs::get().near => false,
        AtomView::Fun(f) => f.iter().any(|x| has_vanishing_denominator(x, s)),
        _ => false,
    }
}

/// A derived function before lowering.
struct Spec {
    kernel: Kernel,
    doc: String,
    args: Vec<Arg>,
    /// Intermediates computed once from the arguments (e.g. dth = omega*dt).
    lets: Vec<(Symbol, Atom)>,
    rows: usize,
    cols: usize,
    row_names: Vec<String>,
    col_names: Vec<String>,
    outputs: Vec<Atom>,
    /// Symbols at which removable singularities are looked for.
    singular: Vec<Symbol>,
}

fn lower(
    spec: &Spec,
    fx: Funcs,
    options: &GenOptions,
    cse: bool,
) -> Result<(Vec<Op>, Vec<u32>), SymbolicError> {
    let mut tb = TapeBuilder::new(fx, cse, options.series_switch);
    let order = options.series_order;
    for (ai, a) in spec.args.iter().enumerate() {
        for (i, s) in a.syms.iter().enumerate() {
            let slot = tb.push(Op::Arg(ai as u16, i as u16));
            tb.bind(*s, slot);
        }
    }
    for (s, e) in &spec.lets {
        // a let may itself be singular (sin(dth)/dth of the exact step): it gets
        // its series here, once, instead of in every output that uses it
        let mut e = e.clone();
        for &sing in spec.singular.iter().filter(|&&sing| sing != *s) {
            e = regularize(&e, sing, fx, order)
                .map_err(|err| SymbolicError(format!("{:?} let {s}: {}", spec.kernel, err.0)))?;
        }
        let slot = tb.atom(e.as_view())?;
        tb.bind(*s, slot);
    }
    let mut outs = Vec::new();
    for (k, o) in spec.outputs.iter().enumerate() {
        check_no_placeholder(o, &format!("{:?} output {k}", spec.kernel))?;
        let mut o = o.clone();
        for &s in &spec.singular {
            o = regularize(&o, s, fx, order)
                .map_err(|e| SymbolicError(format!("{:?} output {k}: {}", spec.kernel, e.0)))?;
        }
        outs.push(tb.atom(o.as_view())?);
    }
    Ok(tb.finish(&outs))
}

/// Replace every subexpression with a removable singularity at s = 0 by
/// `kg_near(s, series, closed)`. The whole expression is tried first (singular
/// terms of a sum may cancel only together); if symbolica cannot expand it (e.g. it
/// contains one of our own functions of s) its parts are regularised one by one.
fn regularize(a: &Atom, s: Symbol, fx: Funcs, order: i64) -> Result<Atom, SymbolicError> {
    if !has_vanishing_denominator(a.as_view(), s) {
        return Ok(a.clone());
    }
    let own_fn =
        |f: Symbol| [fx.tan, fx.atan, fx.atan2, fx.abs, fx.sign, fx.pinv, fx.lsq].contains(&f);
    if !matches!(a.as_view(), AtomView::Fun(f) if own_fn(f.get_symbol())) {
        if let Ok(series) = a.series(s, Atom::num(0), SeriesDepth::absolute(order)) {
            let series = series.to_atom();
            if has_negative_power(series.as_view(), s) {
                return Err(SymbolicError(format!(
                    "singular at {} = 0 and the singularity is not removable",
                    Atom::var(s)
                )));
            }
            if !has_vanishing_denominator(series.as_view(), s) {
                check_no_placeholder(&series, "series")?;
                return Ok(symbolica::function!(
                    fx.near,
                    Atom::var(s),
                    horner(&series, s),
                    a.clone()
                ));
            }
        }
    }
    // Rebuild from regularised parts.
    Ok(match a.as_view() {
        AtomView::Add(add) => add.iter().try_fold(Atom::num(0), |acc, t| {
            Ok::<_, SymbolicError>(acc + regularize(&t.to_owned(), s, fx, order)?)
        })?,
        AtomView::Mul(m) => m.iter().try_fold(Atom::num(1), |acc, t| {
            Ok::<_, SymbolicError>(acc * regularize(&t.to_owned(), s, fx, order)?)
        })?,
        AtomView::Pow(p) => {
            let (b, e) = p.get_base_exp();
            let b2 = regularize(&b.to_owned(), s, fx, order)?;
            if has_vanishing_denominator(b2.as_view(), s)
                || (crate::symbolic::as_f64(e).is_some_and(|n| n < 0.0)
                    && is_zero(&substitute(&b.to_owned(), s, &Atom::num(0))))
            {
                return Err(SymbolicError(format!(
                    "singular at {} = 0 in `{}` and symbolica found no series for it",
                    Atom::var(s),
                    a
                )));
            }
            b2.pow(e.to_owned())
        }
        AtomView::Fun(f) => {
            let mut args = Vec::new();
            for x in f.iter() {
                args.push(regularize(&x.to_owned(), s, fx, order)?);
            }
            let mut fb = symbolica::atom::FunctionBuilder::new(f.get_symbol());
            for x in &args {
                fb = fb.add_arg(x);
            }
            fb.finish()
        }
        _ => a.clone(),
    })
}

/// The series `sum c_k s^k` (k >= 0) in Horner form,
/// `s^k0 (c_k0 + s^(k1-k0) (c_k1 + ...))`: one multiplication and one addition
/// per nonzero term, where the expanded sum costs a power and a product each.
/// The coefficients may hold other symbols (a series of a whole output).
fn horner(series: &Atom, s: Symbol) -> Atom {
    let mut by_power: Vec<(i64, Atom)> = Vec::new();
    let add_term = |by_power: &mut Vec<(i64, Atom)>, t: AtomView| {
        let (k, c) = split_power(t, s);
        match by_power.iter_mut().find(|(kk, _)| *kk == k) {
            Some((_, acc)) => *acc = &*acc + &c,
            None => by_power.push((k, c)),
        }
    };
    match series.as_view() {
        AtomView::Add(terms) => terms.iter().for_each(|t| add_term(&mut by_power, t)),
        t => add_term(&mut by_power, t),
    }
    by_power.sort_by_key(|(k, _)| *k);
    let sv = Atom::var(s);
    let mut acc: Option<Atom> = None;
    for w in (0..by_power.len()).rev() {
        let (k, c) = &by_power[w];
        acc = Some(match acc {
            None => c.clone(),
            Some(inner) => {
                let gap = by_power[w + 1].0 - k;
                c + &sv.pow(Atom::num(gap)) * &inner
            }
        });
    }
    match (acc, by_power.first()) {
        (Some(p), Some((k0, _))) if *k0 > 0 => sv.pow(Atom::num(*k0)) * &p,
        (Some(p), _) => p,
        (None, _) => Atom::num(0),
    }
}

/// A series term `c * s^k` as (k, c); k is 0 when s does not occur as a factor.
fn split_power(t: AtomView, s: Symbol) -> (i64, Atom) {
    let power_of = |f: AtomView| -> Option<i64> {
        match f {
            AtomView::Var(v) if v.get_symbol() == s => Some(1),
            AtomView::Pow(p) => {
                let (b, e) = p.get_base_exp();
                let k = crate::symbolic::as_f64(e)?;
                (matches!(b, AtomView::Var(v) if v.get_symbol() == s) && k.fract() == 0.0)
                    .then_some(k as i64)
            }
            _ => None,
        }
    };
    match t {
        AtomView::Mul(m) => {
            let mut k = 0;
            let mut c = Atom::num(1);
            for f in m.iter() {
                match power_of(f) {
                    Some(kk) => k += kk,
                    None => c *= f.to_owned(),
                }
            }
            (k, c)
        }
        f => match power_of(f) {
            Some(k) => (k, Atom::num(1)),
            None => (0, f.to_owned()),
        },
    }
}

fn has_negative_power(a: AtomView, s: Symbol) -> bool {
    match a {
        AtomView::Pow(p) => {
            let (base, exp) = p.get_base_exp();
            (matches!(base, AtomView::Var(v) if v.get_symbol() == s)
                && crate::symbolic::as_f64(exp).is_some_and(|n| n < 0.0))
                || has_negative_power(base, s)
        }
        AtomView::Mul(m) => m.iter().any(|x| has_negative_power(x, s)),
        AtomView::Add(m) => m.iter().any(|x| has_negative_power(x, s)),
        AtomView::Fun(f) => f.iter().any(|x| has_negative_power(x, s)),
        _ => false,
    }
}

fn finish(spec: Spec, model: &Model, sym: &Sym) -> Result<Function, SymbolicError> {
    let (tape, outputs) = lower(&spec, sym.fx, &sym.options, true)?;
    let ops_tree = kinegen_model::passes::tree_size(&tape, &outputs);
    Ok(Function {
        kernel: spec.kernel,
        name: spec
            .kernel
            .name(|o| model.observations[o as usize].name.clone()),
        doc: spec.doc,
        args: spec.args.into_iter().map(|a| a.spec).collect(),
        rows: spec.rows,
        cols: spec.cols,
        row_names: spec.row_names,
        col_names: spec.col_names,
        tape,
        outputs,
        ops_tree,
    })
}

/// Jacobian of `outs` w.r.t. `vars` (row-major) when the outputs are written in
/// the variables and in let-bound intermediates `lets` (each may use earlier
/// ones): the total derivative by the chain rule. Each intermediate's total
/// derivative is bound once as a further let (returned with the Jacobian), so
/// it is computed once and shared by every output, not expanded into each: the
/// twist's parameter derivatives of a least-squares model are long.
fn jacobian_through(
    outs: &[Atom],
    vars: &[Symbol],
    lets: &[(Symbol, Atom)],
) -> (Vec<Atom>, Vec<(Symbol, Atom)>) {
    let mut dlets: Vec<(Symbol, Atom)> = Vec::new();
    // d_of[l][v]: the symbol bound to D(let l)/D(var v); None when it is zero
    let mut d_of: Vec<Vec<Option<Symbol>>> = Vec::new();
    for (li, (_, e)) in lets.iter().enumerate() {
        // the partial derivative wrt each earlier let, bound once when it is more
        // than a number or a symbol: shared by every variable's chain rule (and,
        // when singular, given one series)
        let partial: Vec<Atom> = lets[..li]
            .iter()
            .enumerate()
            .map(|(mi, (m, _))| {
                let p = e.derivative(*m);
                if matches!(p.as_view(), AtomView::Num(_) | AtomView::Var(_)) {
                    return p;
                }
                let s = symbol!(&format!("kg_p_{li}_{mi}"));
                dlets.push((s, p));
                Atom::var(s)
            })
            .collect();
        let row = vars
            .iter()
            .enumerate()
            .map(|(vi, &v)| {
                let mut d = e.derivative(v);
                for (mi, p) in partial.iter().enumerate() {
                    if let Some(dm) = d_of[mi][vi] {
                        d += p * Atom::var(dm);
                    }
                }
                (!d.is_zero()).then(|| {
                    let s = symbol!(&format!("kg_d_{li}_{vi}"));
                    dlets.push((s, d));
                    s
                })
            })
            .collect();
        d_of.push(row);
    }
    let mut j = Vec::new();
    for o in outs {
        let by_let: Vec<Atom> = lets.iter().map(|(l, _)| o.derivative(*l)).collect();
        for (vi, &v) in vars.iter().enumerate() {
            let mut d = o.derivative(v);
            for (li, dl) in by_let.iter().enumerate() {
                if let Some(s) = d_of[li][vi] {
                    d += dl * Atom::var(s);
                }
            }
            j.push(d);
        }
    }
    (j, dlets)
}

/// Derive every function of a model, its series branches as `options` say.
pub fn derive(model: &Model, options: &GenOptions) -> Result<ModelIr, SourceError> {
    let fx = Funcs::get();
    let sym = symbols(model, fx, *options);
    let se = |e| sym_err(model, e);
    let args = Args::new(model, &sym);
    // Body twist with and without noise.
    let twist_noisy: Vec<Atom> = match &model.kinematics {
        Kinematics::Twist(t) => t
            .iter()
            .map(|e| to_atom(&model.expand(e), &sym.by_name, &fx))
            .collect::<Result<_, _>>()
            .map_err(se)?,
        Kinematics::Constraints(c) => least_squares_twist(model, c, &sym).map_err(se)?,
    };
    let twist: Vec<Atom> = twist_noisy
        .iter()
        .map(|a| {
            args.w_names.iter().fold(a.clone(), |acc, n| {
                substitute(&acc, sym.s(n), &Atom::num(0))
            })
        })
        .collect();
    let mut fns = vec![Spec {
        kernel: Kernel::Twist,
        doc: format!("Body twist [vx, vy, omega] (m/s, m/s, rad/s) from the inputs: the forward kinematics. {}", model.motion_doc),
        args: vec![args.au.clone(), args.ap.clone()],
        lets: vec![],
        rows: 3,
        cols: 1,
        row_names: strings(&["vx", "vy", "omega"]),
        col_names: vec![],
        outputs: twist.clone(),
        singular: vec![],
    }];
    fns.push(gyro_spec(model, &sym, &args, &twist).map_err(se)?);
    fns.extend(step_specs(&sym, &args, &twist_noisy));
    fns.extend(observation_specs(model, &sym, &args, &twist).map_err(se)?);
    // Inverse kinematics.
    let no_inverse = match inverse_kinematics(model, &sym, &twist, &args.ap, &args.adt)? {
        Inverse::Derived(specs) => {
            fns.extend(specs);
            None
        }
        Inverse::Unavailable(reason) => Some(reason),
    };
    let mut functions = Vec::new();
    for s in fns {
        functions.push(finish(s, model, &sym).map_err(se)?);
    }
    ModelIr::try_from(model.ir_file(no_inverse, functions))
        .map_err(|e| se(SymbolicError(e.to_string())))
}

/// A symbol for every name a kernel may read (the state, inputs, noise,
/// runtime parameters, the step, the landmark, the twist and the let-bound
/// quantities), and each const parameter as its exact number.
fn symbols(model: &Model, fx: Funcs, options: GenOptions) -> Sym {
    let mut by_name = HashMap::new();
    let mut names: Vec<String> = STATE.iter().map(|s| s.to_string()).collect();
    names.extend(model.inputs.iter().map(|i| i.name.clone()));
    names.extend(model.noise.iter().map(|n| n.name.clone()));
    names.extend(model.runtime_params().map(|p| p.name.clone()));
    names.extend(strings(&[
        "dt",
        "xl",
        "yl",
        "vx",
        "vy",
        "omega",
        "dx",
        "dy",
        "dtheta",
        "kg_dth",
        "kg_sinc",
        "kg_cosc",
        "kg_inc_vx",
        "kg_inc_vy",
    ]));
    for n in &names {
        by_name.insert(n.clone(), Atom::var(symbol!(&format!("kg_v_{n}"))));
    }
    // const parameters are folded in as exact numbers
    for p in model.params.iter().filter(|p| p.constant) {
        by_name.insert(p.name.clone(), number_f64(p.nominal));
    }
    Sym {
        fx,
        by_name,
        options,
    }
}

/// The kernels' arguments: state, inputs, noise, parameters and time step.
struct Args {
    ax: Arg,
    au: Arg,
    aw: Arg,
    ap: Arg,
    adt: Arg,
    w_names: Vec<String>,
}

impl Args {
    fn new(model: &Model, sym: &Sym) -> Args {
        let u_names: Vec<String> = model.inputs.iter().map(|i| i.name.clone()).collect();
        let w_names: Vec<String> = model.noise.iter().map(|n| n.name.clone()).collect();
        let p_names: Vec<String> = model.runtime_params().map(|p| p.name.clone()).collect();
        Args {
            ax: arg(sym, ArgRole::State, &strings(&STATE)),
            au: arg(sym, ArgRole::Inputs, &u_names),
            aw: arg(sym, ArgRole::Noise, &w_names),
            ap: arg(sym, ArgRole::Params, &p_names),
            adt: arg(sym, ArgRole::Dt, &strings(&["dt"])),
            w_names,
        }
    }

    /// A step's arguments (with the noise when asked and the model has some).
    fn step(&self, with_w: bool) -> Vec<Arg> {
        let mut v = vec![self.ax.clone(), self.au.clone()];
        if with_w && !self.w_names.is_empty() {
            v.push(self.aw.clone());
        }
        v.extend([self.ap.clone(), self.adt.clone()]);
        v
    }
}

/// Gyrodometry (seed 000 eq. 13-18): the translational velocity when the yaw
/// rate is measured by a gyro instead of computed from the inputs.
fn gyro_spec(model: &Model, sym: &Sym, args: &Args, twist: &[Atom]) -> Result<Spec, SymbolicError> {
    let (twist_gyro, gyro_doc) = match &model.kinematics {
        Kinematics::Constraints(c) => {
            // eq. 17: xi' = J_xi^+ (q' - S_theta theta'), a 2-column least squares,
            // solved with the same pseudo-inverse (M embedded as diag(M_xi, 1))
            let rows = constraint_rows(model, c, sym)?;
            let om = sym.a("omega");
            let m2: Vec<Atom> = [(0, 0), (0, 1)]
                .iter()
                .map(|&(a, b)| {
                    rows.iter()
                        .fold(Atom::num(0), |acc, (_, s)| acc + &s[a] * &s[b])
                })
                .chain([
                    Atom::num(0),
                    rows.iter()
                        .fold(Atom::num(0), |acc, (_, s)| acc + &s[1] * &s[1]),
                    Atom::num(0),
                    Atom::num(1),
                ])
                .collect();
            let rhs: Vec<Atom> = (0..2)
                .map(|a| {
                    rows.iter().fold(Atom::num(0), |acc, (r, s)| {
                        acc + &s[a] * (Atom::var(*r) - &s[2] * &om)
                    })
                })
                .collect();
            let xi = (0..2)
                .map(|k| (0..2).fold(Atom::num(0), |acc, j| acc + pinv_entry(k, j, &m2) * &rhs[j]))
                .collect();
            (xi, GYRO_DOC_C)
        }
        Kinematics::Twist(_) => (twist[..2].to_vec(), GYRO_DOC_T),
    };
    Ok(Spec {
        kernel: Kernel::TwistGyro,
        doc: gyro_doc.into(),
        args: vec![
            args.au.clone(),
            arg(sym, ArgRole::YawRate, &strings(&["omega"])),
            args.ap.clone(),
        ],
        lets: vec![],
        rows: 2,
        cols: 1,
        row_names: strings(&["vx", "vy"]),
        col_names: vec![],
        outputs: twist_gyro,
        singular: vec![],
    })
}

/// The Euler and exact steps and their Jacobians, written in the twist
/// (let-bound: computed once, and differentiated once per variable, see
/// `jacobian_through`).
fn step_specs(sym: &Sym, args: &Args, twist_noisy: &[Atom]) -> Vec<Spec> {
    let (x, y, th, dt) = (sym.a("x"), sym.a("y"), sym.a("theta"), sym.a("dt"));
    // A component that is a number or a single symbol stays inline: a let would
    // hide a zero (vy of a differential drive) from simplification.
    let tw_syms = [
        symbol!("kg_tw_vx"),
        symbol!("kg_tw_vy"),
        symbol!("kg_tw_om"),
    ];
    let mut tw_lets: Vec<(Symbol, Atom)> = Vec::new();
    let [vx, vy, om] = [0, 1, 2].map(|k| {
        let e = &twist_noisy[k];
        if matches!(e.as_view(), AtomView::Num(_) | AtomView::Var(_)) {
            e.clone()
        } else {
            tw_lets.push((tw_syms[k], e.clone()));
            Atom::var(tw_syms[k])
        }
    });
    let (vx, vy, om) = (&vx, &vy, &om);
    let euler = vec![
        &x + (th.cos() * vx - th.sin() * vy) * &dt,
        &y + (th.sin() * vx + th.cos() * vy) * &dt,
        &th + om * &dt,
    ];
    let dth_sym = sym.s("kg_dth");
    let dth = sym.a("kg_dth");
    let dth_expr = om * &dt;
    // S = sin(dth)/dth and C = (1 - cos dth)/dth are lets: their series (and
    // those of their derivatives, see `jacobian_through`) are computed once per
    // kernel, so the series branch evaluates four short polynomials instead of
    // a series of every output.
    let (s_sym, c_sym) = (sym.s("kg_sinc"), sym.s("kg_cosc"));
    let arc_lets = [
        (s_sym, dth.sin() / &dth),
        (c_sym, (Atom::num(1) - dth.cos()) / &dth),
    ];
    let (s_fun, c_fun) = (Atom::var(s_sym), Atom::var(c_sym));
    let (a, b) = (vx * &dt, vy * &dt);
    let bx = &s_fun * &a - &c_fun * &b;
    let by = &c_fun * &a + &s_fun * &b;
    let exact = vec![
        &x + th.cos() * &bx - th.sin() * &by,
        &y + th.sin() * &bx + th.cos() * &by,
        &th + &dth_expr,
    ];
    let groups: Vec<(Wrt, &Arg)> = [
        (Wrt::State, &args.ax),
        (Wrt::Inputs, &args.au),
        (Wrt::Noise, &args.aw),
        (Wrt::Params, &args.ap),
    ]
    .into_iter()
    .filter(|(_, a)| !a.syms.is_empty())
    .collect();
    let pose_rows = strings(&["x", "y", "theta"]);
    let mut fns = Vec::new();
    for (form, outs, chain, doc) in [
        (StepForm::Euler, &euler, None, EULER_DOC),
        (
            StepForm::Exact,
            &exact,
            Some((dth_sym, &dth_expr)),
            EXACT_DOC,
        ),
    ] {
        let mut lets = tw_lets.clone();
        if let Some((s, e)) = chain {
            lets.push((s, e.clone()));
            lets.extend(arc_lets.iter().cloned());
        }
        let singular = if chain.is_some() {
            vec![dth_sym]
        } else {
            vec![]
        };
        let step = Kernel::Step(form, None);
        let step_name = step.name(|_| String::new());
        fns.push(Spec {
            kernel: step,
            doc: doc.to_string(),
            args: args.step(true),
            lets: lets.clone(),
            rows: 3,
            cols: 1,
            row_names: pose_rows.clone(),
            col_names: vec![],
            outputs: outs.clone(),
            singular: singular.clone(),
        });
        for (g, garg) in &groups {
            let (j, dlets) = jacobian_through(outs, &garg.syms, &lets);
            let what = match *g {
                Wrt::State => "state (seed 001 eq. 4 for Euler)",
                Wrt::Inputs => "inputs",
                Wrt::Noise => "noise inputs (seed 001 eq. 5 for Euler)",
                Wrt::Params => "parameters",
            };
            fns.push(Spec {
                kernel: step.jacobian(*g),
                doc: format!(
                    "Jacobian of `{step_name}` with respect to the {what}; rows x, y, theta."
                ),
                args: args.step(true),
                lets: lets.iter().cloned().chain(dlets).collect(),
                rows: 3,
                cols: garg.syms.len(),
                row_names: pose_rows.clone(),
                col_names: garg.spec.names.clone(),
                outputs: j,
                singular: singular.clone(),
            });
        }
    }
    fns
}

/// Each observation model and its Jacobians with respect to the state and
/// the parameters.
fn observation_specs(
    model: &Model,
    sym: &Sym,
    args: &Args,
    twist: &[Atom],
) -> Result<Vec<Spec>, SymbolicError> {
    let (ax, au, ap) = (&args.ax, &args.au, &args.ap);
    let mut obs_vars = sym.by_name.clone();
    for (n, t) in ["vx", "vy", "omega"].iter().zip(twist) {
        obs_vars.insert(n.to_string(), t.clone());
    }
    let mut fns = Vec::new();
    for (index, o) in model.observations.iter().enumerate() {
        let obs = Kernel::Observation(index as u16, None);
        let outs: Vec<Atom> = o
            .exprs
            .iter()
            .map(|e| to_atom(&model.expand(e), &obs_vars, &sym.fx))
            .collect::<Result<_, _>>()?;
        let mut args = vec![ax.clone(), au.clone(), ap.clone()];
        if o.landmark {
            args.push(arg(sym, ArgRole::Landmark, &strings(&["xl", "yl"])));
        }
        let doc = if o.doc.is_empty() {
            format!("Observation `{}`", o.name)
        } else {
            o.doc.clone()
        };
        fns.push(Spec {
            kernel: obs,
            doc: format!("{doc} Predicted columns: {}.", o.columns.join(", ")),
            args: args.clone(),
            lets: vec![],
            rows: outs.len(),
            cols: 1,
            row_names: o.columns.clone(),
            col_names: vec![],
            outputs: outs.clone(),
            singular: vec![],
        });
        for (g, garg) in [(Wrt::State, ax), (Wrt::Params, ap)] {
            if garg.syms.is_empty() {
                continue;
            }
            fns.push(Spec {
                kernel: obs.jacobian(g),
                doc: format!("Jacobian of `obs_{}` with respect to the {} (seed 001 eq. 7 for range-bearing).", o.name, if g == Wrt::State { "state" } else { "parameters" }),
                args: args.clone(),
                lets: vec![],
                rows: outs.len(),
                cols: garg.syms.len(),
                row_names: o.columns.clone(),
                col_names: garg.spec.names.clone(),
                outputs: jacobian_through(&outs, &garg.syms, &[]).0,
                singular: vec![],
            });
        }
    }
    Ok(fns)
}

/// The gyrodometry kernel's doc for a constrained model, and for a twist model.
const GYRO_DOC_C: &str = "Gyrodometry, seed 000 eq. 17: body velocity [vx, vy] from the inputs when the yaw rate `omega` is measured (by a gyro, eq. 13): the least-squares solution of the constraints with theta' imposed.";
const GYRO_DOC_T: &str = "Gyrodometry (seed 000 eq. 13-18): body velocity [vx, vy] used with a measured yaw rate `omega`. The twist rows are explicit here, so they do not depend on omega.";
/// The steps' docs.
const EULER_DOC: &str = "Euler step (seed 003; seed 001 eq. 3): pose advanced along the body twist held at the start-of-step heading.";
const EXACT_DOC: &str = "Exact step: the pose after moving with the constant body twist for dt along an arc on SE(2) (seed 003, exact integration). Finite and continuous at omega = 0 (series branch).";

/// The rows of S (seed 000 eq. 7) as atoms, with their rate symbols.
fn constraint_rows(
    model: &Model,
    c: &Constraints,
    sym: &Sym,
) -> Result<Vec<(Symbol, [Atom; 3])>, SymbolicError> {
    c.rows
        .iter()
        .map(|(rate, co)| {
            let [a, b, d] = co
                .clone()
                .map(|e| to_atom(&model.expand(&e), &sym.by_name, &sym.fx));
            Ok((sym.s(rate), [a?, b?, d?]))
        })
        .collect()
}

/// Twist of a constraint model: z = (S^T S)^+ S^T q' (seed 000 eq. 9-10), as
/// `kg_lsq` entries: lowered through the pseudo-inverse (evaluated numerically
/// with a rank check in the emitted code), differentiated by their own rule.
fn least_squares_twist(
    model: &Model,
    c: &Constraints,
    sym: &Sym,
) -> Result<Vec<Atom>, SymbolicError> {
    let rows = constraint_rows(model, c, sym)?;
    let s: Vec<[Atom; 3]> = rows.iter().map(|(_, s)| s.clone()).collect();
    let q: Vec<Atom> = rows.iter().map(|(r, _)| Atom::var(*r)).collect();
    Ok((0..3)
        .map(|k| {
            let solved = lsq_entry(k, &s, &q);
            match &c.noise[k] {
                Some(n) => solved + sym.a(n),
                None => solved,
            }
        })
        .collect())
}

/// Evaluate an atom numerically with symbol values (used for rank and
/// consistency checks at sample points, never for emitted code).
fn eval_at(a: &Atom, values: &[(Symbol, f64)], sym: &Sym) -> Result<f64, SymbolicError> {
    let mut tb = TapeBuilder::new(sym.fx, true, sym.options.series_switch);
    let vals: Vec<f64> = values.iter().map(|v| v.1).collect();
    for (i, (s, _)) in values.iter().enumerate() {
        let slot = tb.push(Op::Arg(0, i as u16));
        tb.bind(*s, slot);
    }
    let out = tb.atom(a.as_view())?;
    let (tape, outputs) = tb.finish(&[out]);
    let f = Function {
        kernel: Kernel::Fused,
        name: String::new(),
        doc: String::new(),
        args: vec![ArgSpec {
            role: ArgRole::Values,
            names: vec![String::new(); vals.len()],
        }],
        rows: 1,
        cols: 1,
        row_names: vec![],
        col_names: vec![],
        tape,
        outputs,
        ops_tree: 0,
    };
    Ok(f.interpret(&[&vals])[0])
}

/// Deterministic pseudo-random sample points (no RNG dependency in the derive stage).
fn sample(k: usize, i: usize) -> f64 {
    let h = ((k as u64 + 1).wrapping_mul(0x9E3779B97F4A7C15)
        ^ (i as u64 + 7).wrapping_mul(0xBF58476D1CE4E5B9))
        >> 11;
    (h as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
}

/// Inverse kinematics: inputs from a body twist, and the integrated form (seed 001
/// eq. 12-18): inputs that produce a given pose increment over dt.
///
/// A derived inverse that does not exist (the twist is not linear in the
/// inputs it would give) is no error: compare, fit, diagnose and localize never
/// need it, so the model gets [`Inverse::Unavailable`] with the reason, which
/// `generate` prints and `inverse` and `navigate` give when they refuse it.
fn inverse_kinematics(
    model: &Model,
    sym: &Sym,
    twist: &[Atom],
    ap: &Arg,
    adt: &Arg,
) -> Result<Inverse, SourceError> {
    let cx = InverseCx::new(model, sym, twist);
    let solved = if let Some((exprs, idoc)) = &model.inverse {
        cx.declared(exprs, idoc)?
    } else if let Kinematics::Constraints(c) = &model.kinematics {
        cx.constrained(c)?
    } else {
        match cx.derived()? {
            Ok(solved) => solved,
            Err(reason) => return Ok(Inverse::Unavailable(reason.to_string())),
        }
    };
    Ok(Inverse::Derived(cx.specs(solved, ap, adt)?))
}

/// Why no inverse kinematics can be derived from a twist (a spec may still
/// declare one).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NoInverse {
    #[error("the twist is not linear in any input (no cumulative input, and no absolute input enters it linearly), so it cannot be inverted symbolically; declare an [inverse] section giving each input from vx, vy and omega (spec/README.md)")]
    NotLinear,
    #[error("cannot derive inverse kinematics: {linear_rows} twist row(s) are linear in the {needed} input(s) it would give ({}), {needed} needed; declare an [inverse] section giving each input from vx, vy and omega (spec/README.md)", inputs.join(", "))]
    TooFewRows {
        linear_rows: usize,
        /// The inputs the inverse would give, and how many rows that needs.
        inputs: Vec<String>,
        needed: usize,
    },
    #[error("cannot derive inverse kinematics: the twist is linearly dependent in the rates of {} (they drive fewer independent rows than there are of them, as two encoders that both measure one speed), and the robot steers by what it reads; declare an [inverse] section giving each input from vx, vy and omega (spec/README.md)", inputs.join(", "))]
    Singular {
        /// The inputs the inverse would give.
        inputs: Vec<String>,
    },
    #[error("cannot derive inverse kinematics: with {} added, the twist rows linear in the input rates are dependent (det = 0); declare an [inverse] section giving each input from vx, vy and omega (spec/README.md)", effects.join(", "))]
    SingularWithEffects {
        /// The spec's effects.
        effects: Vec<String>,
    },
}

/// An inverse found: the inputs it gives (expressions of the twist), their
/// names, its doc, and whether it imposes the lateral speed.
struct Solved {
    outs: Vec<Atom>,
    names: Vec<String>,
    doc: String,
    imposes_vy: bool,
}

/// What the inverse kinematics of a model work with.
struct InverseCx<'a> {
    model: &'a Model,
    sym: &'a Sym,
    twist: &'a [Atom],
    /// What the inverse gives: the rates of the cumulative inputs; a model
    /// without any (a velocity-commanded robot, wheel speeds from tachometers)
    /// gets the absolute inputs that enter the twist linearly. The other
    /// absolute inputs (a steering angle) are configuration it reads.
    rates: Vec<&'a kinegen_model::spec::Input>,
    cfg_names: Vec<String>,
    rate_syms: Vec<Symbol>,
    tw_syms: [Symbol; 3],
    tw_atoms: [Atom; 3],
    /// which twist rows cannot be non-zero at all
    structurally_zero: Vec<bool>,
}

impl<'a> InverseCx<'a> {
    fn new(model: &'a Model, sym: &'a Sym, twist: &'a [Atom]) -> Self {
        let cumulative: Vec<&kinegen_model::spec::Input> = model
            .inputs
            .iter()
            .filter(|i| i.kind == InputKind::Cumulative)
            .collect();
        let rates: Vec<&kinegen_model::spec::Input> = if cumulative.is_empty() {
            model
                .inputs
                .iter()
                .filter(|i| enters_linearly(twist, sym.s(&i.name)))
                .collect()
        } else {
            cumulative
        };
        let cfg_names: Vec<String> = model
            .inputs
            .iter()
            .filter(|i| i.kind == InputKind::Absolute && !rates.iter().any(|r| r.name == i.name))
            .map(|i| i.name.clone())
            .collect();
        InverseCx {
            model,
            sym,
            twist,
            rate_syms: rates.iter().map(|i| sym.s(&i.name)).collect(),
            rates,
            cfg_names,
            tw_syms: [sym.s("vx"), sym.s("vy"), sym.s("omega")],
            tw_atoms: [sym.a("vx"), sym.a("vy"), sym.a("omega")],
            structurally_zero: twist.iter().map(is_zero).collect(),
        }
    }

    fn se(&self, e: SymbolicError) -> SourceError {
        sym_err(self.model, e)
    }

    /// Sample values for parameters (nominal, perturbed) and configuration inputs.
    fn point(&self, k: usize) -> Vec<(Symbol, f64)> {
        let sym = self.sym;
        let mut v: Vec<(Symbol, f64)> = self
            .model
            .runtime_params()
            .enumerate()
            .map(|(i, p)| (sym.s(&p.name), p.nominal * (1.0 + 0.1 * sample(k, i))))
            .collect();
        for (i, c) in self.cfg_names.iter().enumerate() {
            v.push((sym.s(c), 0.7 * sample(k, 100 + i)));
        }
        v
    }

    /// A declared inverse, checked numerically against the forward model.
    fn declared(&self, exprs: &[Expr], idoc: &str) -> Result<Solved, SourceError> {
        let (model, sym, fx) = (self.model, self.sym, self.sym.fx);
        let mut vars = sym.by_name.clone();
        for (n, a) in ["vx", "vy", "omega"].iter().zip(&self.tw_atoms) {
            vars.insert(n.to_string(), a.clone());
        }
        let outs: Vec<Atom> = exprs
            .iter()
            .map(|e| to_atom(e, &vars, &fx))
            .collect::<Result<_, _>>()
            .map_err(|e| self.se(e))?;
        // the rows the declared inverse imposes are the twist components it reads;
        // the others follow from the inputs (like y in seed 001 eq. 12)
        let imposed: Vec<bool> = ["vx", "vy", "omega"]
            .iter()
            .map(|n| {
                exprs
                    .iter()
                    .any(|e| e.variables().iter().any(|(v, _)| v == n))
            })
            .collect();
        for k in 0..8 {
            let mut pt = self.point(k);
            pt.retain(|(s, _)| !model.inputs.iter().any(|i| sym.s(&i.name) == *s));
            let tw: Vec<f64> = (0..3)
                .map(|r| {
                    if self.structurally_zero[r] || !imposed[r] {
                        0.0
                    } else {
                        0.2 + 0.5 * sample(k, 200 + r).abs()
                    }
                })
                .collect();
            let mut at = pt.clone();
            at.extend(self.tw_syms.iter().copied().zip(tw.iter().copied()));
            let mut fwd_at = pt.clone();
            for (i, o) in model.inputs.iter().zip(&outs) {
                fwd_at.push((
                    sym.s(&i.name),
                    eval_at(o, &at, sym).map_err(|e| self.se(e))?,
                ));
            }
            for r in (0..3).filter(|&r| imposed[r]) {
                let back = eval_at(&self.twist[r], &fwd_at, sym).map_err(|e| self.se(e))?;
                if (back - tw[r]).abs() > 1e-9 * (1.0 + tw[r].abs()) {
                    return Err(err_at(
                        model,
                        &exprs[0],
                        format!("declared inverse does not invert the motion model: twist {:?} maps back to {} = {back} instead of {}", tw, ["vx", "vy", "omega"][r], tw[r]),
                    ));
                }
            }
        }
        Ok(Solved {
            outs,
            names: model.inputs.iter().map(|i| i.name.clone()).collect(),
            doc: idoc.to_string(),
            imposes_vy: imposed[1],
        })
    }

    /// The constraints are the inverse kinematics (seed 000 eq. 3): q' = S z'.
    /// Their least-squares inverse exists where S has rank 3; if it never does,
    /// the model cannot be used.
    fn constrained(&self, c: &Constraints) -> Result<Solved, SourceError> {
        let model = self.model;
        let rows = constraint_rows(model, c, self.sym).map_err(|e| self.se(e))?;
        let full_rank_somewhere = (0..8).any(|k| {
            let pt = self.point(k);
            let m: Option<Vec<f64>> = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
                .iter()
                .map(|&(a, b)| {
                    eval_at(
                        &rows
                            .iter()
                            .fold(Atom::num(0), |acc, (_, s)| acc + &s[a] * &s[b]),
                        &pt,
                        self.sym,
                    )
                    .ok()
                })
                .collect();
            m.is_some_and(|m| {
                kinegen_model::linalg::rank_sym3([m[0], m[1], m[2], m[3], m[4], m[5]]) == 3
            })
        });
        if !full_rank_somewhere {
            return Err(err_kin(model, "inverse kinematics is singular everywhere: the constraint rows have rank < 3, so no twist is determined"));
        }
        let by_rate: HashMap<Symbol, &[Atom; 3]> = rows.iter().map(|(r, s)| (*r, s)).collect();
        let outs = self
            .rate_syms
            .iter()
            .map(|r| {
                (0..3).fold(Atom::num(0), |acc, c| {
                    acc + &by_rate[r][c] * &self.tw_atoms[c]
                })
            })
            .collect();
        let names = self.rates.iter().map(|i| i.name.clone()).collect();
        let (outs, names, doc): (Vec<Atom>, Vec<String>, String) = (outs, names, "Input rates from a body twist: the kinematic constraints themselves, q' = S(q, lambda) R(theta) z' (seed 000 eq. 3, 6-7), evaluated in the body frame.".into());
        Ok(Solved {
            outs,
            names,
            doc,
            imposes_vy: true,
        })
    }

    /// Derived inverse: choose twist rows that are linear in the input rates,
    /// M(cfg, p) * rates, as many as there are rates, with M invertible (vx and
    /// omega first, then vy). The other rows follow from the inputs, as y does in
    /// seed 001 eq. 12 (and the lateral slip of an effect-augmented model).
    /// Err(reason) where no inverse can be derived.
    fn derived(&self) -> Result<Result<Solved, NoInverse>, SourceError> {
        let model = self.model;
        let rate_syms = &self.rate_syms;
        let linear = |t: &Atom| {
            let at_zero = rate_syms
                .iter()
                .fold(t.clone(), |acc, s| substitute(&acc, *s, &Atom::num(0)));
            is_zero(&at_zero)
                && rate_syms.iter().all(|a| {
                    rate_syms
                        .iter()
                        .all(|b| is_zero(&t.derivative(*a).derivative(*b)))
                })
        };
        let candidates: Vec<usize> = [0usize, 2, 1]
            .into_iter()
            .filter(|&r| !self.structurally_zero[r] && linear(&self.twist[r]))
            .collect();
        let k = rate_syms.len();
        let (chosen, any_square) = self.invertible_rows(&candidates);
        let Some((rows, inv)) = chosen else {
            if any_square && !self.cfg_names.is_empty() {
                // a robot that steers by a read angle and has more wheel
                // rates than the rows they drive (a car's two rear encoders
                // that both measure its speed): a real robot, whose inverse
                // the derivation cannot choose
                return Ok(Err(NoInverse::Singular {
                    inputs: self.rates.iter().map(|i| i.name.clone()).collect(),
                }));
            }
            if any_square && !model.effects.is_empty() {
                // the effects made it so (a toe angle that turns the speed
                // into vx and vy alike, with a turn rate no longer linear):
                // the spec as written inverted, and diagnosis, fit and
                // localize never use the inverse
                return Ok(Err(NoInverse::SingularWithEffects {
                    effects: model.effects.clone(),
                }));
            }
            if any_square {
                // linear but singular everywhere with nothing else to steer
                // by: almost always a slip in the spec (a sum where a
                // difference was meant), so an error
                return Err(err_kin(model, "inverse kinematics is singular everywhere: the twist rows are linearly dependent in the input rates (det = 0), as with two encoders that both measure one speed; declare an [inverse] section giving each input from vx, vy and omega (spec/README.md)"));
            }
            let rates = &self.rates;
            if rates.is_empty() {
                return Ok(Err(NoInverse::NotLinear));
            }
            return Ok(Err(NoInverse::TooFewRows {
                linear_rows: candidates.len(),
                inputs: rates.iter().map(|i| i.name.clone()).collect(),
                needed: k,
            }));
        };
        let outs: Vec<Atom> = (0..rows.len())
            .map(|i| {
                rows.iter().enumerate().fold(Atom::num(0), |acc, (j, &r)| {
                    acc + &inv[i][j] * &self.tw_atoms[r]
                })
            })
            .collect();
        let names = self.rates.iter().map(|i| i.name.clone()).collect();
        let (outs, names, doc): (Vec<Atom>, Vec<String>, String) = (outs, names, "Input rates from a body twist: the inverse of the (square, invertible) map from input rates to the twist rows that are not identically zero, derived symbolically (seed 003: W = (V_T_W)^-1 V).".into());
        Ok(Ok(Solved {
            outs,
            names,
            doc,
            imposes_vy: rows.contains(&1),
        }))
    }

    /// The first set of `candidates` rows (as many as there are rates) whose
    /// matrix in the rates is not singular everywhere, with its symbolic
    /// inverse; and whether any square set was tried.
    #[allow(clippy::type_complexity)]
    fn invertible_rows(
        &self,
        candidates: &[usize],
    ) -> (Option<(Vec<usize>, Vec<Vec<Atom>>)>, bool) {
        let k = self.rate_syms.len();
        if !((1..=3).contains(&k) && candidates.len() >= k) {
            return (None, false);
        }
        let combos: Vec<Vec<usize>> = match (k, candidates.len()) {
            (1, n) => (0..n).map(|i| vec![candidates[i]]).collect(),
            (2, 2) => vec![vec![candidates[0], candidates[1]]],
            (2, 3) => vec![
                vec![candidates[0], candidates[1]],
                vec![candidates[0], candidates[2]],
                vec![candidates[1], candidates[2]],
            ],
            _ => vec![candidates.to_vec()],
        };
        let mut any_square = false;
        for mut rows in combos {
            rows.sort();
            any_square = true;
            let m: Vec<Vec<Atom>> = rows
                .iter()
                .map(|&r| {
                    self.rate_syms
                        .iter()
                        .map(|s| self.twist[r].derivative(*s))
                        .collect()
                })
                .collect();
            let (inv, det) = symbolic_inverse(&m);
            let singular_everywhere = (0..6).all(|k| self.singular_at(&m, &det, &self.point(k)));
            if !singular_everywhere {
                return (Some((rows, inv)), any_square);
            }
        }
        (None, any_square)
    }

    /// Whether the rows `m` (in the rates) with determinant `det` are
    /// singular at `pt` (or cannot be evaluated there). The test is relative
    /// to Hadamard's bound, the product of the rows' lengths, which |det|
    /// never exceeds: an absolute one took the well-conditioned matrix of
    /// a three-wheel omni base in encoder ticks (entries r 2 pi / 12,288 =
    /// 2.6e-5) for singular, its determinant being 1e-14.
    fn singular_at(&self, m: &[Vec<Atom>], det: &Atom, pt: &[(Symbol, f64)]) -> bool {
        let Ok(d) = eval_at(det, pt, self.sym) else {
            return true;
        };
        let lengths: Option<f64> = m
            .iter()
            .map(|row| {
                row.iter()
                    .map(|e| eval_at(e, pt, self.sym).ok().map(|v| v * v))
                    .sum::<Option<f64>>()
                    .map(f64::sqrt)
            })
            .product();
        match lengths {
            Some(bound) if bound.is_finite() && bound > 0.0 => d.abs() <= 1e-10 * bound,
            _ => true,
        }
    }

    /// The inverse kernels: the rates for a twist, and for a pose increment.
    fn specs(&self, solved: Solved, ap: &Arg, adt: &Arg) -> Result<Vec<Spec>, SourceError> {
        let (model, sym) = (self.model, self.sym);
        let Solved {
            outs: inverse_outs,
            names: out_names,
            doc,
            imposes_vy,
        } = solved;
        let twist_arg = arg(sym, ArgRole::Twist, &strings(&["vx", "vy", "omega"]));
        let cfg_arg = arg(sym, ArgRole::Configuration, &self.cfg_names);
        let mut args = vec![twist_arg];
        if model.inverse.is_none() && !self.cfg_names.is_empty() {
            args.push(cfg_arg.clone());
        }
        args.push(ap.clone());
        let mut specs = vec![Spec {
            kernel: Kernel::InverseTwist,
            doc,
            args,
            lets: vec![],
            rows: inverse_outs.len(),
            cols: 1,
            row_names: out_names.clone(),
            col_names: vec![],
            outputs: inverse_outs.clone(),
            singular: vec![],
        }];
        let (lets, subst) = self.increment_twist(imposes_vy)?;
        let mut args = vec![
            arg(
                sym,
                ArgRole::PoseIncrement,
                &strings(&["dx", "dy", "dtheta"]),
            ),
            adt.clone(),
        ];
        if model.inverse.is_none() && !self.cfg_names.is_empty() {
            args.push(cfg_arg);
        }
        args.push(ap.clone());
        let lateral = imposes_vy;
        specs.push(Spec {
            kernel: Kernel::InverseIncrement,
            doc: format!(
                "Inputs (rates, held for dt) that move the robot by the pose increment (dx, dy, dtheta), given in the start-of-step body frame: seed 001 eq. 12-18 in general form. {} Finite and continuous at dtheta = 0 (eq. 13/16 limit, series branch); valid for |dtheta| < pi.",
                if lateral { "Holonomic: dx, dy and dtheta are all imposed (exact SE(2) logarithm)." } else { "Non-holonomic: dx and dtheta are imposed, dy follows (eq. 12, 15)." }
            ),
            args,
            lets,
            rows: inverse_outs.len(),
            cols: 1,
            row_names: out_names,
            col_names: vec![],
            outputs: inverse_outs.iter().map(subst).collect(),
            singular: vec![sym.s("dtheta")],
        });
        Ok(specs)
    }

    /// Integrated inverse: the constant twist that moves the robot by (dx, dy,
    /// dtheta) (start body frame) in dt, i.e. the SE(2) logarithm, as lets, and
    /// the substitution of it into the inverse. A model whose twist has no
    /// lateral component follows seed 001 eq. 12/15: x and theta are imposed, y
    /// follows; vy is imposed only when the inverse uses the vy row (holonomic
    /// models).
    #[allow(clippy::type_complexity)]
    fn increment_twist(
        &self,
        lateral: bool,
    ) -> Result<(Vec<(Symbol, Atom)>, impl Fn(&Atom) -> Atom + '_), SourceError> {
        let sym = self.sym;
        let (dx, dy, d, dt) = (sym.a("dx"), sym.a("dy"), sym.a("dtheta"), sym.a("dt"));
        let (vx_i, vy_i) = if lateral {
            let half = &d / Atom::num(2);
            let k = &half * d.sin() / (Atom::num(1) - d.cos());
            (
                (&k * &dx + &half * &dy) / &dt,
                (&k * &dy - &half * &dx) / &dt,
            )
        } else {
            (&dx * &d / (d.sin() * &dt), Atom::num(0))
        };
        let om_i = &d / &dt;
        // The removable singularity at dtheta = 0 lives in the twist alone (dtheta /
        // sin dtheta): the twist gets its series branch, and the inverse kinematics
        // is applied to that twist. A series of the whole composed inverse (an
        // atan2 of a curvature, say) would converge slowly or not at all.
        let dtheta = sym.s("dtheta");
        let lets = vec![
            (
                sym.s("kg_inc_vx"),
                regularize(&vx_i, dtheta, sym.fx, sym.options.series_order)
                    .map_err(|e| self.se(e))?,
            ),
            (
                sym.s("kg_inc_vy"),
                regularize(&vy_i, dtheta, sym.fx, sym.options.series_order)
                    .map_err(|e| self.se(e))?,
            ),
        ];
        let tw_syms = self.tw_syms;
        let subst = move |a: &Atom| {
            let a = substitute(a, tw_syms[0], &sym.a("kg_inc_vx"));
            let a = substitute(&a, tw_syms[1], &sym.a("kg_inc_vy"));
            substitute(&a, tw_syms[2], &om_i)
        };
        Ok((lets, subst))
    }
}

/// The inverse kinematics a model gets: its kernels, or why it has none.
enum Inverse {
    Derived(Vec<Spec>),
    Unavailable(String),
}

/// Whether the twist depends on `s` and every row is linear in it (no
/// second derivative): a velocity command scaled by a gain, not a steering
/// angle inside a sine.
fn enters_linearly(twist: &[Atom], s: Symbol) -> bool {
    let first: Vec<Atom> = twist.iter().map(|t| t.derivative(s)).collect();
    first.iter().any(|d| !is_zero(d)) && first.iter().all(|d| is_zero(&d.derivative(s)))
}

/// Inverse of a 1x1, 2x2 or 3x3 symbolic matrix by the adjugate; returns (inverse, det).
fn symbolic_inverse(m: &[Vec<Atom>]) -> (Vec<Vec<Atom>>, Atom) {
    let n = m.len();
    let minor = |r: usize, c: usize| -> Atom {
        let rows: Vec<usize> = (0..n).filter(|&i| i != r).collect();
        let cols: Vec<usize> = (0..n).filter(|&j| j != c).collect();
        match n {
            2 => m[rows[0]][cols[0]].clone(),
            3 => {
                &m[rows[0]][cols[0]] * &m[rows[1]][cols[1]]
                    - &m[rows[0]][cols[1]] * &m[rows[1]][cols[0]]
            }
            _ => Atom::num(1),
        }
    };
    let det = match n {
        1 => m[0][0].clone(),
        _ => (0..n).fold(Atom::num(0), |acc, c| {
            let sign = if c % 2 == 0 {
                Atom::num(1)
            } else {
                Atom::num(-1)
            };
            acc + sign * &m[0][c] * minor(0, c)
        }),
    };
    let det = det.expand();
    let inv = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| {
                    let sign = if (i + j) % 2 == 0 {
                        Atom::num(1)
                    } else {
                        Atom::num(-1)
                    };
                    // adj[i][j] = cofactor[j][i]
                    (sign * minor(j, i) / &det).cancel()
                })
                .collect()
        })
        .collect();
    (inv, det)
}
