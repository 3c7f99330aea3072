//! kinegen-analysis: confront a model with measurements.
//!
//! Everything here runs on the model IR ([`kinegen_model::ir::ModelIr`]) through
//! its evaluator, so a freshly edited spec can be simulated, compared, calibrated
//! and diagnosed without compiling anything, and nothing here touches symbolica
//! (so it may use threads freely).
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
