//! Passes over a finished tape, shared by both ways of deriving it (the
//! symbolic stage in kinegen-codegen and [`crate::autodiff`]): dead ops
//! dropped, divisions by one denominator sharing its reciprocal, and the
//! "before CSE" operation count.
use crate::ir::Op;

/// Drop ops no output needs, renumber, and share reciprocals; returns
/// (tape, outputs).
pub fn finish(tape: Vec<Op>, outputs: &[u32]) -> (Vec<Op>, Vec<u32>) {
    let mut live = vec![false; tape.len()];
    for &o in outputs {
        live[o as usize] = true;
    }
    for i in (0..tape.len()).rev() {
        if live[i] {
            for r in tape[i].operands() {
                live[r as usize] = true;
            }
        }
    }
    let mut new_index = vec![u32::MAX; tape.len()];
    let mut kept = Vec::new();
    for (i, op) in tape.into_iter().enumerate() {
        if !live[i] {
            continue;
        }
        let op = op.remap(|r| new_index[r as usize]);
        new_index[i] = kept.len() as u32;
        kept.push(op);
    }
    let outputs: Vec<u32> = outputs.iter().map(|&o| new_index[o as usize]).collect();
    share_reciprocals(kept, &outputs)
}

/// Arithmetic operations if every output were evaluated as its own expression tree,
/// with no sharing (the "before CSE" count). Counted on the shared tape: an op's
/// tree costs itself plus its operands' trees. Equal to lowering without CSE, but
/// without building a tree that can have millions of nodes.
pub fn tree_size(tape: &[Op], outputs: &[u32]) -> usize {
    let mut size = vec![0usize; tape.len()];
    for (i, op) in tape.iter().enumerate() {
        let own = usize::from(op.is_arithmetic());
        size[i] = op
            .operands()
            .iter()
            .fold(own, |acc, &o| acc.saturating_add(size[o as usize]));
    }
    outputs
        .iter()
        .fold(0usize, |acc, &o| acc.saturating_add(size[o as usize]))
}

/// Every division becomes a product with the denominator's reciprocal: a/d and
/// b/d become r = 1/d, a*r and b*r (a division costs about ten
/// multiplications; the parameter Jacobian of seed 000's omni step divides 52
/// times by one slot). Done even for a single division, so that one quantity
/// has one form in every function of a model: the heading change of a step and
/// of its parameter Jacobian then hash to the same slot when the two are fused,
/// and their sines, cosines and guards are computed once, not twice. Each
/// result moves by at most an ulp or so. The reciprocal is placed right before
/// its first use, so the tape stays in dependency order; `1/d` itself is the
/// reciprocal. A denominator that is a product of slots whose reciprocals
/// exist already (1/r^2 after 1/r, in seed 000's normal equations), or whose
/// square root's reciprocal exists (1/d after 1/sqrt(d), in a range-bearing
/// Jacobian), gets the product of those reciprocals instead of another
/// division: a division costs a multiplication's throughput ten times over.
fn share_reciprocals(tape: Vec<Op>, outputs: &[u32]) -> (Vec<Op>, Vec<u32>) {
    let mut new_index = vec![u32::MAX; tape.len()];
    let mut recip = vec![u32::MAX; tape.len()];
    let mut one = u32::MAX;
    let mut out: Vec<Op> = Vec::with_capacity(tape.len());
    let factors: Vec<Option<(usize, usize)>> = tape
        .iter()
        .map(|op| match *op {
            Op::Mul(a, b) => Some((a as usize, b as usize)),
            _ => None,
        })
        .collect();
    // the slot holding sqrt(d), by d
    let mut root_of = vec![usize::MAX; tape.len()];
    for (i, op) in tape.iter().enumerate() {
        if let Op::Sqrt(d) = *op {
            root_of[d as usize] = i;
        }
    }
    // 1/d as the product of its factors' reciprocals, or as 1/sqrt(d)
    // squared, where those reciprocals exist
    let from_factors = |d: usize, recip: &[u32]| {
        let made = |s: usize| s != usize::MAX && recip[s] != u32::MAX;
        if made(root_of[d]) {
            let r = recip[root_of[d]];
            return Some(Op::Mul(r, r));
        }
        let (a, b) = factors[d]?;
        (made(a) && made(b)).then(|| Op::Mul(recip[a], recip[b]))
    };
    for (i, op) in tape.into_iter().enumerate() {
        let op = match op {
            Op::Div(a, d) if tape_const(&out, new_index[a as usize]) == Some(1.0) => {
                let d = d as usize;
                if recip[d] != u32::MAX {
                    // this 1/d was already made for an earlier division by d
                    new_index[i] = recip[d];
                    continue;
                }
                let op =
                    from_factors(d, &recip).unwrap_or(Op::Div(new_index[a as usize], new_index[d]));
                new_index[i] = out.len() as u32;
                recip[d] = new_index[i];
                out.push(op);
                continue;
            }
            Op::Div(a, d) => {
                let d = d as usize;
                if recip[d] == u32::MAX {
                    if let Some(product) = from_factors(d, &recip) {
                        out.push(product);
                        recip[d] = out.len() as u32 - 1;
                    }
                }
                if recip[d] == u32::MAX {
                    if one == u32::MAX {
                        out.push(Op::Const(1.0));
                        one = out.len() as u32 - 1;
                    }
                    out.push(Op::Div(one, new_index[d]));
                    recip[d] = out.len() as u32 - 1;
                }
                Op::Mul(new_index[a as usize], recip[d])
            }
            o => o.remap(|r| new_index[r as usize]),
        };
        new_index[i] = out.len() as u32;
        out.push(op);
    }
    (
        out,
        outputs.iter().map(|&o| new_index[o as usize]).collect(),
    )
}

/// The value of slot `s` when it is a constant.
fn tape_const(tape: &[Op], s: u32) -> Option<f64> {
    match tape[s as usize] {
        Op::Const(c) => Some(c),
        _ => None,
    }
}
