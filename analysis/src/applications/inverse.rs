//! Integrated inverse kinematics along a planned path (seed 001 eq. 12-18): the
//! input profile that drives the model through the path's poses, step by step,
//! from the generated `inverse_increment` (through the evaluator), checked
//! against what the actuators can deliver: each input's `range` (its value: a
//! wheel's rate, a steering lock) and `max_rate` (a wheel's rate, or how fast an
//! absolute input such as a steering angle can change).
use crate::logs::log::{read_csv, unwrap, LogError};
use crate::model_on_log::model::Runner;
use crate::model_on_log::steering;
use kinegen_model::decl::InputKind;
use kinegen_model::ir::{ArgRole, StepForm};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// A planned path `t,x,y,theta` (world frame, heading unwrapped).
pub struct PlannedPath {
    pub file: PathBuf,
    pub t: Vec<f64>,
    pub pose: Vec<[f64; 3]>,
}

/// Read a path file; every problem is located (file, line, column).
pub fn read_path(path: &Path) -> Result<PlannedPath, LogError> {
    let (header, mut rdr) = read_csv(path, "path")?;
    let idx = header.require(&["t", "x", "y", "theta"])?;
    let (mut t, mut x, mut y, mut th) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (n, rec) in rdr.records().enumerate() {
        let (line, rec) = header.record(n, rec)?;
        let v: Vec<f64> = idx
            .iter()
            .map(|&i| header.number(line, &rec, i))
            .collect::<Result<_, _>>()?;
        if let Some(&prev) = t.last() {
            if v[0] <= prev {
                let what = if v[0] == prev {
                    "a time step of zero"
                } else {
                    "time going backwards"
                };
                return Err(header.err(
                    Some(line),
                    Some("t"),
                    format!("{what}: {} follows {prev} (t must increase strictly)", v[0]),
                ));
            }
        }
        t.push(v[0]);
        x.push(v[1]);
        y.push(v[2]);
        th.push(v[3]);
    }
    if t.len() < 2 {
        return Err(LogError::new(
            path,
            None,
            None,
            format!("the path has {} row(s); it needs at least 2", t.len()),
        ));
    }
    let th = unwrap(&th);
    Ok(PlannedPath {
        file: path.to_path_buf(),
        pose: (0..t.len()).map(|k| [x[k], y[k], th[k]]).collect(),
        t,
    })
}

/// One input along the path.
#[derive(Debug, Clone, Serialize)]
pub struct InputProfile {
    pub name: String,
    pub unit: String,
    pub kind: InputKind,
    /// The input's value over each step (a rate for a cumulative input).
    pub value: Vec<f64>,
    /// What `max_rate` limits, per step: |value| for a cumulative input, |change
    /// per second| for an absolute one (0 on the first step: the start is free).
    pub rate: Vec<f64>,
    pub max_rate: Option<f64>,
    pub range: Option<[f64; 2]>,
    pub peak_rate: f64,
}

