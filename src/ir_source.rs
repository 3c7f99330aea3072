//! Getting a spec's IR.
//!
//! The analysis (simulate, compare, fit, diagnose, localize, batches and
//! benchmarks) runs on [`analysis_deriver`]: the committed IR of a bundled
//! spec when it is current, else the spec differentiated in this process by
//! `kinegen_model::autodiff`, which needs no symbolica, takes milliseconds
//! and may run on every thread.
//!
//! The symbolic IR (closed-form inverse kinematics, the simplified kernels
//! `generate` emits and `verify` checks) comes from [`symbolic_deriver`]:
//! 1. The committed IR of the generated crate, when its spec fingerprint matches.
//! 2. A cache of earlier derivations (temp dir, keyed by fingerprint).
//! 3. Otherwise `kinegen derive` in a child process: symbolica's one-thread permit is
//!    then held only while deriving, its output never reaches our stdout, and this
//!    process stays free to use threads.
use kinegen_analysis::model_on_log::derivation::{
    as_in_its_file, committed, AutodiffDeriver, DerivationFailed, Deriver,
};
use kinegen_model::ir::ModelIr;
use kinegen_model::spec::Model;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// Version of the IR's JSON layout: part of the cache key, so an IR derived by
/// an older kinegen (without observation roles, or with libm::pow powers
/// instead of products: format 3; unshared reciprocals: 4; an integrated
/// inverse whose whole expression got the series branch: 5; measurement delays
/// found by name: 6; kernels and arguments named by string: 7; steps
/// differentiated through the expanded twist: 8, which also divided by a
/// denominator used once instead of multiplying by its reciprocal; |x|
/// differentiated as x/|x|, NaN at x = 0 where it is now sign(x): 9) is
/// never reused.
const IR_FORMAT: u32 = 10;

pub fn cache_dir() -> PathBuf {
    std::env::temp_dir().join("kinegen-ir-cache")
}

/// The symbolic [`Deriver`]: [`load`] (the committed IR, the cache, or
/// `kinegen derive` in a child process) of a spec as its file has it; a
/// model built in memory (a spec with effects added has no file of its own)
/// goes to the child as text on stdin, and its errors name it by `label`.
pub struct ChildDeriver;

impl Deriver for ChildDeriver {
    fn derive(&self, model: &Model, label: &str) -> Result<ModelIr, DerivationFailed> {
        // a spec read from its file as it is there: the file itself (next to
        // its generated/ir, if it has one)
        if as_in_its_file(model) {
            return load(&model.path).map_err(DerivationFailed);
        }
        // a model built in memory (effects added): its text goes to the
        // child on stdin, named by `label`; no spec file is written
        derive_cached(model, Spec::Text(label)).map_err(DerivationFailed)
    }
}

/// The deriver the analysis commands use: in-process automatic
/// differentiation, no symbolica, no lock, any number of threads. For a
/// same-run baseline, `KINEGEN_ANALYSIS_DERIVER=symbolic` (full build only)
/// runs the analysis on the symbolic IR instead, derived in a child process
/// as before automatic differentiation (`scripts/bench_derivers.py` compares
/// the two).
pub fn analysis_deriver() -> &'static dyn Deriver {
    let symbolic = std::env::var("KINEGEN_ANALYSIS_DERIVER").is_ok_and(|v| v == "symbolic");
    if symbolic && cfg!(feature = "symbolic") {
        &ChildDeriver
    } else {
        &AutodiffDeriver
    }
}

/// The deriver of commands that need closed forms only the symbolic stage
/// gives (`inverse`, `navigate`): a child process, as symbolica allows one
/// thread per user and machine and holding it for a whole command would
/// keep every other kinegen waiting. A kinegen built without the symbolic
/// stage says so (exit 2) for a spec without a committed IR.
pub fn symbolic_deriver() -> &'static dyn Deriver {
    &ChildDeriver
}

