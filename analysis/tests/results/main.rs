//! What the analysis finds, asserted on the library's values, in one test
//! binary (one link of the analysis, not eleven, and the runner's threads
//! balanced over all their tests): calibration, diagnosis, the
//! velocity-commanded robot, landmarks (each case made from the named
//! scenarios, `../scenarios`), proposals beyond the catalogue, refinement,
//! delays, sub-steps, the nominal prior, bag lengths and the log reader's
//! fuzzing.
#[path = "../scenarios/mod.rs"]
mod scenarios;

mod bag_lengths;
mod calibration;
mod commanded;
mod delay;
mod diagnosis;
mod fuzz_log;
mod landmarks;
mod nominal_prior;
mod proposals;
mod refine;
mod substeps;
