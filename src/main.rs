//! `kinegen`: declare a wheeled-robot model once, generate its kernels, and confront
//! it with measurements. See `kinegen --help` and the README.
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

mod analysis_cmd;
mod batch_cmd;
mod bench_diagnose_cmd;
mod bench_real_cmd;
mod compare_cmd;
mod compare_text;
mod diagnose_cmd;
mod diagnose_text;
mod effects_cmd;
mod export;
mod fit_cmd;
mod fit_text;
mod generate_cmd;
mod init_cmd;
mod inverse_cmd;
mod ir_source;
mod localize_cmd;
mod localize_text;
mod navigate_cmd;
mod output;
mod progress;
mod report;
mod signals;
mod verify_cmd;

#[derive(Parser)]
#[command(
    name = "kinegen",
    version,
    about = "Kinematic model generator and calibration toolkit for wheeled mobile robots"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Derive every spec symbolically and write the generated crate.
    ///
    /// Example: kinegen generate --spec-dir spec --out generated --check
    Generate {
        /// Directory with the model specs (*.toml).
        #[arg(long, default_value = "spec")]
        spec_dir: PathBuf,
        /// The generated crate's directory.
        #[arg(long, default_value = "generated")]
        out: PathBuf,
        /// Write nothing; exit 1 if any generated file is stale.
        #[arg(long)]
        check: bool,
    },
    /// Verify a spec's kernels: Jacobians against finite differences, exact vs
    /// Euler integration, inverse-kinematics round trips, singular limits, SE(2)
    /// equivariance; and the compiled kernels against the IR when the spec is one
    /// of the generated crate's (and not changed since).
    ///
    /// Example: kinegen verify --spec spec/tricycle.toml --samples 500
    Verify {
        /// The spec to verify (default: every spec in spec/).
        #[arg(long)]
        spec: Option<PathBuf>,
        /// Samples per property (at least 1: a check on no samples proves nothing).
        #[arg(long, default_value_t = 200, value_parser = at_least_one)]
        samples: usize,
        /// Print every check's table (function, check, samples, error, status),
        /// not only each model's line and the verdict.
        #[arg(short, long)]
        verbose: bool,
    },
    /// Run the model against logs with nominal parameters: how large the error is,
    /// and where and when it grows.
    ///
    /// Example: kinegen compare --spec spec/diff_drive.toml --data ../shared/real/optiodom-diff-square/run-01.csv --report report
    Compare(analysis_cmd::Common),
    /// EKF localisation with mapped landmarks on the model's
    /// step and observation Jacobians: the track with its covariance, gating of
    /// outliers, NIS and NEES against their chi-square bounds. The noise is
    /// estimated from the sightings unless given, and so is the spec's input
    /// delay when it declares one (`add-effect --effect input_delay`; `--set`
    /// fixes it).
    ///
    /// Example: kinegen localize --spec spec/unicycle_ekf.toml --data run.csv --observations obs.csv --landmarks map.csv --track track.csv
    Localize {
        #[command(flatten)]
        common: analysis_cmd::Common,
        #[command(flatten)]
        options: localize_cmd::LocalizeArgs,
    },
    /// Integrated inverse kinematics along a planned path:
    /// each robot's input profile, checked against its inputs' `max_rate` and
    /// `range`; exit 1 when a robot cannot drive the path as planned.
    ///
    /// Example: kinegen inverse --spec spec/diff_drive.toml --spec spec/tricycle.toml --spec spec/omni3.toml --path tour.csv --report report/inverse
    Inverse(inverse_cmd::InverseArgs),
    /// Cellular-automaton navigation on a grid, driven on odometry
    /// by a real robot with hidden geometry errors: collisions, safety-zone
    /// intrusions and the final distance to the goal, before and after
    /// calibrating the odometry (--calibrate umbmark|lm).
    ///
    /// Example: kinegen navigate --spec data/seed004/epuck.toml --grid data/seed004/arena.txt --set r_l=0.0201 --set b=0.056 --calibrate umbmark --report report/navigate
    Navigate(navigate_cmd::NavigateArgs),
    /// Recovery benchmark of the diagnosis: every spec x applicable effect x 3
    /// magnitudes x 2 noise levels x seeds simulated and diagnosed, plus clean
    /// and two-effect logs: top-1, full-chain and false-alarm rates per model;
    /// with --beyond, effects outside the catalogue too, and how often the
    /// diagnosis's proposal recovers them.
    ///
    /// Example: kinegen bench-diagnose --seeds 5 --beyond tests/proposal_effects --json bench.json
    BenchDiagnose(bench_diagnose_cmd::BenchDiagnoseArgs),
    /// Calibration judged on real runs it was not fitted on: each session of
    /// the OptiOdom study calibrated by kinegen, scored with the nominal values
    /// and every published method's parameters on the robot's other sessions
    /// (median final position error and whole-run RMSE) and on its own runs.
    ///
    /// Example: kinegen bench-real ../shared/real/optiodom-dev --json bench-real.json
    BenchReal(bench_real_cmd::BenchRealArgs),
    /// Calibrate the spec's free parameters (bounded Levenberg-Marquardt on the
    /// generated parameter Jacobians): before/after error, estimates with standard
    /// deviations, correlations and identifiability warnings.
    ///
    /// Example: kinegen fit --spec spec/diff_drive.toml --data run-01.csv --data run-04.csv --holdout run-02.csv --json -
    Fit {
        #[command(flatten)]
        common: analysis_cmd::Common,
        #[command(flatten)]
        options: fit_cmd::FitArgs,
    },
    /// Calibrate, then test each applicable effect of the catalogue (built in, plus --effects DIR),
    /// rank them, say which effect is missing (or that none is, or that unexplained
    /// structure remains) and print the spec change that adds the winner.
    ///
    /// Example: kinegen diagnose --spec spec/diff_drive.toml --data data/mystery_robot.csv --report report
    Diagnose(analysis_cmd::Common),
    /// Synthetic logs in the real-log format, optionally with hidden effects.
    ///
    /// Example: kinegen simulate --spec spec/diff_drive.toml --effect lateral_slip=0.05 --set b=0.21 --trajectory square --seed 3 --out sim.csv
    ///
    /// With landmarks: kinegen simulate --spec spec/unicycle_ekf.toml --trajectory random --landmarks map.csv --observations obs.csv --out sim.csv
    Simulate(effects_cmd::SimArgs),
    /// Write a copy of a spec with an effect from the catalogue added.
    ///
    /// Example: kinegen add-effect --spec spec/diff_drive.toml --effect lateral_slip --value k_slip=0.05 --out my_robot.toml
    AddEffect {
        #[arg(long)]
        spec: PathBuf,
        #[arg(long)]
        effect: String,
        /// Starting value PARAM=VALUE of an effect parameter; repeatable.
        #[arg(long)]
        value: Vec<String>,
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        catalogue: analysis_cmd::EffectDirs,
    },
    /// Run many jobs (a fleet's nightly fits and diagnoses): one JSON line a
    /// job in, one result line a job out, at most --jobs at once, each job a
    /// process of its own; rerun after an interruption, it skips the jobs
    /// whose results are already there. Exit 1 when a job failed.
    ///
    /// Example: kinegen batch jobs.jsonl --out results.jsonl --jobs 2
    /// with jobs.jsonl lines like {"id": "r17-fit", "args": ["fit", "--spec", "robot.toml", "--data", "r17.csv"]}
    Batch(batch_cmd::BatchArgs),
    /// Write a spec (and a --topics mapping for bags) from a robot's URDF and its
    /// ros2_control controller configuration: wheels, radii, track, wheelbase,
    /// steering joints, casters and the kinematic class, every nominal value the
    /// description's own number.
    ///
    /// Example: kinegen init --urdf robot.urdf --controller controllers.yaml --out robot.toml --topics-out topics.toml
    Init(init_cmd::InitArgs),
    /// Derive one spec's IR into a file (used internally by the analysis commands).
    #[command(hide = true)]
    Derive {
        /// The spec file, or `-` for its text on stdin.
        #[arg(long)]
        spec: PathBuf,
        /// What messages call a spec read from stdin.
        #[arg(long)]
        label: Option<String>,
        #[arg(long)]
        ir_out: PathBuf,
    },
}

