//! `kinegen simulate` (its robot from kinegen_analysis::applications::hidden::with_hidden)
//! and `kinegen add-effect`.
use crate::analysis_cmd::bad;
use kinegen_analysis::applications::simulate::{SimOptions, Trajectory};
use kinegen_analysis::applications::simulate_request::{simulate_files, SimulateRequest};
use kinegen_analysis::effects::{add_effect, AddEffect};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(clap::Args, Debug)]
pub struct SimArgs {
    #[arg(long)]
    pub spec: PathBuf,
    /// Hidden effect from the catalogue: NAME=VALUE (its first parameter) or NAME.PARAM=VALUE; repeatable.
    #[arg(long)]
    pub effect: Vec<String>,
    /// True parameter value NAME=VALUE (default: nominal); repeatable.
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// square (UMBMark, both directions), figure8, random, spin, back-and-forth (1.5 m along a line and back), beacons (a tour of the --landmarks in order, stopping at the last).
    #[arg(long, default_value = "square")]
    pub trajectory: String,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Repetitions of the trajectory.
    #[arg(long, default_value_t = 1)]
    pub laps: usize,
    #[arg(long)]
    pub out: PathBuf,
    /// Landmark map `id,x,y` to observe (with --observations).
    #[arg(long)]
    pub landmarks: Option<PathBuf>,
    /// Write range-bearing observations `t,id,range,bearing` of the --landmarks
    /// in range (--landmark-range, at --landmark-hz, the noise of the spec's
    /// `landmark` observation) here.
    #[arg(long)]
    pub observations: Option<PathBuf>,
    /// Observations per second of each landmark in range.
    #[arg(long, default_value_t = 5.0, value_parser = crate::analysis_cmd::positive)]
    pub landmark_hz: f64,
    /// Farthest landmark observed, m.
    #[arg(long, default_value_t = 10.0, value_parser = crate::analysis_cmd::positive)]
    pub landmark_range: f64,
    /// Cruise speed of the beacons tour, m/s (the EKF paper's tour: 5).
    #[arg(long, default_value_t = 0.5, value_parser = crate::analysis_cmd::positive)]
    pub speed: f64,
    #[command(flatten)]
    pub catalogue: crate::analysis_cmd::EffectDirs,
}

pub fn run_simulate(a: SimArgs) -> ExitCode {
    let go = || -> Result<String, String> {
        let trajectory: Trajectory = a.trajectory.parse().map_err(|e| format!("{e}"))?;
        if a.landmarks.is_some() != a.observations.is_some() {
            return Err("--landmarks MAP.csv and --observations OBS.csv go together (the map to observe, the file to write)".into());
        }
        let request = SimulateRequest {
            spec: &a.spec,
            effects: &a.effect,
            sets: &a.set,
            effect_dirs: &a.catalogue.effects,
            landmarks: a.landmarks.as_deref(),
            options: SimOptions {
                trajectory,
                seed: a.seed,
                laps: a.laps,
                landmark_hz: a.landmark_hz,
                landmark_range: a.landmark_range,
                cruise_speed: a.speed,
                ..SimOptions::default()
            },
        };
        let sim = simulate_files(&request, crate::ir_source::analysis_deriver())
            .map_err(|e| e.to_string())?;
        kinegen_model::files::write_atomic(&a.out, &sim.csv()).map_err(|e| e.to_string())?;
        let rows = &sim.log.rows;
        let mut msg = format!(
            "wrote {} rows ({:.1} s) to {}",
            rows.len(),
            rows.last().map_or(0.0, |r| r[0]),
            a.out.display()
        );
        if let Some(path) = &a.observations {
            kinegen_model::files::write_atomic(path, &sim.observations_csv())
                .map_err(|e| e.to_string())?;
            msg += &format!(
                "\nwrote {} landmark observations to {}",
                sim.log.observations.len(),
                path.display()
            );
        }
        Ok(msg)
    };
    match go() {
        Ok(msg) => {
            eprintln!("{msg}");
            ExitCode::SUCCESS
        }
        Err(e) => bad(e),
    }
}

pub fn run_add_effect(
    spec: &Path,
    effect: &str,
    values: &[String],
    out: &Path,
    extra: &[PathBuf],
) -> ExitCode {
    let go = || -> Result<String, String> {
        let values = kinegen_analysis::model_on_log::model::parse_pairs("--value", values)
            .map_err(|e| e.to_string())?;
        let request = AddEffect {
            spec,
            effect,
            values: &values,
            effect_dirs: extra,
        };
        let added = add_effect(&request).map_err(|e| e.to_string())?;
        kinegen_model::files::write_atomic(out, &added.source).map_err(|e| e.to_string())?;
        // the change as a diff, each line within the terminal's width (the
        // whole of it is in the file written)
        let width = crate::output::WIDTH;
        let lines: Vec<String> = added.change.lines().map(crate::output::cut).collect();
        let whole = if added.change.lines().any(|l| l.chars().count() > width) {
            format!(
                "\n(lines cut at {width} columns: {} has them whole)",
                out.display()
            )
        } else {
            String::new()
        };
        Ok(format!(
            "added `{effect}` to {} -> {}:\n{}{whole}",
            spec.display(),
            out.display(),
            lines.join("\n")
        ))
    };
    match go() {
        Ok(msg) => {
            println!("{msg}");
            ExitCode::SUCCESS
        }
        Err(e) => bad(e),
    }
}