/// How the derive child gets the spec.
#[derive(Clone, Copy)]
enum Spec<'a> {
    /// The spec file itself.
    File(&'a Path),
    /// The model's text on stdin; the label names it in messages.
    Text(&'a str),
}

/// Load and validate a spec and return its symbolic IR.
pub fn load(spec: &Path) -> Result<ModelIr, String> {
    let model = Model::load(spec).map_err(|e| e.to_string())?;
    match committed(spec, &model) {
        Some(ir) => Ok(ir),
        None => derive_cached(&model, Spec::File(spec)),
    }
}

/// The IR of `model` from the cache, or derived into it by `kinegen derive`
/// in a child process.
fn derive_cached(model: &Model, spec: Spec) -> Result<ModelIr, String> {
    let fp = model.fingerprint();
    let cached = cache_dir().join(format!("{}-{fp}-ir{IR_FORMAT}.json", model.name));
    if let Ok(text) = std::fs::read_to_string(&cached) {
        if let Ok(ir) = ModelIr::from_json(&text) {
            return Ok(ir);
        }
    }
    let exe =
        std::env::current_exe().map_err(|e| format!("cannot find the kinegen binary: {e}"))?;
    let mut command = Command::new(exe);
    command.args(["derive", "--spec"]);
    let named = match spec {
        Spec::File(path) => {
            command.arg(path);
            path.display().to_string()
        }
        Spec::Text(label) => {
            command.args(["-", "--label", label]).stdin(Stdio::piped());
            label.to_string()
        }
    };
    let mut child = command
        .arg("--ir-out")
        .arg(&cached)
        // symbolica's banner is drained here rather than sent to /dev/null,
        // which is a plain file on some containers and would keep it.
        .stdout(Stdio::piped())
        // what the child says is ours to say: its error becomes this
        // derivation's (the caller names the spec it came from, not a file
        // in the cache); symbolica's own log lines (an infinity met while
        // trying an inverse that does not exist) are not the user's
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot run `kinegen derive`: {e}"))?;
    crate::signals::child_started(child.id());
    if let Some(mut input) = child.stdin.take() {
        // a spec is a few kilobytes, under any pipe's buffer; an error
        // means the child ended early, which its status and stderr say
        let _ = std::io::Write::write_all(&mut input, model.source.as_bytes());
    }
    let said = child.stderr.take().map(|mut e| {
        std::thread::spawn(move || {
            let mut text = String::new();
            // an error here only means the child closed its stderr early
            let _ = std::io::Read::read_to_string(&mut e, &mut text);
            text
        })
    });
    if let Some(mut banner) = child.stdout.take() {
        // an error here only means the child closed its stdout early
        let _ = std::io::copy(&mut banner, &mut std::io::sink());
    }
    let status = child.wait();
    crate::signals::child_finished(child.id());
    let said = said.and_then(|t| t.join().ok()).unwrap_or_default();
    let status = status.map_err(|e| format!("`kinegen derive` did not finish: {e}"))?;
    if !status.success() {
        // kinegen's own error, else the child's last word (a crash's)
        return Err(match said.find("error: ") {
            Some(at) => said[at + "error: ".len()..].trim().to_string(),
            None => match said.lines().rev().find(|l| !l.trim().is_empty()) {
                Some(last) => format!("{named}: derivation failed: {}", last.trim()),
                None => format!("{named}: derivation failed"),
            },
        });
    }
    let text =
        std::fs::read_to_string(&cached).map_err(|e| format!("{}: {e}", cached.display()))?;
    ModelIr::from_json(&text).map_err(|e| format!("{}: {e}", cached.display()))
}

/// What a binary built without the derivation stage says when it needs it.
#[cfg_attr(feature = "symbolic", allow(dead_code))]
pub const NO_SYMBOLIC: &str = "this kinegen was built without its symbolic stage (the `symbolic` feature), which `generate`, `verify` and `derive` need, as do `inverse` and `navigate` for a spec whose closed-form inverse kinematics are not committed; every analysis command works without it; build the full kinegen with `cargo build --bin kinegen` (the default features)";

/// `kinegen derive`: derive one spec's IR into a file (used by `load`).
#[cfg(not(feature = "symbolic"))]
pub fn derive_to(_spec: &Path, _label: Option<&str>, _out: &Path) -> Result<(), String> {
    Err(NO_SYMBOLIC.into())
}

/// `kinegen derive`: derive one spec's IR into a file (used by `load`); a
/// spec `-` is read from stdin and named `label` in messages.
#[cfg(feature = "symbolic")]
pub fn derive_to(spec: &Path, label: Option<&str>, out: &Path) -> Result<(), String> {
    let model = if spec == Path::new("-") {
        let mut text = String::new();
        std::io::Read::read_to_string(&mut std::io::stdin(), &mut text)
            .map_err(|e| format!("cannot read the spec from stdin: {e}"))?;
        Model::parse(Path::new(label.unwrap_or("<stdin>")), &text)
    } else {
        Model::load(spec)
    }
    .map_err(|e| e.to_string())?;
    let ir =
        kinegen_codegen::derive_model(&model, &Default::default()).map_err(|e| e.to_string())?;
    kinegen_model::files::write_atomic(out, &ir.to_json()).map_err(|e| e.to_string())
}
