//! kinegen-model: everything about a kinematic model that does not need symbolic algebra.
//!
//! * [`spec`]: the TOML spec language (`spec/*.toml`), parsed and validated with
//!   errors that point at file, line and column.
//! * [`decl`]: inputs, parameters, noise and observations as plain data, shared
//!   by the spec (which parses them) and the IR (which carries them).
//! * [`expr`]: the math-expression language used inside specs (parser with spans).
//! * [`ir`]: the serialisable model IR that the derivation stage (kinegen-codegen,
//!   which owns symbolica) produces, with an interpreter of its tapes (the
//!   analysis evaluates it through kinegen-jit, which compiles hot tapes). The Rust emitter,
//!   the verification suite and the analysis commands all consume this IR, so none of
//!   them ever touches symbolica.
//! * [`linalg`]: the pseudo-inverse with a rank check used by least-squares
//!   (constraint) kinematics, shared verbatim with the generated crate.
//!
//! A spec parsed, and a derived IR's exact step evaluated (the IR of the
//! bundled `unicycle_ekf` spec, committed; `kinegen derive` makes one for any
//! spec):
//!
//! ```
//! use kinegen_model::ir::{ArgRole, ModelIr, StepForm};
//! use kinegen_model::spec::Model;
//!
//! let spec = Model::parse(
//!     "my_robot.toml".as_ref(),
//!     r#"
//! name = "my_robot"
//! state = ["x", "y", "theta"]
//! [[input]]
//! name = "v"
//! column = "v_cmd"
//! kind = "absolute"
//! [[input]]
//! name = "w"
//! column = "w_cmd"
//! kind = "absolute"
//! [motion]
//! vx = "v"
//! vy = "0"
//! omega = "w"
//! "#,
//! )
//! .unwrap();
//! assert_eq!(spec.inputs.len(), 2);
//!
//! let ir = ModelIr::from_json(include_str!("../../generated/ir/unicycle_ekf.json")).unwrap();
//! let step = ir.step(StepForm::Exact).value;
//! let p: Vec<f64> = ir.runtime_params().iter().map(|q| q.nominal).collect();
//! // a quarter turn at 1 m/s over pi/2 s from the origin: to (1, 1), heading pi/2
//! let (x, u, dt) = ([0.0; 3], [1.0, 1.0], [std::f64::consts::FRAC_PI_2]);
//! let args: Vec<&[f64]> = step
//!     .args
//!     .iter()
//!     .map(|a| match a.role {
//!         ArgRole::State => &x[..],
//!         ArgRole::Inputs => &u[..],
//!         ArgRole::Params => &p[..],
//!         ArgRole::Dt => &dt[..],
//!         _ => &[0.0, 0.0][..a.names.len()],
//!     })
//!     .collect();
//! let pose = step.interpret(&args);
//! assert!((pose[0] - 1.0).abs() < 1e-12 && (pose[1] - 1.0).abs() < 1e-12);
//! ```
pub mod autodiff;
pub mod decl;
pub mod effects;
pub mod error;
pub mod expr;
pub mod files;
pub mod fuse;
pub mod ir;
pub mod kernel;
pub mod linalg;
pub mod options;
pub mod passes;
pub mod schedule;
pub mod spec;

pub use error::{SourceError, SourcePos};
