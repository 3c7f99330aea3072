//! Calibration methods behind one interface, registered in one place
//! ([`METHODS`]): the CLI's `--method` choices, `--method all` and the dispatch
//! all read the registry, so a new method (issue #15's neural gyrodometry, say)
//! is one `impl` and one line here.
use crate::estimation::fit::{fit, for_use, FitOptions, FitResult, Search};
use crate::estimation::seed_methods::{ekf, gradient_descent, umbmark, yaw_rate_blind_directions};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::decl::ObservationRole::YawRate;

/// What every method may read besides the model and the logs.
pub struct Settings<'a> {
    /// Side of the UMBMark squares, m.
    pub side: f64,
    /// EKF measurement-noise inflation (seed 000 eq. 26), rad/s.
    pub mu: f64,
    /// Options of the Levenberg-Marquardt fit.
    pub fit: &'a FitOptions,
    /// Hidden units of the neural gyrodometry network.
    pub hidden: usize,
}

impl<'a> Settings<'a> {
    /// The side of UMBMark's squares unless told otherwise, m (seed 004: 1 m).
    pub const SIDE: f64 = 1.0;
    /// The EKF's measurement-noise inflation unless told otherwise, rad/s.
    pub const MU: f64 = 0.01;

    /// The defaults, with the fit's options `fit` (one hidden size: none).
    pub fn defaults(fit: &'a FitOptions) -> Settings<'a> {
        Settings {
            side: Self::SIDE,
            mu: Self::MU,
            fit,
            hidden: 0,
        }
    }
}

/// A learned yaw rate (rad/s) from one step's inputs: a virtual gyro.
pub type YawRateModel = crate::model_on_log::track_rows::LearnedYawRate;

/// Why a method does not apply to these logs or this model.
#[derive(Debug, thiserror::Error)]
pub enum MethodError {
    #[error(transparent)]
    Fit(#[from] crate::estimation::fit::FitError),
    #[error(transparent)]
    Seed(#[from] crate::estimation::seed_methods::SeedError),
    #[error(transparent)]
    Neural(#[from] crate::estimation::neural::TrainError),
}

/// One method's outcome.
pub struct Calibration {
    pub p: Vec<f64>,
    /// Standard deviation per free parameter (NaN where the method has none,
    /// infinite where it is unidentified).
    pub std: Vec<f64>,
    /// How it went, in words (iterations, costs, warnings).
    pub note: String,
    /// The full result, for the method that produces one (LM).
    pub fit: Option<FitResult>,
    /// For a method that learns the yaw rate instead of calibrating the model
    /// (neural gyrodometry): its tracks are gyrodometry with this virtual gyro
    /// (and `p` left at the nominal values).
    pub yaw_rate: Option<YawRateModel>,
}

pub trait Method: Sync {
    /// The `--method` value.
    fn name(&self) -> &'static str;
    /// One line for `--help`.
    fn about(&self) -> &'static str;
    /// Calibrate `r`'s free parameters from `r.p`; Err says why the method does
    /// not apply to these logs or this model.
    fn calibrate(&self, r: &Runner, runs: &[Run], s: &Settings)
        -> Result<Calibration, MethodError>;
    /// Run once per `--hidden` size (named `NAME-SIZE`).
    fn per_hidden_size(&self) -> bool {
        false
    }
    /// Whether the method calibrates the model's parameters (rather than
    /// learning a virtual gyro beside them).
    fn calibrates_parameters(&self) -> bool {
        true
    }
    /// Whether the method gives a full fit (covariance, identifiability,
    /// held-out and leave-one-run-out judgement) that `fit` reports and
    /// exports on its own; the others are compared beside each other.
    fn full_fit(&self) -> bool {
        false
    }
}

/// Every calibration method, in the order `--method all` runs and reports them.
pub static METHODS: &[&dyn Method] = &[&Lm, &Gd, &Ekf, &UmbMark, &Neural];

/// The method called `name`.
pub fn by_name(name: &str) -> Option<&'static dyn Method> {
    METHODS.iter().copied().find(|m| m.name() == name)
}

/// The method that gives a full fit (the default calibration).
pub fn full_fit() -> &'static dyn Method {
    METHODS
        .iter()
        .copied()
        .find(|m| m.full_fit())
        .unwrap_or(&Lm)
}

/// What `--method` asks for, parsed once where the user wrote it: one
/// registered method, or every one compared.
#[derive(Clone, Copy)]
pub enum MethodChoice {
    One(&'static dyn Method),
    All,
}

impl MethodChoice {
    /// `all`, or a registered method's name (None: no such method).
    pub fn parse(name: &str) -> Option<MethodChoice> {
        if name == "all" {
            Some(MethodChoice::All)
        } else {
            by_name(name).map(MethodChoice::One)
        }
    }

    /// The methods chosen, in the registry's order.
    pub fn methods(&self) -> Vec<&'static dyn Method> {
        match self {
            MethodChoice::One(m) => vec![*m],
            MethodChoice::All => METHODS.to_vec(),
        }
    }

    /// A method whose full fit `fit` reports and exports on its own.
    pub fn is_full_fit(&self) -> bool {
        matches!(self, MethodChoice::One(m) if m.full_fit())
    }
}

impl std::fmt::Debug for MethodChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MethodChoice::One(m) => write!(f, "{}", m.name()),
            MethodChoice::All => write!(f, "all"),
        }
    }
}

struct Lm;
struct Gd;
struct Ekf;
struct UmbMark;
struct Neural;

