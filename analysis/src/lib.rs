//! kinegen-analysis: confront a model with measurements.
//!
//! Everything here runs on the model IR ([`kinegen_model::ir::ModelIr`]) through
//! its evaluator, so a freshly edited spec can be simulated, compared, calibrated
//! and diagnosed without compiling anything, and nothing here touches symbolica
//! (so it may use threads freely).
//!
//! The pipeline in one example: a model's IR (what `kinegen derive` makes
//! from a spec; the bundled specs' IR is committed), a robot whose right
//! wheel is 1% larger than the spec says, its log, and the calibration that
//! finds the difference.
//!
//! ```
//! use kinegen_analysis::fit::{fit, FitOptions};
//! use kinegen_analysis::model::Runner;
//! use kinegen_analysis::simulate::{simulate, SimOptions, Trajectory};
//! use kinegen_model::ir::ModelIr;
//!
//! let ir = ModelIr::from_json(include_str!("../../generated/ir/diff_drive.json")).unwrap();
//! let spec = Runner::new(ir.clone(), &[]).unwrap();
//! let r_r = spec.p[spec.param_index("r_r").unwrap()];
//! let robot = Runner::new(ir, &[("r_r".into(), 1.01 * r_r)]).unwrap();
//!
//! let options = SimOptions { trajectory: Trajectory::Random, ..SimOptions::default() };
//! let log = simulate(&spec, &robot, &options).to_run(&spec, "log").unwrap();
//!
//! let calibrated = fit(&spec, &[log], &FitOptions::default()).unwrap();
//! let found = calibrated.p[spec.param_index("r_r").unwrap()];
//! assert!((found / r_r - 1.01).abs() < 0.001, "{found} against {}", 1.01 * r_r);
//! ```
//!
//! From there: [`localize`] runs the EKF on landmark sightings,
//! [`diagnose_job`] names the physical effects a spec is missing (its
//! candidates derived through a [`derivation::Deriver`]), and
//! [`holdout_bench`] scores calibrations on runs they were not fitted on.
pub mod bag;
pub mod column;
pub mod coverage;
pub mod dataset;
pub mod deadreckon;
pub mod derivation;
pub mod diagnose;
pub mod diagnose_job;
pub mod discretisation;
pub mod fit;
pub mod grid;
pub mod holdout_bench;
pub mod innovations;
pub mod input_range;
pub mod interp;
pub mod inverse;
pub mod lag;
pub mod landmarks;
pub mod localize;
pub mod log;
pub mod methods;
pub mod metrics;
pub mod model;
pub mod navigate;
pub mod neural;
pub mod periodic;
pub mod rosdyn;
pub mod rosmsg;
pub mod rows;
pub mod run;
pub mod seed_methods;
pub mod simulate;
pub mod steering;
pub mod sweep;
pub mod timeline;
pub mod track_rows;

pub use kinegen_model::effects;
pub use kinegen_model::ir::ModelIr;
