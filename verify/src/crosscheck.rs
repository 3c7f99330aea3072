//! The two ways kinegen differentiates a spec held to each other: the
//! symbolic IR (symbolica, simplified, what `kinegen generate` emits) and the
//! automatically differentiated IR (`kinegen_model::autodiff`, what the
//! analysis runs on). Every kernel they share, value and every Jacobian, at
//! random points of the model's domain and at the exact step's singular
//! limit (omega*dt at 0, a hair from 0, either side of the series switch).
//! A wrong derivative rule in either path shows up as a disagreement.
use crate::checks::Finding;
use crate::sample::{at_turn, Sampler};
use kinegen_model::ir::{Function, Kernel as KernelId, ModelIr, StepForm};

/// How far apart the two may be, relative to an entry (or to 1e-6 of the
/// matrix's largest magnitude, whichever is larger): both compute the same
/// mathematics by different formulas, so they differ by rounding, which
/// cancellation in a chain-rule sum can amplify by a few orders (an entry
/// that is 0 in exact arithmetic comes out as 1e-17 on one side and -3e-16
/// on the other); a wrong rule is off by O(1) of the entry.
pub const TOLERANCE: f64 = 1e-8;
const MATRIX_FLOOR: f64 = 1e-6;

/// One finding per kernel both IRs have (the autodiff IR has no inverse
/// kinematics: those stay the symbolic stage's).
pub fn autodiff_agrees(
    symbolic: &ModelIr,
    autodiff: &ModelIr,
    n: usize,
    seed: u64,
) -> Vec<Finding> {
    let mut sampler = Sampler::new(symbolic, seed);
    let mut out = Vec::new();
    for f in symbolic.functions() {
        let Some(g) = autodiff.kernel(f.kernel) else {
            continue;
        };
        let mut fd = Finding::blank(symbolic, f, "autodiff vs symbolic");
        if g.args != f.args || (g.rows, g.cols) != (f.rows, f.cols) {
            // a different signature: nothing can be compared, which fails
            fd.note(f64::INFINITY, f64::INFINITY, None, &[], f);
            out.push(fd);
            continue;
        }
        let singular = matches!(f.kernel, KernelId::Step(StepForm::Exact, _));
        for _ in 0..n {
            let args = sampler.args(f);
            compare_at(&mut fd, f, g, &args);
            if singular {
                let switch = f.series_switches().first().copied().unwrap_or(0.05);
                for s in [
                    0.0,
                    1e-9,
                    -1e-7,
                    switch * (1.0 - 1e-9),
                    switch * (1.0 + 1e-9),
                ] {
                    let twist = sampler.twist();
                    if let Some(at) = at_turn(&mut sampler, f, &args, &twist, s) {
                        compare_at(&mut fd, f, g, &at);
                    }
                }
            }
            fd.samples += 1;
        }
        out.push(fd);
    }
    out
}

fn compare_at(fd: &mut Finding, f: &Function, g: &Function, args: &[Vec<f64>]) {
    let refs: Vec<&[f64]> = args.iter().map(|a| &a[..]).collect();
    let (a, b) = (f.interpret(&refs), g.interpret(&refs));
    let matrix_max = a.iter().chain(&b).fold(0.0f64, |m, v| m.max(v.abs()));
    for (i, (p, q)) in a.iter().zip(&b).enumerate() {
        let (r, c) = (i / f.cols, i % f.cols);
        let scale = p
            .abs()
            .max(q.abs())
            .max(MATRIX_FLOOR * matrix_max)
            .max(1e-300);
        let err = if p == q { 0.0 } else { (p - q).abs() / scale };
        let name = format!(
            "{} / {}",
            f.row_names.get(r).map_or("", String::as_str),
            f.col_names.get(c).map_or("", String::as_str)
        );
        fd.note(err, err / TOLERANCE, Some((r, c, name)), args, f);
    }
}
