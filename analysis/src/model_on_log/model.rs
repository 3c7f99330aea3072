//! A model ready to run: its IR, the runtime parameter vector (nominal values with
//! `--set` overrides) and which parameters are free.
use kinegen_jit::{Evaluator, IrCode};
use kinegen_model::decl::ObservationRole;
use kinegen_model::ir::{ArgRole, ArgSpec, Function, ModelIr, StepForm};

#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("unknown parameter `{name}` in --set (the model `{model}` has: {known})")]
    UnknownParam {
        name: String,
        model: String,
        known: String,
    },
    #[error("{0} {1}: expected NAME=VALUE with a finite number")]
    BadSet(&'static str, String),
    #[error("{option} {name}={second}: `{name}` is given twice (first {option} {name}={first}); give it once")]
    Repeated {
        option: &'static str,
        name: String,
        first: f64,
        second: f64,
    },
    #[error("--set {name}={value}: outside the declared bounds of `{name}` ({})", bounds_text(*.min, *.max))]
    OutOfBounds {
        name: String,
        value: f64,
        min: Option<f64>,
        max: Option<f64>,
    },
    #[error("model `{0}` lacks the function `{1}` (regenerate its IR)")]
    Missing(String, String),
}

/// Declared bounds for people: "above 0", "above 0 and at most 1", "at most 2".
fn bounds_text(min: Option<f64>, max: Option<f64>) -> String {
    match (min, max) {
        (Some(a), Some(b)) => format!("above {a} and at most {b}"),
        (Some(a), None) => format!("above {a}"),
        (None, Some(b)) => format!("at most {b}"),
        (None, None) => "none".into(),
    }
}

#[derive(Debug, Clone)]
pub struct Runner {
    pub ir: ModelIr,
    /// Values of the runtime parameters, in the `p` argument order.
    pub p: Vec<f64>,
    pub names: Vec<String>,
    /// Indices (into `p`) of the parameters `fit` calibrates.
    pub free: Vec<usize>,
    /// Index (into `p`) of the spec's measurement delay, if it declares one
    /// (see [`crate::model_on_log::timeline`]).
    pub delay: Option<usize>,
    /// Index (into `p`) of the spec's input delay, if it declares one: the
    /// robot executes its commands that late (see [`crate::model_on_log::timeline::executed`]).
    pub input_delay: Option<usize>,
    /// Index into `p` of the time constant of the robot's response to its
    /// commands (`input_lag = true`), if the spec declares one.
    pub input_lag: Option<usize>,
    /// One step's pose and twist in one tape (dead reckoning).
    pub step_twist: Evaluator,
    /// One step's pose, twist, state and parameter Jacobians in one tape
    /// (dead reckoning with sensitivities): [3 pose, 3 twist, 9 F_x, 3 x P F_p].
    pub step_linearized: Evaluator,
    /// The machine code of the IR's functions, kept beside it (see [`Runner::eval`]).
    pub code: IrCode,
}

/// Parse the `NAME=VALUE` pairs of `--set` (or of `option`, see [`parse_pairs`]).
pub fn parse_sets(sets: &[String]) -> Result<Vec<(String, f64)>, ModelError> {
    parse_pairs("--set", sets)
}

/// Parse `NAME=VALUE` pairs given to `option` (named in the error).
pub fn parse_pairs(
    option: &'static str,
    sets: &[String],
) -> Result<Vec<(String, f64)>, ModelError> {
    let pairs = sets
        .iter()
        .map(|s| {
            let (n, v) = s
                .split_once('=')
                .ok_or_else(|| ModelError::BadSet(option, s.clone()))?;
            let v: f64 = v
                .trim()
                .parse()
                .map_err(|_| ModelError::BadSet(option, s.clone()))?;
            if !v.is_finite() {
                return Err(ModelError::BadSet(option, s.clone()));
            }
            Ok((n.trim().to_string(), v))
        })
        .collect::<Result<Vec<_>, _>>()?;
    // a name given twice is a mistake, not a choice for the last one
    for (k, (name, second)) in pairs.iter().enumerate() {
        if let Some((_, first)) = pairs[..k].iter().find(|(n, _)| n == name) {
            return Err(ModelError::Repeated {
                option,
                name: name.clone(),
                first: *first,
                second: *second,
            });
        }
    }
    Ok(pairs)
}

