//! Sessions in the layout of the OptiOdom study (Sousa et al. 2022; see
//! `../shared/real/optiodom-dev/README.md`): one folder per session with
//! `run-NN.csv` files and a `metadata.json`, and one `published.json` with
//! every method's calibration per session. A benchmark file
//! (`spec/benchmarks/optiodom/benchmark.toml`) names, per robot type, the
//! spec its user would write and how the study's parameter names map onto
//! the spec's.
use super::{Calibration, Session};
use crate::model_on_log::derivation::Deriver;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::files::{read_text, unreadable};
use kinegen_model::ir::ModelIr;
use kinegen_model::spec::Model;
use serde::Deserialize;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The benchmark file.
#[derive(Debug)]
pub struct Config {
    /// Per robot type (a session's `type`).
    pub robot: BTreeMap<String, RobotConfig>,
}

#[derive(Debug)]
pub struct RobotConfig {
    /// The spec, relative to the benchmark file.
    pub spec: PathBuf,
    /// Spec parameter -> the study's parameter (value = study's * scale).
    pub published: BTreeMap<String, Mapped>,
}

#[derive(Debug)]
pub struct Mapped {
    pub name: String,
    pub scale: f64,
    /// Where the mapping is written in the benchmark file (1-based), for
    /// errors.
    pub line: usize,
}

/// The benchmark file as written: a mapping's span gives its line.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    robot: BTreeMap<String, RawRobotConfig>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRobotConfig {
    spec: PathBuf,
    #[serde(default)]
    published: BTreeMap<String, toml::Spanned<RawMapped>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMapped {
    name: String,
    #[serde(default = "one")]
    scale: f64,
}

fn one() -> f64 {
    1.0
}

impl Config {
    pub fn read(path: &Path) -> Result<Config, BenchError> {
        let unread = |message: String| BenchError::Unread {
            path: path.to_path_buf(),
            message,
        };
        let text = read_text(path).map_err(|e| unread(unreadable(e)))?;
        let raw: RawConfig = toml::from_str(&text).map_err(|e| unread(e.to_string()))?;
        let line = |at: usize| text[..at.min(text.len())].matches('\n').count() + 1;
        let robot = raw.robot.into_iter().map(|(name, r)| {
            let published = r.published.into_iter().map(|(key, m)| {
                let at = line(m.span().start);
                let m = m.into_inner();
                (
                    key,
                    Mapped {
                        name: m.name,
                        scale: m.scale,
                        line: at,
                    },
                )
            });
            let published = published.collect();
            (
                name,
                RobotConfig {
                    spec: r.spec,
                    published,
                },
            )
        });
        Ok(Config {
            robot: robot.collect(),
        })
    }
}

/// A study folder, benchmark file or session that cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("{}: no such folder (give the folder of OptiOdom sessions, e.g. ../shared/real/optiodom-dev)", .0.display())]
    NoFolder(PathBuf),
    /// A file or folder that cannot be read or parsed, with what its reader says.
    #[error("{}: {message}", path.display())]
    Unread { path: PathBuf, message: String },
    #[error("{}:{line}: robot.{robot}.published.{key}: {} has no parameter `{key}` (it has: {})", config.display(), spec.display(), known.join(", "))]
    UnknownPublished {
        config: PathBuf,
        line: usize,
        robot: String,
        key: String,
        spec: PathBuf,
        known: Box<[String]>,
    },
    #[error("{}: no session folders (with a metadata.json){}", dir.display(), if only.is_empty() { String::new() } else { format!(" named {}", only.join(", ")) })]
    NoSessions { dir: PathBuf, only: Vec<String> },
    /// A robot's spec that does not give a model.
    #[error("{0}")]
    Spec(String),
    #[error(transparent)]
    Log(#[from] crate::logs::log::LogError),
}