impl Method for Lm {
    fn name(&self) -> &'static str {
        "lm"
    }
    fn about(&self) -> &'static str {
        "Levenberg-Marquardt on pose, gyro and landmark residuals"
    }
    fn full_fit(&self) -> bool {
        true
    }
    fn calibrate(
        &self,
        r: &Runner,
        runs: &[Run],
        s: &Settings,
    ) -> Result<Calibration, MethodError> {
        // the user's calibration: the data combined with the nominal values
        // as measurements of their own (what one log cannot tell stays near them)
        let res = for_use(r, runs, s.fit, fit(r, runs, s.fit, Search::Global)?);
        Ok(Calibration {
            p: res.p.clone(),
            std: res.std.clone(),
            note: format!("{} LM iterations", res.iterations),
            fit: Some(res),
            yaw_rate: None,
        })
    }
}

impl Method for Gd {
    fn name(&self) -> &'static str {
        "gd"
    }
    fn about(&self) -> &'static str {
        "gradient descent on the yaw-rate error (gyrodometry calibration)"
    }
    fn calibrate(
        &self,
        r: &Runner,
        runs: &[Run],
        _: &Settings,
    ) -> Result<Calibration, MethodError> {
        let g = gradient_descent(r, runs, 2000)?;
        let note = format!(
            "{} iterations, yaw-rate cost {:.3e} -> {:.3e}{}",
            g.iterations,
            g.cost_before,
            g.cost_after,
            blind_warning(r, &g.p, runs)
        );
        Ok(Calibration {
            p: g.p,
            std: g.std,
            note,
            fit: None,
            yaw_rate: None,
        })
    }
}

impl Method for Ekf {
    fn name(&self) -> &'static str {
        "ekf"
    }
    fn about(&self) -> &'static str {
        "parameter EKF on the yaw rate (gyrodometry calibration)"
    }
    fn calibrate(
        &self,
        r: &Runner,
        runs: &[Run],
        s: &Settings,
    ) -> Result<Calibration, MethodError> {
        let sigma_omega = r
            .obs_sigma(YawRate)
            .and_then(|s| s.first().copied())
            .filter(|s| *s > 0.0)
            .unwrap_or(0.005);
        let e = ekf(r, runs, sigma_omega, s.mu)?;
        let note = format!(
            "{} updates, mu = {}, yaw-rate cost {:.3e} -> {:.3e}{}",
            e.iterations,
            s.mu,
            e.cost_before,
            e.cost_after,
            blind_warning(r, &e.p, runs)
        );
        Ok(Calibration {
            p: e.p,
            std: e.std,
            note,
            fit: None,
            yaw_rate: None,
        })
    }
}

impl Method for UmbMark {
    fn name(&self) -> &'static str {
        "umbmark"
    }
    fn about(&self) -> &'static str {
        "Borenstein & Feng, differential drive, cw and ccw square runs of side --side"
    }
    fn calibrate(
        &self,
        r: &Runner,
        runs: &[Run],
        s: &Settings,
    ) -> Result<Calibration, MethodError> {
        let u = umbmark(r, runs, s.side)?;
        Ok(Calibration {
            p: u.p,
            std: vec![f64::NAN; r.free.len()],
            note: format!(
                "Ed = {:.5}, Eb = {:.5} (alpha {:.3} deg, beta {:.3} deg; {} cw, {} ccw runs)",
                u.ed, u.eb, u.alpha_deg, u.beta_deg, u.cw_runs, u.ccw_runs
            ),
            fit: None,
            yaw_rate: None,
        })
    }
}

impl Method for Neural {
    fn name(&self) -> &'static str {
        "neural"
    }
    fn about(&self) -> &'static str {
        "neural gyrodometry: a tanh MLP (--hidden N units) trained by LM maps the joint rates to the yaw rate and replaces the gyro; the model's parameters stay nominal"
    }
    fn per_hidden_size(&self) -> bool {
        true
    }
    fn calibrates_parameters(&self) -> bool {
        false
    }
    fn calibrate(
        &self,
        r: &Runner,
        runs: &[Run],
        s: &Settings,
    ) -> Result<Calibration, MethodError> {
        let angles: Vec<bool> =
            r.ir.inputs
                .iter()
                .map(|i| i.kind == kinegen_model::decl::InputKind::Absolute && i.unit == "rad")
                .collect();
        let (net, t) = crate::estimation::neural::train(runs, &angles, s.hidden, 0)?;
        let note = format!(
            "{} hidden units, {} LM iterations (weights of iteration {} kept: best on the validation split), yaw-rate RMSE {:.4} rad/s on the training steps, {:.4} on the validation steps ({} training samples)",
            net.hidden(),
            t.iterations,
            t.best_iteration,
            t.train_rmse,
            t.validation_rmse,
            t.samples
        );
        Ok(Calibration {
            p: r.p.clone(),
            std: vec![f64::NAN; r.free.len()],
            note,
            fit: None,
            yaw_rate: Some(std::sync::Arc::new(move |u: &[f64]| net.predict(u))),
        })
    }
}

/// The yaw-rate methods' warning about the directions they cannot see.
fn blind_warning(r: &Runner, p: &[f64], runs: &[Run]) -> String {
    let dirs = yaw_rate_blind_directions(r, p, runs);
    if dirs.is_empty() {
        return String::new();
    }
    format!(
        "\n      WARNING: the yaw rate alone leaves {} parameter direction(s) undetermined (scaled by parameter size), so this method cannot identify them; they stay at their starting values:\n        [{}]",
        dirs.len(),
        dirs.join("]\n        [")
    )
}
