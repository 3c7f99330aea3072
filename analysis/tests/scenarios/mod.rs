//! Named scenarios the library's tests share, each as the commands see it:
//! a log simulated as `kinegen simulate` writes it ([`Sim`]), the logs read
//! as `--data` and `--holdout` are read ([`load`]), and calibrated as `kinegen
//! fit` calibrates ([`calibrated`]), one library call each and no process.
//! The command-line tests keep what only the command has: options, exit
//! codes, the JSON's shape.
#![allow(dead_code)] // each test file uses its own few scenarios

use kinegen_analysis::applications::localize::{EkfOptions, NoiseSource};
use kinegen_analysis::applications::localize_request::{
    localize_files, LocalizeRequest, LocalizedFiles,
};
use kinegen_analysis::applications::simulate::SimOptions;
use kinegen_analysis::applications::simulate_request::{simulate_files, SimulateRequest};
use kinegen_analysis::diagnosis::diagnose::Diagnosis;
use kinegen_analysis::diagnosis::diagnose_job::Hooks;
use kinegen_analysis::diagnosis::request::{diagnose_files, Diagnosed, Request};
use kinegen_analysis::estimation::fit::FitOptions;
use kinegen_analysis::estimation::fit_job::{calibrate, Calibrated};
use kinegen_analysis::model_on_log::derivation::AutodiffDeriver;
use kinegen_analysis::model_on_log::files::{read_files, Files};
use kinegen_analysis::model_on_log::load::{Loaded, Sources};
use kinegen_analysis::model_on_log::run::DEFAULT_MAX_GAP_S;
use std::path::{Path, PathBuf};

pub mod elsewhere;
mod named;
pub use named::*;

impl Sim<'_> {
    /// The log to `log` (returned) and its sightings to `obs`, as `kinegen
    /// simulate` writes them, in-process.
    pub fn write_to(&self, log: &Path, obs: &Path) -> PathBuf {
        let owned = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let (effects, sets) = (owned(self.effects), owned(self.sets));
        let defaults = SimOptions::default();
        let request = SimulateRequest {
            spec: &spec(self.spec),
            effects: &effects,
            sets: &sets,
            effect_dirs: &[],
            landmarks: self.landmarks,
            options: SimOptions {
                trajectory: self.trajectory.parse().expect("a known trajectory"),
                seed: self.seed,
                laps: self.laps,
                landmark_hz: self.camera.map_or(defaults.landmark_hz, |c| c.0),
                landmark_range: self.camera.map_or(defaults.landmark_range, |c| c.1),
                ..defaults
            },
        };
        let sim = simulate_files(&request, &AutodiffDeriver)
            .unwrap_or_else(|e| panic!("simulating {}: {e}", self.spec));
        std::fs::write(log, sim.csv()).unwrap();
        if self.landmarks.is_some() {
            std::fs::write(obs, sim.observations_csv()).unwrap();
        }
        log.to_path_buf()
    }
}

/// `spec` with the catalogue's `effect` added at `values` (`NAME=VALUE`;
/// the effect's nominal values otherwise), written to `out`, as `kinegen
/// add-effect` writes it.
pub fn with_effect(spec: &Path, effect: &str, values: &[(&str, f64)], out: &Path) -> PathBuf {
    let values: Vec<(String, f64)> = values.iter().map(|(n, v)| (n.to_string(), *v)).collect();
    let request = kinegen_analysis::effects::AddEffect {
        spec,
        effect,
        values: &values,
        effect_dirs: &[],
    };
    let added = kinegen_analysis::effects::add_effect(&request)
        .unwrap_or_else(|e| panic!("{effect} added to {}: {e}", spec.display()));
    std::fs::write(out, &added.source).unwrap();
    out.to_path_buf()
}

/// The logs of a job, as its options name them.
#[derive(Default)]
pub struct Logs<'a> {
    /// `--set NAME=VALUE`.
    pub sets: &'a [&'a str],
    pub data: &'a [&'a Path],
    pub holdout: &'a [&'a Path],
    /// `--observations`, the k-th for the k-th `data` log.
    pub observations: &'a [&'a Path],
    pub landmarks: Option<&'a Path>,
}

