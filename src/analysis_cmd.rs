//! What the commands that read logs share: the common options (as the
//! library's `Sources`), the progress of reading a bag, and the text every
//! command prints (errors, landmark innovations, warnings).
use crate::output::Out;
use clap::Args;
use kinegen_analysis::logs::bag::is_bag;
use kinegen_analysis::model_on_log::innovations::InnovationStats;
use kinegen_analysis::model_on_log::load::Sources;
use kinegen_analysis::model_on_log::metrics::Errors;
use std::path::{Path, PathBuf};

#[derive(Args, Debug, Clone)]
pub struct Common {
    /// The model spec.
    #[arg(long)]
    pub spec: PathBuf,
    /// Measurement log: CSV with a header row, `t` in seconds and the spec's
    /// columns, or a ROS 2 bag (.mcap); repeat for several runs.
    #[arg(long, required = true)]
    pub data: Vec<PathBuf>,
    /// Topic mapping for ROS 2 bags given as --data (TOML: `stamps`, `[inputs]`,
    /// `[pose]`, `[gyro]`; see the guide's "Read a ROS 2 bag"). Without it: the bag's only
    /// JointState, PoseStamped/Odometry and Imu topics, joints named as the
    /// spec's input columns.
    #[arg(long, value_name = "FILE.toml")]
    pub topics: Option<PathBuf>,
    /// Runs scored but not fitted; repeatable.
    #[arg(long)]
    pub holdout: Vec<PathBuf>,
    /// Override a parameter's nominal value: NAME=VALUE; repeatable.
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// Range-bearing observations `t,id,range,bearing` (needs --landmarks); the
    /// k-th file belongs to the k-th --data log. Repeatable.
    #[arg(long)]
    pub observations: Vec<PathBuf>,
    /// Landmark map `id,x,y` for --observations.
    #[arg(long)]
    pub landmarks: Option<PathBuf>,
    /// Write a self-contained HTML report to DIR/index.html.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write one JSON document to PATH (`-`: stdout).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Split a log into runs only at gaps longer than this (seconds); shorter
    /// gaps are bridged: a command holds its value, a counter's difference
    /// spreads over the interval.
    #[arg(long, value_name = "SECONDS", default_value_t = kinegen_analysis::model_on_log::run::DEFAULT_MAX_GAP_S, value_parser = positive)]
    pub max_gap: f64,
    #[command(flatten)]
    pub catalogue: EffectDirs,
    /// Print every figure and the evidence behind the answer, not only the
    /// answer and its table (the JSON and the report always have them all).
    #[arg(short, long)]
    pub verbose: bool,
}

/// `--effects DIR`: the user's own effect catalogues (commands that use effects).
#[derive(Args, Debug, Clone, Default)]
pub struct EffectDirs {
    /// A directory of your own effect files (same format as the bundled
    /// catalogue, which is built in); repeatable. A file with a bundled effect's
    /// name replaces it.
    #[arg(long = "effects", value_name = "DIR")]
    pub effects: Vec<PathBuf>,
}

/// Progress bars stay quiet when stdout carries the JSON document.
pub fn quiet(c: &Common) -> bool {
    c.json.as_deref() == Some(std::path::Path::new("-"))
}

/// Say each of the warnings the logs' reading found.
pub fn say_warnings(out: &Out, warnings: &[String]) {
    for w in warnings {
        out.say(&format!("warning: {w}"));
    }
}

/// The logs' warnings as a command says them before its answer: whole with
/// `-v`, else each once in at most two lines of the width; returns how many
/// lines were said (the answer's 25 lines count them).
pub fn say_read_warnings(out: &Out, warnings: &[String], verbose: bool) -> usize {
    if verbose {
        say_warnings(out, warnings);
        return warnings.len();
    }
    crate::output::say_warnings_short(out, warnings, 2)
}

/// Exit 2 with a message naming the problem (where every command finds it).
pub use crate::output::bad;

