//! Helpers shared by the end-to-end tests: run the kinegen binary.
#![allow(dead_code)]
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

// The scenarios the library's tests name (seed 000's truth, the real logs,
// a simulated log's description), shared with these tests rather than
// copied; the library's calls stay on its side, so that these test
// binaries do not link the analysis (29 links of it took minutes in CI).
#[path = "../analysis/tests/scenarios/named.rs"]
pub mod scenarios;
#[allow(unused_imports)] // each test file uses its own few
pub use scenarios::{
    commanded_spec, landmark_map, mrclam_robot, real_data, real_runs, Sim, SEED_000_TRUTH,
    SIX_LANDMARKS,
};

pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn kinegen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_kinegen"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("run kinegen")
}

pub fn kinegen_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_kinegen"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run kinegen")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).to_string()
}

/// Copy a directory's files (not recursive).
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        if e.path().is_file() {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

/// Run kinegen where it must refuse (exit 2, bad input); its stderr, the
/// message the assertions read.
pub fn refused(args: &[&str]) -> String {
    let o = kinegen(args);
    assert_eq!(o.status.code(), Some(2), "kinegen {args:?}: {}", stderr(&o));
    stderr(&o)
}

/// Run kinegen with `--json -` appended and parse stdout.
pub fn kinegen_json(args: &[&str]) -> serde_json::Value {
    json_of(args, &kinegen(&[args, &["--json", "-"]].concat()))
}

/// [`kinegen_json`] in `dir`, also checking that the text printed beside
/// the JSON (stderr: the default text) reads at a glance, unless `args`
/// ask for more with `-v`.
pub fn kinegen_json_glanceable(dir: &Path, args: &[&str]) -> serde_json::Value {
    let o = kinegen_in(dir, &[args, &["--json", "-"]].concat());
    let doc = json_of(args, &o);
    if !args.iter().any(|a| *a == "-v" || *a == "--verbose") {
        assert_glanceable(args, &stderr(&o));
    }
    doc
}

/// The JSON document a successful run printed.
fn json_of(args: &[&str], o: &Output) -> serde_json::Value {
    assert!(
        o.status.success(),
        "kinegen {:?} failed: {}",
        args,
        stderr(o)
    );
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "stdout of {args:?} is not one JSON document ({e}): {}",
            stdout(o)
        )
    })
}

/// Simulate a log into `dir`; returns its path.
pub fn simulate(dir: &Path, name: &str, args: &[&str]) -> PathBuf {
    let out = dir.join(name);
    let mut a = vec!["simulate"];
    a.extend_from_slice(args);
    a.extend(["--out", out.to_str().unwrap()]);
    let o = kinegen(&a);
    assert!(o.status.success(), "simulate {args:?}: {}", stderr(&o));
    out
}

// ---- named scenarios

impl Sim<'_> {
    /// The log to `log` (returned) and its sightings to `obs`, by `kinegen
    /// simulate`.
    pub fn write_to(&self, log: &Path, obs: &Path) -> PathBuf {
        let mut a = self.options();
        if self.landmarks.is_some() {
            a.extend(["--observations".into(), obs.display().to_string()]);
        }
        a.extend(["--out".into(), log.display().to_string()]);
        let args: Vec<&str> = std::iter::once("simulate")
            .chain(a.iter().map(String::as_str))
            .collect();
        let o = kinegen(&args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        log.to_path_buf()
    }
}

/// A log of seed 000's Omni robot at its truth ([`SEED_000_TRUTH`]), random
/// driving from `seed`, written to `dir/name`.
pub fn seed_000_log(dir: &Path, name: &str, seed: u64) -> PathBuf {
    Sim::seed_000(seed).write(dir, name)
}

/// `kinegen add-effect`: `spec` with the catalogue's `effect` added (at
/// `values`, each `NAME=VALUE`), written to `out`, which is returned.
pub fn add_effect(spec: &Path, effect: &str, values: &[&str], out: &Path) -> PathBuf {
    let mut a = vec![
        "add-effect",
        "--spec",
        spec.to_str().unwrap(),
        "--effect",
        effect,
    ];
    for v in values {
        a.extend(["--value", v]);
    }
    a.extend(["--out", out.to_str().unwrap()]);
    let o = kinegen(&a);
    assert!(o.status.success(), "add-effect {effect}: {}", stderr(&o));
    out.to_path_buf()
}

