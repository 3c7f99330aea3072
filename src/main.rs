//! `kinegen`: declare a wheeled-robot model once, generate its kernels, and confront
//! it with measurements. See `kinegen --help` and the README.
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

mod generate_cmd;
mod verify_cmd;

#[derive(Parser)]
#[command(name = "kinegen", version, about = "Kinematic model generator and calibration toolkit for wheeled mobile robots")]
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
        /// Samples per property.
        #[arg(long, default_value_t = 200)]
        samples: usize,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Generate { spec_dir, out, check } => generate_cmd::run(&spec_dir, &out, check),
        Command::Verify { spec, samples } => verify_cmd::run(spec.as_deref(), samples),
    }
}
