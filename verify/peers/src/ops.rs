//! How many operations each side's generated code spends on a row, as each
//! tool counts them in the code it writes: kinegen's doc comment ("N
//! arithmetic operations"), wrenfold's ("// total: N", one count for its
//! three builds), SymForce's ("// Total ops: N"). CasADi writes none: its
//! count here is the instructions of its function that compute something
//! (an assignment with an operator or a call; not the reads of arguments
//! and constants). The tools do not count alike (wrenfold counts branches
//! and negations, kinegen only arithmetic), so the counts say how much code
//! each formulation takes within a tool more than across tools.
//!
//! Read from the committed generated files: the counts are what was
//! compiled, with no tool needed at bench time.
use crate::Row;
use std::path::Path;

fn read(relative: &str) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(root.join(relative)).unwrap_or_default()
}

/// The first number after `marker` in `text`, looking from `from`.
fn number_after(text: &str, from: usize, marker: &str) -> Option<usize> {
    let at = from + text[from..].find(marker)? + marker.len();
    let digits: String = (text[at..].trim_start().chars())
        .take_while(char::is_ascii_digit)
        .collect();
    digits.parse().ok()
}

/// kinegen's generated function for each row, in its model's file.
fn kinegen_function(row: Row) -> (&'static str, &'static str) {
    match row.matched() {
        Row::DdStepJacXJacP => ("diff_drive", "step_exact_with_jac_p"),
        Row::UcLandmarkJacX => ("unicycle_ekf", "obs_landmark_linearized"),
        Row::OcTwist => ("omni_caster", "twist"),
        Row::OcStepJacP => ("omni_caster", "step_exact_with_jac_p"),
        Row::DdStep => ("diff_drive", "step_exact"),
        Row::DdJacX => ("diff_drive", "step_exact_jac_x"),
        Row::DdJacP => ("diff_drive", "step_exact_jac_p"),
        Row::UcLandmark => ("unicycle_ekf", "obs_landmark"),
        Row::UcJacX => ("unicycle_ekf", "obs_landmark_jac_x"),
        Row::OcStep => ("omni_caster", "step_exact"),
        _ => ("omni_caster", "step_exact_jac_p"),
    }
}

/// kinegen's count: the doc comment just before its function (the flat
/// form of a fused kernel, which holds the computation).
fn kinegen(row: Row) -> Option<usize> {
    let (model, f) = kinegen_function(row);
    let text = read(&format!("../../generated/src/{model}.rs"));
    let at =
        (text.find(&format!("pub fn {f}_flat("))).or_else(|| text.find(&format!("pub fn {f}(")))?;
    let doc = text[..at].rfind("/**")?;
    // "... N arithmetic operations (M before ...)": the number before it
    let line = doc + text[doc..at].find(" arithmetic operations")?;
    let start = text[..line].rfind(|c: char| !c.is_ascii_digit())? + 1;
    text[start..line].parse().ok()
}

/// wrenfold's count in its Rust file (the same code in every build).
fn wrenfold(row: Row) -> Option<usize> {
    let text = read("wrenfold/kernels.rs");
    let at = text.find(&format!("pub fn {}<", row.name()))?;
    number_after(&text, at, "// total:")
}

/// SymForce's count, after its function's signature.
fn symforce(row: Row) -> Option<usize> {
    let camel: String = (row.name().split('_'))
        .map(|w| {
            let mut c = w.chars();
            c.next().map_or(String::new(), |f| {
                f.to_ascii_uppercase().to_string() + c.as_str()
            })
        })
        .collect();
    let text = read("symforce/kernels.h");
    let at = text.find(&format!("void {camel}("))?;
    number_after(&text, at, "// Total ops:")
}

/// CasADi's instructions that compute, in the function its exported name
/// calls.
fn casadi(row: Row) -> Option<usize> {
    let text = read("casadi/casadi_kernels.c");
    let export = text.find(&format!("CASADI_SYMBOL_EXPORT int {}(", row.name()))?;
    let call = export + text[export..].find("return casadi_f")? + "return ".len();
    let name: String = (text[call..].chars())
        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
        .collect();
    let body = text.find(&format!("static int {name}("))?;
    let end = body + text[body..].find("\n}")?;
    let computes = |line: &str| {
        let Some((lhs, rhs)) = line.trim().split_once('=') else {
            return false;
        };
        let is_work = lhs.starts_with('a') && lhs[1..].chars().all(|c| c.is_ascii_digit());
        let reads = rhs.starts_with("arg[") || rhs.trim_end_matches(';').parse::<f64>().is_ok();
        is_work && !reads
    };
    Some(text[body..end].lines().filter(|l| computes(l)).count())
}

/// The count of `side` (its name in [`crate::sides`]) on `row`.
pub fn operations(row: Row, side: &str) -> Option<usize> {
    match side {
        s if s.starts_with("kinegen") => kinegen(row),
        s if s.starts_with("wrenfold") => wrenfold(row),
        "SymForce C++" => symforce(row),
        "CasADi C" => casadi(row),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every side's count is found for every row (the generated files and
    /// their comments are where this module looks), and the fused rows
    /// cost more than the step alone.
    #[test]
    fn every_side_has_a_count_for_every_row() {
        for row in Row::ALL {
            for side in [
                "kinegen no_std",
                "CasADi C",
                "wrenfold Rust",
                "SymForce C++",
            ] {
                let n = operations(row, side);
                assert!(n.is_some_and(|n| n > 0), "{side} {row:?}: {n:?}");
            }
        }
        for side in [
            "kinegen no_std",
            "CasADi C",
            "wrenfold Rust",
            "SymForce C++",
        ] {
            assert!(
                operations(Row::DdStepJacXJacP, side) > operations(Row::DdStep, side),
                "{side}"
            );
        }
    }
}