impl Runner {
    /// Whether parameters `params` change only what the observation of
    /// `role` reads: neither the motion (the twist, the step), nor a timing
    /// (a measurement or input delay, a command lag), nor another
    /// observation. A gyro's bias and scale are such parameters, and so are
    /// a camera's range scale and mounting turn: what the sensor reads, not
    /// where the robot goes.
    pub fn only_observed_by(&self, params: &[usize], role: ObservationRole) -> bool {
        let reads = |f: &Function, i| f.reads(ArgRole::Params, i);
        let motion = [self.ir.twist(), self.ir.step(StepForm::Exact).value];
        let others: Vec<&Function> = (0..self.ir.observations().len())
            .map(|k| self.ir.observation_kernels_at(k))
            .filter(|o| o.decl.role != role)
            .map(|o| o.value)
            .collect();
        let sensor = self.ir.observation_kernels(role).map(|o| o.value);
        let timing = [self.delay, self.input_delay, self.input_lag];
        !params.is_empty()
            && params.iter().all(|&i| {
                !timing.contains(&Some(i))
                    && sensor.is_some_and(|s| reads(s, i))
                    && !motion.iter().chain(&others).any(|f| reads(f, i))
            })
    }

    pub fn new(ir: ModelIr, sets: &[(String, f64)]) -> Result<Runner, ModelError> {
        let rp = ir.runtime_params();
        let names: Vec<String> = rp.iter().map(|p| p.name.clone()).collect();
        let mut p: Vec<f64> = rp.iter().map(|p| p.nominal).collect();
        let free = rp
            .iter()
            .enumerate()
            .filter(|(_, p)| p.free)
            .map(|(i, _)| i)
            .collect();
        for (n, v) in sets {
            let i = names
                .iter()
                .position(|x| x == n)
                .ok_or_else(|| ModelError::UnknownParam {
                    name: n.clone(),
                    model: ir.name.clone(),
                    known: names.join(", "),
                })?;
            let decl = rp[i];
            // strict at min (a radius of 0 divides by zero), inclusive at
            // max; a lag's time constant of 0 is no lag, as its nominal is
            // once add-effect adds it, so the user can fix it there
            let below = |m: f64| *v < m || (*v == m && !decl.input_lag);
            if decl.min.is_some_and(below) || decl.max.is_some_and(|m| *v > m) {
                return Err(ModelError::OutOfBounds {
                    name: n.clone(),
                    value: *v,
                    min: decl.min,
                    max: decl.max,
                });
            }
            p[i] = *v;
        }
        let exact = ir.step(StepForm::Exact);
        // a model without runtime parameters has no jac_p: its sensitivities are empty
        let jac_p = exact.jac_p.into_iter();
        let fused = |name: &str, parts: Vec<&Function>| {
            kinegen_model::fuse::fuse(name, &parts)
                .map_err(|e| ModelError::Missing(ir.name.clone(), format!("{name} ({e})")))
        };
        let step_twist = fused("step_twist", vec![exact.value, ir.twist()])?;
        let step_linearized = fused(
            "step_linearized",
            [exact.value, ir.twist(), exact.jac_x]
                .into_iter()
                .chain(jac_p)
                .collect(),
        )?;
        let delay = rp.iter().position(|q| q.measurement_delay);
        let input_delay = rp.iter().position(|q| q.input_delay);
        let input_lag = rp.iter().position(|q| q.input_lag);
        Ok(Runner {
            code: IrCode::new(&ir),
            ir,
            p,
            names,
            free,
            delay,
            input_delay,
            input_lag,
            step_twist: Evaluator::new(step_twist),
            step_linearized: Evaluator::new(step_linearized),
        })
    }

    /// Evaluate `f`, one of this runner's IR functions (`self.ir`), into a
    /// new vector: as machine code once it is hot (kinegen-jit).
    pub fn eval(&self, f: &Function, args: &[&[f64]]) -> Vec<f64> {
        let mut out = vec![0.0; f.rows * f.cols];
        self.eval_into(f, args, &mut out, &mut Vec::new());
        out
    }