/// A stretch of the path the robot cannot drive as planned.
#[derive(Debug, Clone, Serialize)]
pub struct Stretch {
    /// The input at fault, or "path" for motion the model cannot make at all.
    pub input: String,
    pub t_start: f64,
    pub t_end: f64,
    /// Why, for people ("rate 12.3 > max_rate 10").
    pub why: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct Profile {
    /// Start time of each step.
    pub t: Vec<f64>,
    pub inputs: Vec<InputProfile>,
    pub infeasible: Vec<Stretch>,
    /// The largest distance, over one step, between the planned position and
    /// where the inputs take the model (a non-holonomic robot cannot follow
    /// sideways motion; seed 001 eq. 12: x and theta are imposed, y follows).
    pub max_step_miss_m: f64,
}

/// Miss per step above which the path is marked as not followable: 5 mm plus
/// 25% of the step. A path that asks for sideways motion misses by about its
/// whole step; a recorded path with millimetres of tracker noise, or a planned
/// one whose heading lags its curvature a little, stays below.
const MISS_ABS_M: f64 = 5e-3;
const MISS_REL: f64 = 0.25;

/// Stretches closer than this (s) are one stretch.
const MERGE_GAP_S: f64 = 1.0;

/// Why a path's inputs cannot be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProfileError {
    #[error(transparent)]
    NoInverse(#[from] kinegen_model::ir::NoInverse),
    #[error("{}: the inverse of the step at t = {t} s gives a non-finite `{input}` (a turn of {turn:.3} rad in one step: the path needs more rows)", file.display())]
    NotFinite {
        file: std::path::PathBuf,
        t: f64,
        input: String,
        turn: f64,
    },
}

/// The input profile of `path` for the model of `r`.
pub fn profile(r: &Runner, path: &PlannedPath) -> Result<Profile, ProfileError> {
    let steps = solve_steps(r, path)?;
    let n = path.t.len() - 1;
    let t: Vec<f64> = path.t[..n].to_vec();
    let mut inputs = Vec::new();
    let mut infeasible = Vec::new();
    for (j, name) in steps.names.iter().enumerate() {
        let Some(spec) = r.ir.inputs.iter().find(|i| &i.name == name) else {
            continue;
        };
        let (p, out_of_bounds) = input_profile(spec, name, &steps.values[j], &t, path.t[n]);
        inputs.push(p);
        infeasible.extend(out_of_bounds);
    }
    let max_step_miss_m = (0..n)
        .map(|k| {
            let a = path.pose[k];
            let b = path.pose[k + 1];
            steps.misses[k] * (MISS_ABS_M + MISS_REL * (b[0] - a[0]).hypot(b[1] - a[1]))
        })
        .fold(0.0f64, f64::max);
    let misses = with_drift(&steps.misses, &steps.lateral, &t);
    infeasible.extend(stretches(&t, &path.t[n], &misses, |x| x > 1.0).into_iter().map(|(a, b, _)| Stretch {
        input: "path".into(),
        t_start: a,
        t_end: b,
        why: "moves the robot in a direction it cannot move (sideways, for a non-holonomic robot): the inputs shown follow the path's heading and forward motion only".into(),
    }));
    infeasible.sort_by(|a, b| a.t_start.total_cmp(&b.t_start));
    Ok(Profile {
        t,
        inputs,
        infeasible,
        max_step_miss_m,
    })
}

/// Each step's miss, or the sideways miss the steps of the second before it
/// add up to where that is larger (both in units of the tolerance for the
/// distance they cover). A path that asks for a little sideways motion in
/// every step (0.2 m/s at 20 Hz: 1 cm a step, under the 1.2 cm a step may
/// miss) drifts 20 cm sideways in a second, which a robot that cannot strafe
/// does not follow. Tracker noise does not add up: a sum of differences of
/// noisy poses is the difference of its ends.
fn with_drift(misses: &[f64], lateral: &[(f64, f64)], t: &[f64]) -> Vec<f64> {
    const WINDOW_S: f64 = 1.0;
    let mut from = 0;
    let (mut side, mut dist) = (0.0, 0.0);
    (0..misses.len())
        .map(|k| {
            side += lateral[k].0;
            dist += lateral[k].1;
            while t[k] - t[from] > WINDOW_S {
                side -= lateral[from].0;
                dist -= lateral[from].1;
                from += 1;
            }
            misses[k].max(side.abs() / (MISS_ABS_M + MISS_REL * dist))
        })
        .collect()
}

/// Each step's inputs by the inverse kinematics, and how far the model, fed
/// them, misses the step (in units of the tolerance).
struct Steps {
    names: Vec<String>,
    /// per input, per step
    values: Vec<Vec<f64>>,
    misses: Vec<f64>,
    /// per step: the sideways miss (body frame, signed) and the step's length
    lateral: Vec<(f64, f64)>,
}

/// The inverse kinematics of every step of `path`, the configuration
/// (caster angles, a steering angle) carried from step to step.
fn solve_steps(r: &Runner, path: &PlannedPath) -> Result<Steps, ProfileError> {
    let inv = r.ir.inverse_increment()?;
    let step = r.ir.step(StepForm::Exact).value;
    let names = &inv.row_names;
    // configuration inputs (steering angles of caster wheels) the inverse starts from
    let cfg_names: Vec<String> = inv
        .args
        .iter()
        .find(|a| a.role == ArgRole::Configuration)
        .map(|a| a.names.clone())
        .unwrap_or_default();
    let mut cfg = vec![0.0; cfg_names.len()];
    // absolute inputs the inverse only reads (a car-like robot's steering
    // angle, see crate::model_on_log::steering): solved for each step's twist and reported
    // with the rates
    let tw_names = steering::configuration_names(r);
    let solve_idx = steering::to_solve(r, &[]);
    let solved: Vec<String> = solve_idx.iter().map(|&k| tw_names[k].clone()).collect();
    let mut tw_cfg = vec![0.0; tw_names.len()];
    let names: Vec<String> = names
        .iter()
        .cloned()
        .chain(solved.iter().cloned())
        .collect();
    let names = &names;
    let n = path.t.len() - 1;
    let mut values: Vec<Vec<f64>> = vec![Vec::with_capacity(n); names.len()];
    let mut misses = Vec::with_capacity(n);
    let mut lateral = Vec::with_capacity(n);
    let zeros = [0.0; 16];
    for k in 0..n {
        let dt = path.t[k + 1] - path.t[k];
        let (a, b) = (path.pose[k], path.pose[k + 1]);
        let (c, s) = (a[2].cos(), a[2].sin());
        let (wx, wy) = (b[0] - a[0], b[1] - a[1]);
        let dpose = [c * wx + s * wy, -s * wx + c * wy, b[2] - a[2]];
        if !solve_idx.is_empty() {
            steering::solve(r, &se2_log(&dpose, dt), &mut tw_cfg, &solve_idx);
            for (cv, name) in cfg.iter_mut().zip(&cfg_names) {
                if let Some(k) = solved.iter().position(|x| x == name) {
                    *cv = tw_cfg[solve_idx[k]];
                }
            }
        }
        let args: Vec<&[f64]> = inv
            .args
            .iter()
            .map(|a| match a.role {
                ArgRole::PoseIncrement => &dpose[..],
                ArgRole::Dt => std::slice::from_ref(&dt),
                ArgRole::Params => &r.p[..],
                _ => &cfg[..],
            })
            .collect();
        let mut u = r.eval(inv, &args);
        u.extend(solve_idx.iter().map(|&k| tw_cfg[k]));
        if let Some(i) = u.iter().position(|v| !v.is_finite()) {
            return Err(ProfileError::NotFinite {
                file: path.file.clone(),
                t: path.t[k],
                input: names[i].clone(),
                turn: dpose[2],
            });
        }
        for (cv, name) in cfg.iter_mut().zip(&cfg_names) {
            if let Some(i) = names.iter().position(|x| x == name) {
                *cv = u[i];
            }
        }
        // where these inputs take the model, against the plan
        let model_u =
            r.ir.inputs
                .iter()
                .map(|i| {
                    names
                        .iter()
                        .position(|x| x == &i.name)
                        .map(|j| u[j])
                        .or_else(|| cfg_names.iter().position(|x| x == &i.name).map(|j| cfg[j]))
                        .unwrap_or(0.0)
                })
                .collect::<Vec<_>>();
        let end = r.eval(
            step,
            &Runner::step_args(step, &[0.0, 0.0, 0.0], &model_u, &r.p, &[dt], &zeros),
        );
        misses.push(
            (end[0] - dpose[0]).hypot(end[1] - dpose[1])
                / (MISS_ABS_M + MISS_REL * dpose[0].hypot(dpose[1])),
        );
        lateral.push((dpose[1] - end[1], dpose[0].hypot(dpose[1])));
        for (col, v) in values.iter_mut().zip(&u) {
            col.push(*v);
        }
    }
    Ok(Steps {
        names: names.clone(),
        values,
        misses,
        lateral,
    })
}

/// One input's profile over the path (its values and rates) and the
/// stretches where it exceeds its declared rate or range.
fn input_profile(
    spec: &kinegen_model::decl::Input,
    name: &str,
    v: &[f64],
    t: &[f64],
    t_end: f64,
) -> (InputProfile, Vec<Stretch>) {
    let n = t.len();
    let mut infeasible = Vec::new();
    let rate: Vec<f64> = match spec.kind {
        InputKind::Cumulative => v.iter().map(|x| x.abs()).collect(),
        InputKind::Absolute => (0..n)
            .map(|k| {
                if k == 0 {
                    0.0
                } else {
                    ((v[k] - v[k - 1]) / (t[k] - t[k - 1])).abs()
                }
            })
            .collect(),
    };
    let per_s = if spec.kind == InputKind::Absolute {
        format!("{}/s", spec.unit)
    } else {
        spec.unit.clone()
    };
    if let Some(m) = spec.max_rate {
        infeasible.extend(stretches(t, &t_end, &rate, |x| x > m).into_iter().map(
            |(a, b, peak)| Stretch {
                input: name.to_string(),
                t_start: a,
                t_end: b,
                why: format!("needs a rate of {peak:.4} {per_s}, above max_rate {m}"),
            },
        ));
    }
    if let Some([lo, hi]) = spec.range {
        let out: Vec<f64> = v
            .iter()
            .map(|x| {
                if *x < lo {
                    lo - x
                } else if *x > hi {
                    x - hi
                } else {
                    0.0
                }
            })
            .collect();
        infeasible.extend(stretches(t, &t_end, &out, |x| x > 0.0).into_iter().map(
            |(a, b, peak)| Stretch {
                input: name.to_string(),
                t_start: a,
                t_end: b,
                why: format!(
                    "leaves its range [{lo}, {hi}] {} by up to {peak:.4}",
                    spec.unit
                ),
            },
        ));
    }
    let peak_rate = rate.iter().fold(0.0f64, |a, b| a.max(*b));
    let profile = InputProfile {
        name: name.to_string(),
        unit: spec.unit.clone(),
        kind: spec.kind,
        value: v.to_vec(),
        rate,
        max_rate: spec.max_rate,
        range: spec.range,
        peak_rate,
    };
    (profile, infeasible)
}

/// The constant body twist that moves by `dpose` (start body frame) in `dt`:
/// the SE(2) logarithm over dt.
fn se2_log(dpose: &[f64; 3], dt: f64) -> [f64; 3] {
    let [dx, dy, dth] = *dpose;
    let half = 0.5 * dth;
    // half / tan(half) -> 1 as dth -> 0 (series below 1e-4: error ~ dth^4/720)
    let a = if half.abs() < 1e-4 {
        1.0 - half * half / 3.0
    } else {
        half / half.tan()
    };
    [
        (a * dx + half * dy) / dt,
        (a * dy - half * dx) / dt,
        dth / dt,
    ]
}

/// Maximal runs of steps where `bad(x)` holds: (start time, end time, peak x).
fn stretches(t: &[f64], t_end: &f64, x: &[f64], bad: impl Fn(f64) -> bool) -> Vec<(f64, f64, f64)> {
    let mut out: Vec<(f64, f64, f64)> = Vec::new();
    let mut k = 0;
    while k < x.len() {
        if !bad(x[k]) {
            k += 1;
            continue;
        }
        let start = k;
        let mut peak = x[k];
        while k < x.len() && bad(x[k]) {
            peak = peak.max(x[k]);
            k += 1;
        }
        let end = t.get(k).copied().unwrap_or(*t_end);
        match out.last_mut() {
            Some(last) if t[start] - last.1 < MERGE_GAP_S => {
                last.1 = end;
                last.2 = last.2.max(peak);
            }
            _ => out.push((t[start], end, peak)),
        }
    }
    out
}

/// One spec's input profile along a path.
pub struct SpecProfile {
    pub spec: PathBuf,
    pub runner: Runner,
    pub profile: Profile,
}

/// Why a path cannot be profiled for the specs.
#[derive(Debug, thiserror::Error)]
pub enum InverseFilesError {
    #[error(transparent)]
    Path(LogError),
    #[error(transparent)]
    Spec(#[from] kinegen_model::error::SourceError),
    #[error(transparent)]
    Derivation(#[from] crate::model_on_log::derivation::DerivationFailed),
    #[error(transparent)]
    Model(#[from] crate::model_on_log::model::ModelError),
    #[error(transparent)]
    Profile(#[from] ProfileError),
}

/// `kinegen inverse` as one call: the planned path of `path` read, then
/// each spec of `specs` derived by `deriver` and profiled along it.
pub fn profile_files(
    path: &Path,
    specs: &[PathBuf],
    deriver: &dyn crate::model_on_log::derivation::Deriver,
) -> Result<(PlannedPath, Vec<SpecProfile>), InverseFilesError> {
    let planned = read_path(path).map_err(InverseFilesError::Path)?;
    let mut out = Vec::new();
    for spec in specs {
        let model = kinegen_model::spec::Model::load(spec)?;
        let runner = Runner::new(deriver.derive(&model, &spec.display().to_string())?, &[])?;
        let profile = profile(&runner, &planned)?;
        out.push(SpecProfile {
            spec: spec.clone(),
            runner,
            profile,
        });
    }
    Ok((planned, out))
}