/// A spinner that counts a bag's messages while it is read (a bag takes a
/// while; a CSV file needs none).
pub fn read_progress(quiet: bool) -> impl Fn(&Path) -> Box<dyn Fn(usize, usize)> {
    move |p: &Path| -> Box<dyn Fn(usize, usize)> {
        let bar = is_bag(p).then(|| {
            crate::progress::Progress::spinner(&format!("reading {}", p.display()), quiet)
        });
        Box::new(move |done: usize, per_mille: usize| {
            if let Some(b) = &bar {
                b.message(&format!("{done} messages, {}%", per_mille / 10));
            }
        })
    }
}

impl Common {
    /// Where the job's logs come from, as the library takes it.
    /// A log given twice (as --data, --holdout, or both) would be counted
    /// twice: refused, naming both places.
    pub fn check_repeated_logs(&self) -> Result<(), String> {
        let given: Vec<(&str, &PathBuf)> = (self.data.iter().map(|p| ("--data", p)))
            .chain(self.holdout.iter().map(|p| ("--holdout", p)))
            .collect();
        for (k, (opt, p)) in given.iter().enumerate() {
            let same = |q: &PathBuf| {
                q == *p
                    || std::fs::canonicalize(q)
                        .ok()
                        .is_some_and(|c| std::fs::canonicalize(p).is_ok_and(|d| c == d))
            };
            if let Some((first, _)) = given[..k].iter().find(|(_, q)| same(q)) {
                return Err(format!(
                    "{opt} {}: already given as {first}; give each log once",
                    p.display()
                ));
            }
        }
        Ok(())
    }

    pub fn sources(&self) -> Sources {
        Sources {
            spec: self.spec.clone(),
            data: self.data.clone(),
            holdout: self.holdout.clone(),
            sets: self.set.clone(),
            topics: self.topics.clone(),
            observations: self.observations.clone(),
            landmarks: self.landmarks.clone(),
            max_gap: self.max_gap,
            truth_scores_only: false,
        }
    }
}

/// The landmark innovations' figures, one line.
pub fn fmt_landmarks(s: &InnovationStats) -> String {
    format!("landmark innovations: {}", fmt_sightings(s))
}

/// The sightings seen from the ground truth, one line: the sensor's own
/// error (the innovations along the dead-reckoned track add its drift).
pub fn fmt_landmarks_from_truth(s: &InnovationStats) -> String {
    format!(
        "sightings seen from the ground truth (the sensor's own error): {}",
        fmt_sightings(s)
    )
}

fn fmt_sightings(s: &InnovationStats) -> String {
    format!(
        "{} observations of {} landmarks; range RMSE {:.4} m (bias {:+.4}, robust sd {:.4}), bearing RMSE {:.4} rad (bias {:+.4}, robust sd {:.4}){}",
        s.observations,
        s.landmarks,
        s.range_rmse_m,
        s.range_bias_m,
        s.range_robust_sd_m,
        s.bearing_rmse_rad,
        s.bearing_bias_rad,
        s.bearing_robust_sd_rad,
        s.worst_landmark.as_ref().map(|(id, v)| format!("; worst landmark `{id}` ({v:.4} m)")).unwrap_or_default()
    )
}

/// A run's (or runs') error figures, as every command says them.
pub fn fmt_errors(e: &Errors) -> String {
    let mut s = format!(
        "position RMSE {:.4} m, heading RMSE {:.4} rad; final error {:.4} m / {:.4} rad; worst {:.4} m at {:.1} s",
        e.rmse, e.heading_rmse_rad, e.final_position_error_m, e.final_heading_error_rad, e.max_position_error_m, e.max_error_at_s
    );
    if let Some(d) = e.rpe_per_m {
        s += &format!(
            "\n  drift {:.2}% of distance (relative pose error over 1 m)",
            100.0 * d
        );
    }
    if let Some(d) = e.rpe_5s_m {
        s += &format!(", {:.4} m per 5 s", d);
    }
    if let Some(g) = e.gyro_rmse_rad_s {
        s += &format!("\n  gyro yaw-rate residual RMSE {:.5} rad/s", g);
    }
    s
}

/// A finite number above zero (clap reports the option on error).
pub fn positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a finite number above 0")),
    }
}

/// A finite number, zero or above.
pub fn non_negative(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a finite number of 0 or more")),
    }
}
