//! `kinegen verify`.
use kinegen_codegen::generate::spec_files;
use kinegen_model::spec::Model;
use kinegen_verify::checks::where_;
use kinegen_verify::{run_all, IrKernel};
use std::path::Path;
use std::process::ExitCode;

pub fn run(spec: Option<&Path>, samples: usize) -> ExitCode {
    let specs = match spec {
        Some(s) => vec![s.to_path_buf()],
        None => match spec_files(Path::new("spec")) {
            Ok(v) => v,
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(2);
            }
        },
    };
    let mut failed = false;
    for path in specs {
        let model = match Model::load(&path) {
            Ok(m) => m,
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(2);
            }
        };
        let ir = match kinegen_codegen::derive_model(&model) {
            Ok(ir) => ir,
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(2);
            }
        };
        println!("== {} ({}): the IR tapes `kinegen generate` emits, {samples} samples per property", ir.name, path.display());
        let report = run_all(&ir, &IrKernel, samples, 1);
        print!("{}", report.table());
        for f in report.failures() {
            failed = true;
            eprintln!("FAILED {}: {}", f.check, where_(f));
        }
    }
    if failed {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}

