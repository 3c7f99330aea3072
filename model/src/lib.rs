//! kinegen-model: everything about a kinematic model that does not need symbolic algebra.
//!
//! * [`spec`]: the TOML spec language (`spec/*.toml`), parsed and validated with
//!   errors that point at file, line and column.
//! * [`decl`]: inputs, parameters, noise and observations as plain data, shared
//!   by the spec (which parses them) and the IR (which carries them).
//! * [`expr`]: the math-expression language used inside specs (parser with spans).
//! * [`ir`]: the serialisable model IR that the derivation stage (kinegen-codegen,
//!   which owns symbolica) produces, and a fast evaluator for it. The Rust emitter,
//!   the verification suite and the analysis commands all consume this IR, so none of
//!   them ever touches symbolica.
//! * [`linalg`]: the pseudo-inverse with a rank check used by least-squares
//!   (constraint) kinematics, shared verbatim with the generated crate.
pub mod decl;
pub mod effects;
pub mod error;
pub mod expr;
pub mod files;
pub mod fuse;
pub mod ir;
pub mod jit;
pub mod kernel;
pub mod linalg;
pub mod options;
pub mod schedule;
pub mod spec;

pub use error::{SourceError, SourcePos};