    /// [`Runner::eval`] into `out`, reusing `scratch`.
    #[inline]
    pub fn eval_into(
        &self,
        f: &Function,
        args: &[&[f64]],
        out: &mut [f64],
        scratch: &mut Vec<f64>,
    ) {
        self.code.eval_into(&self.ir, f, args, out, scratch)
    }

    /// The noise standard deviations the spec declares for the observation playing `role`.
    pub fn obs_sigma(&self, role: ObservationRole) -> Option<&[f64]> {
        self.ir.observation(role).map(|o| &o.sigma[..])
    }

    /// The size of a unit change of runtime parameter `i` at `value`, for the
    /// numerics (scaled variables of the fit, probing steps of diagnosis), so
    /// radii (cm), gains (s) and offsets (rad) weigh alike: the value's magnitude,
    /// or 1% of the declared range when the value is smaller (effect parameters
    /// start at zero), or 1e-3 for an unbounded parameter at zero.
    pub fn param_scale(&self, i: usize, value: f64) -> f64 {
        let q = self.ir.runtime_params()[i];
        let range = match (q.min, q.max) {
            (Some(a), Some(b)) => 0.01 * (b - a),
            _ => 1e-3,
        };
        value.abs().max(range).max(1e-9)
    }

    pub fn param_index(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Build the argument list of a step-shaped function (x, u, [w = 0], p, dt).
    pub fn step_args<'a>(
        f: &Function,
        x: &'a [f64],
        u: &'a [f64],
        p: &'a [f64],
        dt: &'a [f64],
        zeros: &'a [f64],
    ) -> Vec<&'a [f64]> {
        f.args
            .iter()
            .map(|a| Runner::step_arg(a, x, u, p, dt, zeros))
            .collect()
    }

    /// The value of one argument of a step-shaped function: x, u, p, dt, or
    /// zeros for the noise (for callers that fill a fixed array in a hot loop).
    pub fn step_arg<'a>(
        a: &ArgSpec,
        x: &'a [f64],
        u: &'a [f64],
        p: &'a [f64],
        dt: &'a [f64],
        zeros: &'a [f64],
    ) -> &'a [f64] {
        match a.role {
            ArgRole::Dt => dt,
            ArgRole::State | ArgRole::Inputs | ArgRole::Params => Runner::obs_arg(a, x, u, p, &[]),
            _ => &zeros[..a.names.len()],
        }
    }

    /// Observation-shaped arguments (x, u, p, [lm]).
    pub fn obs_args<'a>(
        f: &Function,
        x: &'a [f64],
        u: &'a [f64],
        p: &'a [f64],
        lm: &'a [f64],
    ) -> Vec<&'a [f64]> {
        f.args
            .iter()
            .map(|a| Runner::obs_arg(a, x, u, p, lm))
            .collect()
    }

    /// One argument of an observation-shaped function (see [`Runner::obs_args`]).
    #[inline]
    pub fn obs_arg<'a>(
        a: &ArgSpec,
        x: &'a [f64],
        u: &'a [f64],
        p: &'a [f64],
        lm: &'a [f64],
    ) -> &'a [f64] {
        match a.role {
            ArgRole::State => x,
            ArgRole::Inputs => u,
            ArgRole::Params => p,
            _ => lm,
        }
    }

    /// Evaluate the observation-shaped `f` at (x, u, p) into `out`, its
    /// arguments on the stack: the per-row observations of a fit (a
    /// million rows took an allocation per call for the argument list).
    #[inline]
    pub fn eval_obs_into(
        &self,
        f: &Function,
        (x, u, p): (&[f64], &[f64], &[f64]),
        out: &mut [f64],
        scratch: &mut Vec<f64>,
    ) {
        const MAX_ARGS: usize = 8;
        if f.args.len() > MAX_ARGS {
            return self.eval_into(f, &Runner::obs_args(f, x, u, p, &[]), out, scratch);
        }
        let mut args: [&[f64]; MAX_ARGS] = [&[]; MAX_ARGS];
        for (slot, a) in args.iter_mut().zip(&f.args) {
            *slot = Runner::obs_arg(a, x, u, p, &[]);
        }
        self.eval_into(f, &args[..f.args.len()], out, scratch)
    }
}
