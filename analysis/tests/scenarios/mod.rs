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
use kinegen_analysis::applications::simulate::{SimOptions, Trajectory};
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

/// The workspace's root, where the bundled specs are (this module is also
/// the command-line tests' scenarios, compiled in the root package).
pub fn root() -> PathBuf {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut up = here.ancestors().filter(|d| d.join("Cargo.lock").is_file());
    up.next().expect("the workspace's root").to_path_buf()
}

/// A spec by its path from the workspace's root (as the command-line tests
/// name them), or as given when absolute.
pub fn spec(path: &str) -> PathBuf {
    root().join(path)
}

/// Seed 000's truth: the Omni robot's parameters as the paper identified
/// them (eq. 28), against spec/omni_caster.toml's nominal values (eq. 27).
pub const SEED_000_TRUTH: [&str; 12] = [
    "e1=0.042",
    "e2=0.044",
    "e3=0.043",
    "r1=0.101",
    "r2=0.1",
    "r3=0.101",
    "xa1=0.327",
    "xa2=-0.329",
    "xa3=0.002",
    "ya1=0.188",
    "ya2=0.186",
    "ya3=-0.374",
];

/// The real robot logs' folder `name` (`../shared/real/NAME` beside the
/// checkout, or `$KINEGEN_REAL_DATA/NAME`). Where it is absent the test says
/// so on the terminal, with what to do to get it, and passes without
/// asserting (`None`). CI sets `KINEGEN_REQUIRE_REAL_DATA` (`.ci/run`), so
/// there a missing folder fails the test instead of skipping it silently.
pub fn real_data(name: &str) -> Option<PathBuf> {
    let base = match std::env::var_os("KINEGEN_REAL_DATA") {
        Some(dir) => PathBuf::from(dir),
        None => root().join("../shared/real"),
    };
    let dir = base.join(name);
    if dir.is_dir() {
        return Some(dir);
    }
    let test = std::thread::current()
        .name()
        .unwrap_or("a real-data test")
        .to_string();
    assert!(
        std::env::var_os("KINEGEN_REQUIRE_REAL_DATA").is_none(),
        "{test}: the real logs are required here but {} does not exist",
        dir.display()
    );
    // Straight to the terminal: libtest captures `eprintln!` of passing
    // tests, and a skip must be seen.
    use std::io::Write;
    let _ = writeln!(
        std::io::stderr(),
        "SKIPPED {test}: real data `{name}` not found at {} \
         (put shared/real/ beside the checkout or set KINEGEN_REAL_DATA to the folder holding {name}/)",
        dir.display()
    );
    None
}

/// The six real UMBMark squares of `optiodom-diff-square`, or `None` (skip)
/// where the real data is absent (see `real_data`).
pub fn real_runs() -> Option<Vec<PathBuf>> {
    let dir = real_data("optiodom-diff-square")?;
    Some((1..=6).map(|i| dir.join(format!("run-0{i}.csv"))).collect())
}