impl Logs<'_> {
    fn sources(&self, spec_path: &str) -> Sources {
        let paths = |v: &[&Path]| v.iter().map(|p| p.to_path_buf()).collect();
        Sources {
            spec: spec(spec_path),
            data: paths(self.data),
            holdout: paths(self.holdout),
            sets: self.sets.iter().map(|s| s.to_string()).collect(),
            topics: None,
            observations: paths(self.observations),
            landmarks: self.landmarks.map(Path::to_path_buf),
            max_gap: DEFAULT_MAX_GAP_S,
            truth_scores_only: false,
        }
    }
}

/// `data` and `holdout` read for `spec_path` (with `--set` values `sets`) as
/// every command reads its `--data` and `--holdout`.
pub fn load(spec_path: &str, sets: &[&str], data: &[&Path], holdout: &[&Path]) -> Loaded {
    let logs = Logs {
        sets,
        data,
        holdout,
        ..Logs::default()
    };
    load_logs(spec_path, &logs)
}

/// `logs` read for `spec_path` as every command reads them.
pub fn load_logs(spec_path: &str, logs: &Logs) -> Loaded {
    let sources = logs.sources(spec_path);
    let files = Files {
        sources: &sources,
        effect_dirs: &[],
    };
    match read_files(&files, &AutodiffDeriver, &|_| Box::new(|_, _| {})) {
        Ok(read) => read.loaded,
        Err(e) => panic!("{spec_path} on {:?}: {e}", logs.data),
    }
}

/// `kinegen diagnose`'s diagnosis of `logs` against `spec_path` (with the
/// user's effect folders `effect_dirs`).
pub fn diagnosed(spec_path: &str, logs: &Logs, effect_dirs: &[PathBuf]) -> Diagnosed {
    let sources = logs.sources(spec_path);
    let files = Files {
        sources: &sources,
        effect_dirs,
    };
    let request = Request {
        files,
        for_report: false,
    };
    let progress = &|_: &Path| -> Box<dyn Fn(usize, usize)> { Box::new(|_, _| {}) };
    diagnose_files(&request, &AutodiffDeriver, progress, &Hooks::none())
        .unwrap_or_else(|e| panic!("{spec_path} on {:?}: {e}", logs.data))
}

/// The diagnosis of `data` against `spec_path`, as `kinegen diagnose --spec
/// SPEC --data ...` makes it.
pub fn diagnosis(spec_path: &str, data: &[&Path]) -> Diagnosis {
    let logs = Logs {
        data,
        ..Logs::default()
    };
    diagnosed(spec_path, &logs, &[]).outcome.diagnosis
}

/// `kinegen fit`'s calibration of `l` with its default options.
pub fn calibrated(l: &Loaded) -> Calibrated<'_> {
    calibrated_with(l, &FitOptions::command_default())
}

/// `kinegen fit`'s calibration of `l` with options `fo`.
pub fn calibrated_with<'r>(l: &'r Loaded, fo: &FitOptions) -> Calibrated<'r> {
    calibrate(l, fo).unwrap_or_else(|e| panic!("{e}"))
}

/// A calibrated parameter's estimate and standard deviation (NaN where the
/// logs do not determine it: the JSON's null).
pub fn estimate(c: &Calibrated, l: &Loaded, name: &str) -> (f64, f64) {
    let i = l.runner.param_index(name).expect("a parameter of the spec");
    let k = c
        .fit
        .free
        .iter()
        .position(|&f| f == i)
        .expect("a free parameter");
    (c.fit.p[i], c.fit.std[k])
}

/// `kinegen localize`'s filter options (the noise estimated from the
/// sightings), with `--spec-noise` where `spec_noise`.
pub fn filter_options(spec_noise: bool) -> EkfOptions {
    EkfOptions {
        noise: if spec_noise {
            NoiseSource::Spec
        } else {
            NoiseSource::Estimate
        },
        ..EkfOptions::default()
    }
}

/// `kinegen localize`'s localisation of `logs` against `spec_path` with the
/// filter's options `options`.
pub fn localized(spec_path: &str, logs: &Logs, options: EkfOptions) -> LocalizedFiles {
    let sources = logs.sources(spec_path);
    let request = LocalizeRequest {
        files: Files {
            sources: &sources,
            effect_dirs: &[],
        },
        options,
        sweep: false,
        for_report: false,
    };
    let progress = &|_: &Path| -> Box<dyn Fn(usize, usize)> { Box::new(|_, _| {}) };
    localize_files(&request, &AutodiffDeriver, progress, &|_| {})
        .unwrap_or_else(|e| panic!("{spec_path} on {:?}: {e}", logs.data))
}
