//! `kinegen verify`.
use kinegen_model::autodiff;
use kinegen_model::files::spec_files;
use kinegen_model::spec::Model;
use kinegen_verify::checks::where_;
use kinegen_verify::crosscheck::autodiff_agrees;
use kinegen_verify::{run_all, IrKernel};
use std::path::Path;
use std::process::ExitCode;

/// Verify each spec's kernels; print a line per model (and every check's
/// table with `verbose`), each failure, and one verdict line last.
pub fn run(spec: Option<&Path>, samples: usize, verbose: bool) -> ExitCode {
    let specs = match spec {
        Some(s) => vec![s.to_path_buf()],
        None => match spec_files(Path::new("spec")) {
            Ok(v) => v,
            Err(e) => {
                eprintln!("error: spec: {e}");
                return ExitCode::from(2);
            }
        },
    };
    let (mut checks, mut failed_checks, mut models) = (0usize, 0usize, 0usize);
    for path in specs {
        // the committed IR when it is current, else derived (in a child process)
        let ir = match crate::ir_source::load(&path) {
            Ok(ir) => ir,
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(2);
            }
        };
        if verbose {
            println!(
                "== {} ({}): the IR tapes `kinegen generate` emits, {samples} samples per property",
                ir.name,
                path.display()
            );
        }
        let mut report = run_all(&ir, &IrKernel, samples, 1);
        // the analysis's own IR (automatic differentiation) against this one,
        // kernel by kernel, value and every Jacobian
        let vs_autodiff =
            match Model::load(&path).and_then(|m| autodiff::derive(&m, &Default::default())) {
                Ok(ad) => {
                    let against = autodiff_agrees(&ir, &ad, samples, 2);
                    let n = against.len();
                    report.findings.extend(against);
                    n
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    return ExitCode::from(2);
                }
            };
        let mut casadi = String::from("CasADi skipped");
        match casadi_reference(&path) {
            Ok(dir) => {
                match kinegen_verify::casadi::load(&dir, &ir.name) {
                    Some(fx) => {
                        let against = kinegen_verify::casadi::compare(&ir, &fx, &IrKernel);
                        casadi = format!("{} of them vs CasADi", against.len());
                        report.findings.extend(against);
                    }
                    None => {
                        eprintln!("CasADi check skipped: no reference was written")
                    }
                }
                let _ = std::fs::remove_dir_all(&dir);
            }
            Err(why) => {
                eprintln!("CasADi check skipped: {why}")
            }
        }
        if verbose {
            print!("{}", report.table());
        }
        let failures = report.failures();
        println!(
            "{:<16} {:>4} checks, {:>3} failed ({vs_autodiff} vs autodiff, {casadi}; {samples} samples each)",
            ir.name,
            report.findings.len(),
            failures.len()
        );
        for f in &failures {
            eprintln!("FAILED {}: {}", f.check, where_(f));
        }
        models += 1;
        checks += report.findings.len();
        failed_checks += failures.len();
    }
    let s = if models == 1 { "" } else { "s" };
    if failed_checks > 0 {
        println!("verify: FAILED: {failed_checks} of {checks} checks on {models} model{s} (the lines above name each; -v for every check)");
        ExitCode::from(1)
    } else {
        println!("verify: passed: all {checks} checks on {models} model{s} (-v for every check)");
        ExitCode::SUCCESS
    }
}

/// The CasADi reference script, built into the binary so the cross-check runs
/// from any directory (it needs python3 with the pinned casadi and numpy).
const REFERENCE_PY: &str = include_str!("../verify/casadi/reference.py");

/// Run the independent CasADi reference script for one spec into a temp dir
/// (removed again when the script fails).
fn casadi_reference(spec: &Path) -> Result<std::path::PathBuf, String> {
    let dir = std::env::temp_dir().join(format!("kinegen-casadi-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let script = dir.join("reference.py");
    std::fs::write(&script, REFERENCE_PY).map_err(|e| format!("{}: {e}", script.display()))?;
    let o = std::process::Command::new("python3")
        .arg(&script)
        .args(["--spec"])
        .arg(spec)
        .arg("--out")
        .arg(&dir)
        .output()
        .map_err(|e| format!("cannot run python3: {e}"))?;
    if !o.status.success() {
        let _ = std::fs::remove_dir_all(&dir);
        return Err(format!(
            "the CasADi script failed (it needs python3 with casadi 3.8.2 and numpy: pip install -r verify/casadi/requirements.txt in the kinegen checkout): {}",
            String::from_utf8_lossy(&o.stderr)
                .lines()
                .last()
                .unwrap_or("")
        ));
    }
    Ok(dir)
}
