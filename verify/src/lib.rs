//! kinegen-verify: checks that a model's kernels are right, for any spec.
//!
//! Every check takes a [`ModelIr`] (to know the functions, their arguments and
//! domains) and a [`Kernel`] (what is being verified: the IR evaluator, the
//! generated Rust through `kinegen_generated::call`, or a deliberately corrupted
//! kernel), samples the spec's domain and reports the worst case found: model,
//! function, matrix entry and input. Nothing here is specific to a bundled model,
//! so a new spec is verified with no new test code.
//!
//! A model's IR checked through its own evaluator, and a kernel with one
//! deliberate mistake caught:
//!
//! ```
//! use kinegen_model::ir::{Kernel, ModelIr, StepForm, Wrt};
//! use kinegen_verify::{run_all, Corrupted, IrKernel};
//!
//! let ir = ModelIr::from_json(include_str!("../../generated/ir/diff_drive.json")).unwrap();
//! // Jacobians against finite differences, the exact step against Euler,
//! // inverse round trips, removable singularities, SE(2) equivariance
//! let report = run_all(&ir, &IrKernel, 8, 1);
//! assert!(report.failures().is_empty());
//!
//! // one term of d(step)/d(parameters) with its sign flipped
//! let jac_p = Kernel::Step(StepForm::Exact, Some(Wrt::Params));
//! let broken = Corrupted::flip_term(&ir, jac_p, 2 * 5 + 2);
//! assert!(!run_all(&ir, &broken, 8, 1).failures().is_empty());
//! ```
pub mod casadi;
pub mod checks;
pub mod crosscheck;
pub mod kernel;
#[cfg(feature = "compiled")]
pub mod models;
pub mod sample;

pub use checks::{run_all, Finding, Report};
#[cfg(feature = "compiled")]
pub use kernel::Generated;
pub use kernel::{Corrupted, IrKernel, Kernel};

/// The guide's firmware page (docs/src/howto/embed.md): its Rust runs as a
/// doctest against the generated crate, as the page shows it.
#[cfg(all(doctest, feature = "compiled"))]
#[doc = include_str!("../../docs/src/howto/embed.md")]
pub struct EmbedHowto;
