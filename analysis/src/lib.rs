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
//! use kinegen_analysis::estimation::fit::{fit, FitOptions, Search};
//! use kinegen_analysis::model_on_log::model::Runner;
//! use kinegen_analysis::applications::simulate::{simulate, SimOptions, Trajectory};
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
//! let calibrated = fit(&spec, &[log], &FitOptions::default(), Search::Global).unwrap();
//! let found = calibrated.p[spec.param_index("r_r").unwrap()];
//! assert!((found / r_r - 1.01).abs() < 0.001, "{found} against {}", 1.01 * r_r);
//! ```
//!
//! From there, each command of the CLI is one call that reads its files
//! ([`model_on_log::files::read_files`]: the effect catalogue, the spec derived through a
//! [`model_on_log::derivation::Deriver`], the logs) and runs the job:
//! [`model_on_log::comparison::compare_files`] compares the model with the logs,
//! [`estimation::fit_request::fit_files`] calibrates and judges the result (held-out
//! runs, leave-one-run-out), [`applications::localize_request::localize_files`] runs the
//! EKF on landmark sightings, [`diagnosis::request::diagnose_files`] names the physical
//! effects a spec is missing. Each job also runs on logs already loaded
//! ([`model_on_log::load`], then [`model_on_log::comparison::compare`],
//! [`estimation::fit_job::calibrate`],
//! [`applications::localize::localize_runs`], [`diagnosis::diagnose_job`]),
//! and [`applications::holdout_bench`]
//! scores calibrations on runs they were not fitted on.
// The folders follow the pipeline, each using only the ones before it
// (tests/module_cycles.rs holds them to it): reading logs, the model on a log,
// estimation, diagnosis, and the seed papers' applications. Every module is
// also reachable at the crate's top level (`kinegen_analysis::estimation::fit`).

/// Reading logs: CSV columns and rows, ROS 2 bags (MCAP, CDR, dynamic
/// message definitions).
pub mod logs {
    pub mod bag;
    pub mod column;
    pub mod contained;
    pub mod log;
    pub mod mcap_messages;
    pub mod merged;
    pub mod rosdyn;
    pub mod rosmsg;
    pub mod rows;
}

/// The model on a log: a runnable model, a log as steps, the commands as
/// executed, dead reckoning, innovations and error metrics.
pub mod model_on_log {
    pub mod comparison;
    pub mod coverage;
    pub mod dataset;
    pub mod deadreckon;
    pub mod derivation;
    pub mod evaluation;
    pub mod files;
    pub mod innovations;
    pub mod input_range;
    pub mod interp;
    pub mod landmarks;
    pub mod linalg;
    pub mod load;
    pub mod metrics;
    pub mod model;
    pub mod robust;
    pub mod run;
    pub mod sighting_units;
    pub mod steering;
    pub mod timeline;
    pub mod track_rows;
}

/// Estimation: calibration (the fit and its methods), delays, periodic
/// errors, the model's own discretisation error.
pub mod estimation {
    pub mod discretisation;
    pub mod fit;
    pub mod fit_document;
    pub mod fit_job;
    pub mod fit_request;
    pub mod lag;
    pub mod methods;
    pub mod neural;
    pub mod periodic;
    pub mod seed_methods;
}

/// Diagnosis: which physical effects the model is missing.
pub mod diagnosis {
    pub mod clock;
    pub mod diagnose;
    pub mod diagnose_job;
    pub mod document;
    pub mod estimate;
    pub mod folds;
    pub mod next_steps;
    /// Corrections beyond the catalogue, of the twist and of the sensor.
    pub mod propose {
        pub mod proposal;
        pub mod sightings;
        pub mod twist;
    }
    pub mod ranking;
    pub mod request;
    pub mod sensor;
    pub mod stage;
    pub mod structure;
    pub mod trial;
}

/// The seed papers' applications and the benchmarks: localisation,
/// navigation, inverse kinematics on a path, simulation, calibration on
/// held-out sessions.
pub mod applications {
    pub mod diagnose_bench;
    pub mod grid;
    pub mod hidden;
    pub mod holdout_bench;
    pub mod inverse;
    pub mod localize;
    pub mod localize_document;
    pub mod localize_request;
    pub mod mission;
    pub mod navigate;
    pub mod simulate;
    pub mod simulate_request;
    pub mod sweep;
}

pub use kinegen_model::effects;
pub use kinegen_model::ir::ModelIr;
