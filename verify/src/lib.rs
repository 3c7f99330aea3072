//! kinegen-verify: checks that a model's kernels are right, for any spec.
//!
//! Every check takes a [`ModelIr`] (to know the functions, their arguments and
//! domains) and a [`Kernel`] (what is being verified: the IR evaluator, the
//! generated Rust through `kinegen_generated::call`, or a deliberately corrupted
//! kernel), samples the spec's domain and reports the worst case found: model,
//! function, matrix entry and input. Nothing here is specific to a bundled model,
//! so a new spec is verified with no new test code.
pub mod casadi;
pub mod checks;
pub mod kernel;
#[cfg(feature = "compiled")]
pub mod models;
pub mod sample;

pub use checks::{run_all, Finding, Report};
#[cfg(feature = "compiled")]
pub use kernel::Generated;
pub use kernel::{Corrupted, IrKernel, Kernel};
