//! Comparison with the CasADi reference fixtures (`verify/casadi/fixtures`), made by
//! `verify/casadi/reference.py` from the specs alone.
use crate::checks::Finding;
use crate::kernel::Kernel;
use kinegen_model::ir::ModelIr;
use serde::Deserialize;
use std::path::{Path, PathBuf};

#[derive(Deserialize)]
pub struct Fixture {
    pub model: String,
    pub points: Vec<Point>,
}

#[derive(Deserialize)]
pub struct Point {
    pub function: String,
    pub args: std::collections::BTreeMap<String, Vec<f64>>,
    pub out: Vec<f64>,
}

pub fn fixture_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("casadi/fixtures")
}

pub fn load(dir: &Path, model: &str) -> Option<Fixture> {
    let text = std::fs::read_to_string(dir.join(format!("{model}.json"))).ok()?;
    serde_json::from_str(&text).ok()
}

/// One finding per function: worst |kernel - casadi| / max(|casadi|, floor),
/// tolerance 1e-10. The floor is where rounding, not the formula, decides:
/// - a vector output: 1e-12 times its largest magnitude;
/// - a Jacobian entry: 1e-4 times the largest magnitude in its column. The
///   pose's rows mix through the heading's rotation, so an entry is a sum of
///   terms of its column's size; where they cancel (skid4 with k_slip 0.1
///   has d y / d fr = 2.8e-12 in a column of 6.2e-6), two correct
///   evaluations in different orders differ by rounding of the terms, about
///   eps times the column. The floor allows 1e-14 of the column (some 45
///   ulps) and no more, so a wrong entry still fails.
pub fn compare(ir: &ModelIr, fx: &Fixture, k: &dyn Kernel) -> Vec<Finding> {
    const TOL: f64 = 1e-10;
    let mut out: Vec<Finding> = Vec::new();
    for p in &fx.points {
        // the fixture names kernels as the emitted code does
        let Some(f) = ir.functions().iter().find(|f| f.name == p.function) else {
            continue;
        };
        let args: Vec<Vec<f64>> = f
            .args
            .iter()
            .map(|a| p.args.get(a.ident()).cloned().unwrap_or_default())
            .collect();
        let refs: Vec<&[f64]> = args.iter().map(|a| &a[..]).collect();
        let mut got = vec![f64::NAN; f.rows * f.cols];
        if !k.eval(f, &refs, &mut got) {
            got.fill(f64::NAN);
        }
        let scale = p.out.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let column_scale =
            |c: usize| (0..f.rows).fold(0.0f64, |m, r| m.max(p.out[r * f.cols + c].abs()));
        let idx = match out.iter().position(|x| x.function == f.name) {
            Some(i) => i,
            None => {
                out.push(Finding::blank(ir, f, "vs CasADi"));
                out.len() - 1
            }
        };
        let fd = &mut out[idx];
        for (i, (g, r)) in got.iter().zip(&p.out).enumerate() {
            let err = if g == r {
                0.0
            } else {
                let floor = if f.is_matrix() {
                    1e-4 * column_scale(i % f.cols)
                } else {
                    1e-12 * scale
                };
                (g - r).abs() / r.abs().max(floor).max(1e-300)
            };
            let name = if f.is_matrix() {
                format!(
                    "d {} / d {}",
                    f.row_names[i / f.cols],
                    f.col_names[i % f.cols]
                )
            } else {
                f.row_names[i].clone()
            };
            fd.note(
                err,
                err / TOL,
                Some((i / f.cols, i % f.cols, name)),
                &args,
                f,
            );
        }
        fd.samples += 1;
    }
    out
}
