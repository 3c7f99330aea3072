//! Several derived functions of one model as one tape, sharing their work.
//!
//! A calibration step needs the pose, the twist and both Jacobians of the same
//! step: four tapes that each recompute the twist, the sines and cosines and (for
//! least-squares kinematics) the 3x3 pseudo-inverse. Fused, every operation the
//! parts have in common is computed once (hash-consing over the merged tape), the
//! way SymForce's `with_jacobians` functions share it. Each part's outputs are
//! the same values, to the last bit, as the part evaluated alone.
use crate::ir::{ArgSpec, Function, Kernel, Op};
use std::collections::HashMap;

/// Two parts of a fused function disagree on an argument's length.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("argument `{argument}` has {len} values in {part} but {other} in another part")]
pub struct FuseError {
    pub argument: String,
    pub len: usize,
    pub part: String,
    pub other: usize,
}

/// `parts` as one function named `name`. Its arguments are the union of the
/// parts' arguments (matched by role, in order of first appearance); its outputs
/// the parts' outputs one after another, as a column (`rows` = their total).
/// Fails when two parts give one argument different lengths.
pub fn fuse(name: &str, parts: &[&Function]) -> Result<Function, FuseError> {
    let mut args: Vec<ArgSpec> = Vec::new();
    for f in parts {
        for a in &f.args {
            match args.iter().find(|b| b.role == a.role) {
                Some(b) if b.names.len() != a.names.len() => {
                    return Err(FuseError {
                        argument: a.ident().to_string(),
                        len: a.names.len(),
                        part: f.name.clone(),
                        other: b.names.len(),
                    })
                }
                Some(_) => {}
                None => args.push(a.clone()),
            }
        }
    }
    let mut tape: Vec<Op> = Vec::new();
    // an op (operands already in fused slots) -> its fused slot; the Debug text is
    // an exact key (floats print in their shortest round-trip form)
    let mut seen: HashMap<String, u32> = HashMap::new();
    let mut outputs = Vec::new();
    let mut row_names = Vec::new();
    for f in parts {
        let arg_of: Vec<u16> = f
            .args
            .iter()
            .map(|a| args.iter().position(|b| b.role == a.role).unwrap() as u16)
            .collect();
        let mut slot_of: Vec<u32> = Vec::with_capacity(f.tape.len());
        for op in &f.tape {
            let op = match *op {
                Op::Arg(a, i) => Op::Arg(arg_of[a as usize], i),
                _ => op.remap(|r| slot_of[r as usize]),
            };
            let slot = *seen.entry(format!("{op:?}")).or_insert_with(|| {
                tape.push(op);
                tape.len() as u32 - 1
            });
            slot_of.push(slot);
        }
        outputs.extend(f.outputs.iter().map(|&o| slot_of[o as usize]));
        for k in 0..f.rows * f.cols {
            row_names.push(format!("{}[{k}]", f.name));
        }
    }
    Ok(Function {
        kernel: Kernel::Fused,
        name: name.to_string(),
        doc: format!(
            "{} in one tape",
            parts
                .iter()
                .map(|f| f.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ),
        args,
        rows: outputs.len(),
        cols: 1,
        row_names,
        col_names: vec![],
        tape,
        ops_tree: parts.iter().map(|f| f.ops_tree).sum(),
        outputs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::{ArgRole, ModelIr, StepForm};

    /// On every bundled model, the pose, twist and Jacobians of a step fused give
    /// each part's own outputs to the last bit, with fewer operations than the
    /// parts apart.
    #[test]
    fn a_fused_step_equals_its_parts_with_less_work() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../generated/ir");
        for entry in std::fs::read_dir(dir).unwrap() {
            let ir = ModelIr::from_json(&std::fs::read_to_string(entry.unwrap().path()).unwrap())
                .unwrap();
            let exact = ir.step(StepForm::Exact);
            let parts = vec![exact.value, ir.twist(), exact.jac_x, exact.jac_p.unwrap()];
            let fused = fuse("linearized", &parts).unwrap();
            let apart: usize = parts.iter().map(|f| f.ops_tape()).sum();
            assert!(
                fused.ops_tape() < apart,
                "{}: fused {} ops, apart {apart}",
                ir.name,
                fused.ops_tape()
            );
            for trial in 0..8 {
                let value = |a: usize, i: usize| {
                    if trial == 0 {
                        0.0
                    } else {
                        0.1 + 0.37 * ((trial * 7 + a * 5 + i * 3) % 11) as f64 / 11.0
                    }
                };
                let values: Vec<Vec<f64>> = fused
                    .args
                    .iter()
                    .enumerate()
                    .map(|(a, s)| (0..s.names.len()).map(|i| value(a, i)).collect())
                    .collect();
                let got = fused.interpret(&values.iter().map(Vec::as_slice).collect::<Vec<_>>());
                let mut want = Vec::new();
                for f in &parts {
                    let args: Vec<&[f64]> = f
                        .args
                        .iter()
                        .map(|a| {
                            let k = fused.args.iter().position(|b| b.role == a.role).unwrap();
                            values[k].as_slice()
                        })
                        .collect();
                    want.extend(f.interpret(&args));
                }
                assert_eq!(got.len(), want.len());
                for (k, (g, w)) in got.iter().zip(&want).enumerate() {
                    assert!(
                        g.to_bits() == w.to_bits() || (g.is_nan() && w.is_nan()),
                        "{} output {k} ({}): fused {g:e}, apart {w:e}",
                        ir.name,
                        fused.row_names[k]
                    );
                }
            }
        }
    }

    #[test]
    fn one_argument_name_with_two_lengths_is_refused() {
        let f = |n: usize| Function {
            kernel: Kernel::Fused,
            name: format!("f{n}"),
            doc: String::new(),
            args: vec![ArgSpec {
                role: ArgRole::State,
                names: vec![String::new(); n],
            }],
            rows: 1,
            cols: 1,
            row_names: vec![],
            col_names: vec![],
            tape: vec![Op::Arg(0, 0)],
            outputs: vec![0],
            ops_tree: 0,
        };
        let err = fuse("both", &[&f(3), &f(2)]).unwrap_err();
        assert!(
            err.to_string().contains("`x` has 2 values in f2 but 3"),
            "{err}"
        );
    }
}
