//! `kinegen generate`.
use std::path::Path;
use std::process::ExitCode;

#[cfg(not(feature = "symbolic"))]
pub fn run(_spec_dir: &Path, _out: &Path, _check: bool) -> ExitCode {
    eprintln!("error: {}", crate::ir_source::NO_SYMBOLIC);
    ExitCode::from(2)
}

#[cfg(feature = "symbolic")]
pub fn run(spec_dir: &Path, out: &Path, check: bool) -> ExitCode {
    use kinegen_codegen::generate::{generate, Config, GenerateError};
    match generate(&Config::new(spec_dir, out, check)) {
        Err(e @ GenerateError::Spec(_)) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
        Ok(report) => {
            for (ir, took) in &report.models {
                let tree: usize = ir.functions().iter().map(|f| f.ops_tree).sum();
                let tape: usize = ir.functions().iter().map(|f| f.ops_tape()).sum();
                eprintln!(
                    "{:<14} {:>3} functions  {:>7.2} s  ops {:>6} -> {:>5} after CSE",
                    ir.name,
                    ir.functions().len(),
                    took.as_secs_f64(),
                    tree,
                    tape
                );
                if let Some(why) = &ir.no_inverse {
                    eprintln!(
                        "warning: {}: no inverse kinematics (`inverse` and `navigate` refuse it; everything else works): {why}",
                        ir.name
                    );
                }
            }
            eprintln!("total {:.2} s", report.total.as_secs_f64());
            if check {
                if report.stale.is_empty() {
                    eprintln!("generated code is up to date");
                    ExitCode::SUCCESS
                } else {
                    for p in &report.stale {
                        eprintln!("stale: {}", p.display());
                    }
                    eprintln!("run `kinegen generate` and commit the result");
                    ExitCode::from(1)
                }
            } else {
                eprintln!(
                    "wrote {} file(s) under {}",
                    report.stale.len(),
                    out.display()
                );
                ExitCode::SUCCESS
            }
        }
    }
}
