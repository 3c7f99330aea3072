//! The analysis IR without a symbolic engine: every kernel the analysis uses,
//! lowered from the spec's expression trees onto tapes and differentiated by
//! forward-mode automatic differentiation over the tape.
//!
//! This is what every analysis command runs on (simulate, compare, fit,
//! diagnose, localize, their batches and benchmarks): it needs no symbolica,
//! so it builds in seconds, runs on any number of threads, and takes any
//! spec, edited or new, with any function of the spec language (`atan2`,
//! `abs`, a deadband's `sign`). The symbolic stage (kinegen-codegen) stays
//! where its output is the product: the simplified kernels users embed,
//! closed-form inverse kinematics. `kinegen verify` holds the two IRs to each
//! other, value and every Jacobian, at random points and at the singular
//! limits.
//!
//! ```
//! use kinegen_model::autodiff;
//! use kinegen_model::ir::{ArgRole, StepForm};
//! use kinegen_model::spec::Model;
//!
//! let spec = Model::parse(
//!     "cart.toml".as_ref(),
//!     r#"
//! name = "cart"
//! state = ["x", "y", "theta"]
//! [[input]]
//! name = "v"
//! column = "v_cmd"
//! kind = "absolute"
//! [[input]]
//! name = "w"
//! column = "w_cmd"
//! kind = "absolute"
//! [[parameter]]
//! name = "k"
//! nominal = 1.0
//! [motion]
//! vx = "k*v"
//! vy = "0"
//! omega = "atan2(w, 1)"
//! "#,
//! )
//! .unwrap();
//! let ir = autodiff::derive(&spec, &Default::default()).unwrap();
//! let jac_p = ir.step(StepForm::Exact).jac_p.unwrap();
//! // d x / d k after 1 s at 2 m/s, straight ahead: 2 m per unit of k
//! let args: Vec<&[f64]> = jac_p
//!     .args
//!     .iter()
//!     .map(|a| match a.role {
//!         ArgRole::State => &[0.0, 0.0, 0.0][..],
//!         ArgRole::Inputs => &[2.0, 0.0][..],
//!         ArgRole::Params => &[1.0][..],
//!         _ => &[1.0][..],
//!     })
//!     .collect();
//! assert!((jac_p.interpret(&args)[0] - 2.0).abs() < 1e-12);
//! ```
mod builder;
mod forward;
mod kernels;
mod lower;

use crate::ir::ModelIr;
use crate::options::GenOptions;
use crate::spec::Model;
use crate::SourceError;

/// Why an automatically differentiated IR has no inverse kinematics: they
/// are closed forms only the symbolic stage finds.
pub const NO_INVERSE: &str = "its closed-form inverse kinematics come from kinegen's symbolic stage (`kinegen generate`, or a kinegen built with the `symbolic` feature); the analysis solves for inputs numerically instead";

/// Every analysis kernel of `model`: the twist, gyrodometry, both steps and
/// their Jacobians, each observation and its Jacobians; series branches
/// near omega*dt = 0 as `options` say.
pub fn derive(model: &Model, options: &GenOptions) -> Result<ModelIr, SourceError> {
    let functions = kernels::all(model, options)?;
    ModelIr::try_from(model.ir_file(Some(NO_INVERSE.into()), functions))
        .map_err(|e| SourceError::new(&model.path, None, e.to_string()))
}
