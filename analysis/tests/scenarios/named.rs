//! The named scenarios themselves, with no dependency beyond std: the
//! robots (seed 000's truth, a velocity-commanded robot, MRCLAM's robots),
//! the real logs, a landmark map and a simulated log's description
//! ([`Sim`]). Both the library's tests (`scenarios/mod.rs`: the log made
//! in-process, the commands' library calls) and the command line's
//! (`tests/common.rs`: the log made by `kinegen simulate`) use them, each
//! test binary linking only what it runs.
#![allow(dead_code)] // each test file uses its own few scenarios

use std::path::{Path, PathBuf};

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

/// A map around the `beacons` trajectory's tour, for the sighting-error tests.
pub const SIX_LANDMARKS: [(f64, f64); 6] = [
    (-4.0, -3.0),
    (5.0, -4.0),
    (4.0, 5.0),
    (-5.0, 4.0),
    (0.0, 6.0),
    (0.0, -6.0),
];

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
    /// A trajectory of `kinegen simulate --trajectory`.
    pub trajectory: &'a str,
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
            trajectory: "random",
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

    pub fn drive(self, trajectory: &'a str, seed: u64, laps: usize) -> Sim<'a> {
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

    /// The options `kinegen simulate` takes for this log (with
    /// `--observations` and `--out` to add).
    pub fn options(&self) -> Vec<String> {
        let mut a = vec!["--spec".to_string(), self.spec.to_string()];
        for (flag, values) in [("--set", self.sets), ("--effect", self.effects)] {
            for v in values {
                a.extend([flag.to_string(), v.to_string()]);
            }
        }
        a.extend(["--trajectory".into(), self.trajectory.to_string()]);
        a.extend(["--seed".into(), self.seed.to_string()]);
        a.extend(["--laps".into(), self.laps.to_string()]);
        if let Some(map) = self.landmarks {
            a.extend(["--landmarks".into(), map.display().to_string()]);
        }
        if let Some((hz, range)) = self.camera {
            a.extend(["--landmark-hz".into(), hz.to_string()]);
            a.extend(["--landmark-range".into(), range.to_string()]);
        }
        a
    }

    /// The log into `dir/name` (with its sightings at `dir/name.obs.csv`
    /// where the robot sights a map), by the including side's `write_to`:
    /// in-process for the library's tests, `kinegen simulate` for the
    /// command line's.
    pub fn write(&self, dir: &Path, name: &str) -> PathBuf {
        self.write_sighted(dir, name).0
    }

    /// The log and its sightings (`dir/name` and `dir/name.obs.csv`, the
    /// latter only where the robot sights a map).
    pub fn write_sighted(&self, dir: &Path, name: &str) -> (PathBuf, PathBuf) {
        let (log, obs) = (dir.join(name), dir.join(format!("{name}.obs.csv")));
        self.write_to(&log, &obs);
        (log, obs)
    }

    /// A camera that sights each landmark `hz` times a second within
    /// `range` m.
    pub fn camera(self, hz: f64, range: f64) -> Sim<'a> {
        Sim {
            camera: Some((hz, range)),
            ..self
        }
    }
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