/// The sightings of `all` (`t,id,range,bearing`) within a camera's 0.6 rad
/// half-field of view, each rewritten as `read(range, bearing)` reads it,
/// written to `out`, which is returned.
pub fn camera_view(all: &Path, out: &Path, read: fn(f64, f64) -> (f64, f64)) -> PathBuf {
    let text = std::fs::read_to_string(all).unwrap();
    let mut s = String::from("t,id,range,bearing\n");
    for l in text.lines().skip(1) {
        let f: Vec<&str> = l.split(',').collect();
        let (r, b): (f64, f64) = (f[2].parse().unwrap(), f[3].parse().unwrap());
        if b.abs() <= 0.6 {
            let (r, b) = read(r, b);
            s += &format!("{},{},{r:.4},{b:.4}\n", f[0], f[1]);
        }
    }
    std::fs::write(out, s).unwrap();
    out.to_path_buf()
}

/// A CSV text with its header kept and every data cell rewritten by
/// `edit(column index, cell)`: a log or sightings file in another unit or
/// convention, made from a simulated one.
pub fn edit_cells(csv: &str, edit: impl Fn(usize, &str) -> String) -> String {
    let mut lines = csv.lines();
    let mut out = lines.next().unwrap_or_default().to_string() + "\n";
    for l in lines {
        let cells: Vec<String> = l.split(',').enumerate().map(|(c, v)| edit(c, v)).collect();
        out += &(cells.join(",") + "\n");
    }
    out
}

/// The most lines, and the widest, a command prints by default.
pub const GLANCE_LINES: usize = 25;
pub const GLANCE_WIDTH: usize = 100;

/// What `kinegen args` printed by default (`text`) reads at a glance: at
/// most 25 lines of at most 100 characters, and for the analysis commands
/// an answer line. Tests that run a command on a real log for its figures
/// (its JSON on stdout, this text on stderr) check its shape too, so the
/// long runs are made once.
pub fn assert_glanceable(args: &[&str], text: &str) {
    let lines: Vec<&str> = text.lines().collect();
    assert!(
        lines.len() <= GLANCE_LINES,
        "kinegen {args:?}: {} lines:\n{text}",
        lines.len()
    );
    let wide: Vec<&&str> = (lines.iter())
        .filter(|l| l.chars().count() > GLANCE_WIDTH)
        .collect();
    assert!(
        wide.is_empty(),
        "kinegen {args:?}: lines over {GLANCE_WIDTH}: {wide:#?}"
    );
    if matches!(
        args[0],
        "compare" | "fit" | "diagnose" | "localize" | "bench-real"
    ) {
        assert!(
            lines.iter().any(|l| l.starts_with("answer: ")),
            "kinegen {args:?}: no answer line:\n{text}"
        );
    }
}

// ---- documentation run as written (tests/readme.rs, tests/howtos.rs)

pub fn bin_dir() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_kinegen")).parent().unwrap()
}

/// Run a shell script as written (bash -euo pipefail) in a fresh temporary
/// home, with kinegen on the PATH and `/path/to/kinegen` standing for this
/// checkout: the home (kept for the caller to look into) and the output.
pub fn run_in_home(script: &str) -> (tempfile::TempDir, std::process::Output) {
    let home = tempfile::tempdir().unwrap();
    let script = script.replace("/path/to/kinegen", &root().display().to_string());
    let o = Command::new("bash")
        .args(["-euo", "pipefail", "-c", &script])
        .env("HOME", home.path())
        .env("PATH", path_with_kinegen())
        .current_dir(home.path())
        .output()
        .unwrap();
    (home, o)
}

pub fn path_with_kinegen() -> String {
    format!(
        "{}:{}",
        bin_dir().display(),
        std::env::var("PATH").unwrap_or_default()
    )
}

/// Each line shown must be printed (`...` skips any number of lines), in
/// order.
pub fn shows(shown: &str, printed: &str) -> Result<(), String> {
    let printed: Vec<&str> = printed.lines().map(str::trim_end).collect();
    let mut at = 0;
    for want in shown.lines().map(str::trim_end) {
        if want == "..." {
            continue;
        }
        match printed[at..].iter().position(|l| *l == want) {
            Some(i) => at += i + 1,
            None => return Err(format!("`{want}` is not printed (after line {at})")),
        }
    }
    Ok(())
}