fn main() -> ExitCode {
    signals::install();
    let cli = Cli::parse();
    match cli.command {
        Command::Generate {
            spec_dir,
            out,
            check,
        } => generate_cmd::run(&spec_dir, &out, check),
        Command::Verify {
            spec,
            samples,
            verbose,
        } => verify_cmd::run(spec.as_deref(), samples, verbose),
        Command::Compare(c) => compare_cmd::compare(c),
        Command::Localize { common, options } => localize_cmd::run(common, &options),
        Command::Inverse(a) => inverse_cmd::run(&a),
        Command::Navigate(a) => navigate_cmd::run(&a),
        Command::BenchDiagnose(a) => bench_diagnose_cmd::run(&a),
        Command::BenchReal(a) => bench_real_cmd::run(&a),
        Command::Diagnose(c) => diagnose_cmd::run(c),
        Command::Fit { common, options } => fit_cmd::run_fit(common, &options),
        Command::Simulate(a) => effects_cmd::run_simulate(a),
        Command::AddEffect {
            spec,
            effect,
            value,
            out,
            catalogue,
        } => effects_cmd::run_add_effect(&spec, &effect, &value, &out, &catalogue.effects),
        Command::Batch(a) => batch_cmd::run(&a),
        Command::Init(a) => init_cmd::run(&a),
        Command::Derive {
            spec,
            label,
            ir_out,
        } => match ir_source::derive_to(&spec, label.as_deref(), &ir_out) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => analysis_cmd::bad(e),
        },
    }
}

/// A whole number of 1 or more.
fn at_least_one(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!("`{s}` is not a whole number of 1 or more")),
    }
}