/// Where a session's folder says what it is.
#[derive(Debug, Deserialize)]
struct Metadata {
    #[serde(rename = "type")]
    robot: String,
    pattern: String,
    session: String,
    run_files: Vec<RunFile>,
    #[serde(default)]
    kinegen_nominal: BTreeMap<String, Value>,
}

#[derive(Debug, Deserialize)]
struct RunFile {
    file: String,
}

/// What reading a study folder gives: its sessions, and what was left out.
pub struct Loaded {
    pub sessions: Vec<Session>,
    pub warnings: Vec<String>,
}

/// Read the sessions under `dir` whose folder name starts with one of
/// `only` (all when empty), for the robot types `config` (read from
/// `config_path`) knows. `deriver` gives a spec's IR (the CLI's derives it
/// in a child process); `max_gap` splits a log at longer gaps as every
/// command does.
pub fn load(
    dir: &Path,
    config_path: &Path,
    only: &[String],
    max_gap: f64,
    deriver: &dyn Deriver,
) -> Result<Loaded, BenchError> {
    if !dir.is_dir() {
        return Err(BenchError::NoFolder(dir.to_path_buf()));
    }
    let config = Config::read(config_path)?;
    // a scale that is not a finite number other than 0 made a method's
    // error infinite (and kinegen "win") or its scores null
    for (robot, r) in &config.robot {
        for (key, m) in &r.published {
            if !(m.scale.is_finite() && m.scale != 0.0) {
                return Err(BenchError::Unread {
                    path: config_path.to_path_buf(),
                    message: format!(
                        "line {}: robot.{robot}.published.{key}.scale = {}: a finite number other than 0",
                        m.line, m.scale
                    ),
                });
            }
        }
    }
    let base = config_path.parent().unwrap_or(Path::new("."));
    let published = read_json(&dir.join("published.json"))?;
    let mut folders: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| BenchError::Unread {
            path: dir.to_path_buf(),
            message: e.to_string(),
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    folders.sort();
    let mut irs: BTreeMap<String, ModelIr> = BTreeMap::new();
    let (mut sessions, mut warnings) = (Vec::new(), Vec::new());
    // a session folder without its metadata is left out, and said
    let (folders, bare): (Vec<PathBuf>, Vec<PathBuf>) = folders
        .into_iter()
        .partition(|p| p.join("metadata.json").is_file());
    if !bare.is_empty() {
        let names: Vec<String> = bare
            .iter()
            .map(|p| {
                p.file_name()
                    .unwrap_or_default()
                    .to_string_lossy()
                    .to_string()
            })
            .collect();
        warnings.push(format!(
            "{} folder(s) without a metadata.json left out: {}",
            names.len(),
            names.join(", ")
        ));
    }
    for folder in folders {
        let name = folder.file_name().unwrap().to_string_lossy().to_string();
        if !only.is_empty() && !only.iter().any(|o| name.starts_with(o.as_str())) {
            continue;
        }
        let meta_path = folder.join("metadata.json");
        let meta: Metadata =
            serde_json::from_value(read_json(&meta_path)?).map_err(|e| BenchError::Unread {
                path: meta_path.clone(),
                message: e.to_string(),
            })?;
        let Some(robot) = config.robot.get(&meta.robot) else {
            warnings.push(format!(
                "{name}: robot type `{}` has no entry in {}; left out",
                meta.robot,
                config_path.display()
            ));
            continue;
        };
        if !irs.contains_key(&meta.robot) {
            let spec = base.join(&robot.spec);
            let model = Model::load(&spec).map_err(|e| BenchError::Spec(e.to_string()))?;
            let ir = deriver
                .derive(&model, &spec.display().to_string())
                .map_err(|e| BenchError::Spec(e.to_string()))?;
            let known: Vec<String> = ir.runtime_params().iter().map(|p| p.name.clone()).collect();
            if let Some((k, m)) = robot.published.iter().find(|(k, _)| !known.contains(k)) {
                return Err(BenchError::UnknownPublished {
                    config: config_path.to_path_buf(),
                    line: m.line,
                    robot: meta.robot.clone(),
                    key: k.clone(),
                    spec,
                    known: known.into(),
                });
            }
            irs.insert(meta.robot.clone(), ir);
        }
        let ir = irs[&meta.robot].clone();
        let key = format!("{}/{}/{}", meta.robot, meta.pattern, meta.session);
        let session = session(
            &folder,
            &meta,
            robot,
            ir,
            published.get(&key),
            max_gap,
            &mut warnings,
        )?;
        sessions.push(Session {
            recorded: key.clone(),
            name: key,
            ..session
        });
    }
    if sessions.is_empty() {
        return Err(BenchError::NoSessions {
            dir: dir.to_path_buf(),
            only: only.to_vec(),
        });
    }
    Ok(Loaded { sessions, warnings })
}

fn read_json(path: &Path) -> Result<Value, BenchError> {
    let unread = |message: String| BenchError::Unread {
        path: path.to_path_buf(),
        message,
    };
    let text = read_text(path).map_err(|e| unread(unreadable(e)))?;
    serde_json::from_str(&text).map_err(|e| unread(e.to_string()))
}

/// One session folder: the model at its nominal values, its runs, and the
/// published calibrations (`published`: its entry of published.json).
fn session(
    folder: &Path,
    meta: &Metadata,
    robot: &RobotConfig,
    ir: ModelIr,
    published: Option<&Value>,
    max_gap: f64,
    warnings: &mut Vec<String>,
) -> Result<Session, BenchError> {
    let known: Vec<String> = ir.runtime_params().iter().map(|p| p.name.clone()).collect();
    let sets: Vec<(String, f64)> = meta
        .kinegen_nominal
        .iter()
        .filter(|(k, _)| known.contains(k))
        .filter_map(|(k, v)| v.as_f64().map(|v| (k.clone(), v)))
        .collect();
    let runner = Runner::new(ir, &sets).map_err(|e| BenchError::Unread {
        path: folder.to_path_buf(),
        message: e.to_string(),
    })?;
    let mut runs = Vec::new();
    for f in &meta.run_files {
        let run = Run::read(&folder.join(&f.file), &runner)?;
        let (pieces, warning) = run.split_at_gaps(max_gap);
        warnings.extend(warning);
        runs.extend(pieces);
    }
    let published = published
        .and_then(Value::as_array)
        .map(|methods| calibrations(methods, robot, &runner))
        .unwrap_or_default();
    Ok(Session {
        name: String::new(),
        recorded: String::new(),
        robot: meta.robot.clone(),
        runner,
        runs,
        published,
    })
}

/// The published calibrations of a session in the spec's terms: each
/// method's `session` variant with calibrated parameters (the study also
/// lists re-runs from other starting values, and methods it could not
/// calibrate with).
fn calibrations(methods: &[Value], robot: &RobotConfig, r: &Runner) -> Vec<Calibration> {
    methods
        .iter()
        .filter(|m| m["variant"] == "session")
        .filter_map(|m| {
            let cal = m["params_cal"].as_object().filter(|c| !c.is_empty())?;
            let values: Vec<(usize, f64)> = robot
                .published
                .iter()
                .filter_map(|(spec_name, mapped)| {
                    let k = r.names.iter().position(|n| n == spec_name)?;
                    Some((k, cal.get(&mapped.name)?.as_f64()? * mapped.scale))
                })
                .collect();
            // a published value of 0, or one outside the spec's bounds, is
            // no calibration of this robot (it scored null): left out
            let usable = values.iter().all(|&(k, v)| {
                let p = &r.ir.runtime_params()[k];
                v.is_finite()
                    && v != 0.0
                    && p.min.is_none_or(|m| v > m)
                    && p.max.is_none_or(|m| v <= m)
            });
            if !usable {
                return None;
            }
            Some(Calibration {
                method: m["sheet"].as_str()?.to_string(),
                values,
                study_final_m: m["cal"]["final_pos"].as_f64(),
            })
        })
        .collect()
}