/// A velocity-commanded robot as its user would write it: commands in,
/// gains to calibrate, a camera that reads landmarks; no `[inverse]`.
/// `noise_unit` empty: seed 001's per-row sigmas.
pub fn commanded_spec(dir: &Path, noise_unit: &str) -> PathBuf {
    let unit = if noise_unit.is_empty() {
        String::new()
    } else {
        format!("unit = \"{noise_unit}\"\n")
    };
    let text = format!(
        r#"name = "my_create"
doc = "A robot driven by forward and turn-rate commands."
state = ["x", "y", "theta"]

[[input]]
name = "v_cmd"
column = "v"
kind = "absolute"
unit = "m/s"

[[input]]
name = "w_cmd"
column = "omega"
kind = "absolute"
unit = "rad/s"

[[parameter]]
name = "k_v"
nominal = 1.0
min = 0.0

[[parameter]]
name = "k_w"
nominal = 1.0
min = 0.0

[[noise]]
name = "dv"
sigma = 0.02
{unit}
[[noise]]
name = "dw"
sigma = 0.02
{unit}
[motion]
vx = "k_v*v_cmd + dv"
vy = "0"
omega = "k_w*w_cmd + dw"

[[observation]]
name = "camera"
landmark = true
columns = ["range", "bearing"]
expr = ["sqrt((xl - x)^2 + (yl - y)^2)", "atan2(yl - y, xl - x) - theta"]
angle = [false, true]
sigma = [0.05, 0.02]
"#
    );
    let path = dir.join(if noise_unit.is_empty() {
        "per_row.toml"
    } else {
        "density.toml"
    });
    std::fs::write(&path, text).unwrap();
    path
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

/// One robot of MRCLAM's dataset 6 (`../shared/real/mrclam-dataset6`): its
/// log (commands and Vicon), its camera's sightings and the landmarks' map.
pub struct MrclamRobot {
    pub log: PathBuf,
    pub observations: PathBuf,
    pub landmarks: PathBuf,
}

/// MRCLAM's robot `n` (1-5), or `None` (skip) where the real data is
/// absent (see [`real_data`]).
pub fn mrclam_robot(n: usize) -> Option<MrclamRobot> {
    let dir = real_data("mrclam-dataset6")?.join(format!("robot{n}"));
    Some(MrclamRobot {
        log: dir.join("log.csv"),
        observations: dir.join("observations.csv"),
        landmarks: dir.join("landmarks.csv"),
    })
}

/// A landmark map `id,x,y` of `points` (ids L0, L1, ...) written to
/// `dir/map.csv`, which is returned.
pub fn landmark_map(dir: &Path, points: &[(f64, f64)]) -> PathBuf {
    let mut map = String::from("id,x,y\n");
    for (i, (x, y)) in points.iter().enumerate() {
        map += &format!("L{i},{x},{y}\n");
    }
    let path = dir.join("map.csv");
    std::fs::write(&path, map).unwrap();
    path
}

/// A log to simulate: the spec, the robot's true values (`NAME=VALUE`) and
/// hidden effects (`NAME=VALUE`), and the drive.
#[derive(Clone)]
pub struct Sim<'a> {
    pub spec: &'a str,
    pub sets: &'a [&'a str],
    pub effects: &'a [&'a str],
    pub trajectory: Trajectory,
    pub seed: u64,
    pub laps: usize,
    /// A landmark map the robot's camera sights (`--landmarks`).
    pub landmarks: Option<&'a Path>,
    /// The camera's sightings per second of each landmark and its reach, m
    /// (`--landmark-hz`, `--landmark-range`; none: simulate's defaults).
    pub camera: Option<(f64, f64)>,
}

impl<'a> Sim<'a> {
    /// `spec` at its nominal values, driving at random (seed 1, one lap).
    pub fn new(spec: &'a str) -> Sim<'a> {
        Sim {
            spec,
            sets: &[],
            effects: &[],
            trajectory: Trajectory::Random,
            seed: 1,
            laps: 1,
            landmarks: None,
            camera: None,
        }
    }

    /// Seed 000's setting: the Omni robot at its identified values (eq. 28)
    /// driving at random with seed `seed`.
    pub fn seed_000(seed: u64) -> Sim<'static> {
        Sim {
            sets: &SEED_000_TRUTH,
            seed,
            ..Sim::new("spec/omni_caster.toml")
        }
    }

    /// The robot's true values.
    pub fn sets(self, sets: &'a [&'a str]) -> Sim<'a> {
        Sim { sets, ..self }
    }

    /// Effects the robot has beyond the spec.
    pub fn effects(self, effects: &'a [&'a str]) -> Sim<'a> {
        Sim { effects, ..self }
    }

    pub fn drive(self, trajectory: &str, seed: u64, laps: usize) -> Sim<'a> {
        let trajectory = trajectory.parse().expect("a known trajectory");
        Sim {
            trajectory,
            seed,
            laps,
            ..self
        }
    }

    /// Sighting the landmarks of `map` with the spec's camera.
    pub fn sighting(self, map: &'a Path) -> Sim<'a> {
        Sim {
            landmarks: Some(map),
            ..self
        }
    }

    /// A camera that sights each landmark `hz` times a second within
    /// `range` m.
    pub fn camera(self, hz: f64, range: f64) -> Sim<'a> {
        Sim {
            camera: Some((hz, range)),
            ..self
        }
    }

    /// The log as `kinegen simulate` writes it, into `dir/name` (with its
    /// sightings at `dir/name.obs.csv` where the robot sights a map).
    pub fn write(&self, dir: &Path, name: &str) -> PathBuf {
        self.write_sighted(dir, name).0
    }

    /// The log and its sightings (`dir/name` and `dir/name.obs.csv`, the
    /// latter empty without a map), as `kinegen simulate --observations`
    /// writes them.
    pub fn write_sighted(&self, dir: &Path, name: &str) -> (PathBuf, PathBuf) {
        let (log, obs) = (dir.join(name), dir.join(format!("{name}.obs.csv")));
        self.write_to(&log, &obs);
        (log, obs)
    }

    /// The log to `log` (returned) and its sightings to `obs`.
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
                trajectory: self.trajectory,
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

/// The mean of `v`.
pub fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// The sample standard deviation of `v`.
pub fn spread_of(v: &[f64]) -> f64 {
    let m = mean(v);
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}
