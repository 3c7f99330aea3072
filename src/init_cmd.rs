//! `kinegen init`: a spec (and a `--topics` mapping for bags) from the robot's
//! URDF and its ros2_control controller configuration. Parses, calls
//! `kinegen_init::from_files` once, writes both files (each whole or not at
//! all) and says what it found.
use crate::output::{bad, check_writable};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

/// Write a spec from a robot description.
///
/// Example: kinegen init --urdf robot.urdf --controller controllers.yaml --out robot.toml --topics-out topics.toml
#[derive(Args)]
pub struct InitArgs {
    /// The robot's URDF (a `.xacro` is expanded with the `xacro` tool)
    #[arg(long)]
    pub urdf: PathBuf,
    /// Its ros2_control controller configuration (diff_drive_controller,
    /// tricycle_controller, ackermann_steering_controller, mecanum_drive_controller)
    #[arg(long)]
    pub controller: Option<PathBuf>,
    /// The robot's body frame (default: the controller's base_frame_id, else the URDF's root link)
    #[arg(long)]
    pub base_link: Option<String>,
    /// The spec to write
    #[arg(long)]
    pub out: PathBuf,
    /// The --topics mapping for the robot's bags
    #[arg(long)]
    pub topics_out: Option<PathBuf>,
    /// Write a spec of the velocity commands (cmd_vel: forward speed and
    /// turn rate, and sideways speed for a base that moves sideways, each
    /// with a gain to calibrate) rather than of the wheel joints, for bags
    /// that logged only what the controller was sent
    #[arg(long)]
    pub commands: bool,
    /// Also print every wheel found and every note in full
    #[arg(short, long)]
    pub verbose: bool,
}

pub fn run(a: &InitArgs) -> ExitCode {
    if let Err(e) = check_writable("--out", &a.out).and_then(|()| {
        a.topics_out
            .as_deref()
            .map_or(Ok(()), |t| check_writable("--topics-out", t))
    }) {
        return bad(e);
    }
    if a.topics_out.as_ref() == Some(&a.out) {
        return bad("--topics-out: the same file as --out; give the mapping its own file");
    }
    let options = kinegen_init::Options {
        base_link: a.base_link.clone(),
        spec_path: Some(a.out.clone()),
        commands: a.commands,
    };
    let made = match kinegen_init::from_files(&a.urdf, a.controller.as_deref(), &options) {
        Ok(m) => m,
        Err(e) => return bad(e),
    };
    // both written or neither: the mapping first, removed if the spec fails
    if let Some(t) = &a.topics_out {
        if let Err(e) = kinegen_model::files::write_atomic(t, &made.topics) {
            return bad(e);
        }
    }
    if let Err(e) = kinegen_model::files::write_atomic(&a.out, &made.spec) {
        if let Some(t) = &a.topics_out {
            let _ = std::fs::remove_file(t);
        }
        return bad(e);
    }
    println!(
        "{}: {} with {} wheel joints{}, base link `{}` -> {}{}",
        made.name,
        made.class.describe(),
        made.wheels.len(),
        if a.commands {
            ", driven by its velocity commands"
        } else {
            ""
        },
        made.base_link,
        a.out.display(),
        a.topics_out
            .as_ref()
            .map_or(String::new(), |t| format!(" (topics: {})", t.display()))
    );
    if a.verbose {
        for (joint, role) in &made.wheels {
            println!("  {joint}: {role}");
        }
    }
    let shown = if a.verbose {
        made.notes.len()
    } else {
        made.notes.len().min(3)
    };
    for n in &made.notes[..shown] {
        println!("note: {}", crate::output::cut(n));
    }
    if shown < made.notes.len() {
        println!("({} more notes: -v)", made.notes.len() - shown);
    }
    println!(
        "next: kinegen fit --spec {} --data LOG.csv",
        a.out.display()
    );
    ExitCode::SUCCESS
}
