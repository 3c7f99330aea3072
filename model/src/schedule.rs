//! In what order, and inside which branch, a tape's operations are emitted as
//! code (by the Rust emitter of kinegen-codegen and by the evaluator's JIT).
//!
//! A removable singularity is a guard, `if |x| < eps { series } else { closed
//! form }` (`Op::NearZero`). Evaluating both sides and selecting one wastes the
//! work of the other, so each side's own operations go inside it. Guards with
//! the same condition (the x, y and heading of an exact step all switch on
//! omega dt) become one `if` whose sides compute all their values, so the shared
//! series powers, or the sine and cosine of omega dt, are computed only on the
//! side that needs them.
use crate::ir::Op;

/// Guards emitted as one `if`: the same condition, branches independent of each
/// other (no member reads another's value).
#[derive(Debug, Clone, PartialEq)]
pub struct Group {
    /// The NearZero slots, in tape order.
    pub members: Vec<usize>,
    pub x: u32,
    pub eps: f64,
}

/// What to emit, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Item {
    /// The slot's own statement.
    Slot(usize),
    /// A guard group: its members bound from an `if` whose sides emit `near` and
    /// `far` first.
    Guard {
        group: usize,
        near: Vec<Item>,
        far: Vec<Item>,
    },
}

/// The emission plan of a tape with these outputs.
pub fn schedule(tape: &[Op], outputs: &[u32]) -> (Vec<Item>, Vec<Group>) {
    let mut groups = group_guards(tape);
    loop {
        let owner = owners(tape, outputs, &groups);
        // members of one group must live in the same scope to share an `if`
        let split: Vec<usize> = (0..groups.len())
            .filter(|&g| {
                let m = &groups[g].members;
                m.iter().any(|&s| owner[s] != owner[m[0]])
            })
            .collect();
        if let Some(&g) = split.first() {
            let members = std::mem::take(&mut groups[g].members);
            let (x, eps) = (groups[g].x, groups[g].eps);
            groups[g].members = vec![members[0]];
            groups.extend(members[1..].iter().map(|&m| Group {
                members: vec![m],
                x,
                eps,
            }));
            continue;
        }
        let plan = Planner {
            tape,
            owner: &owner,
            groups: &groups,
            group_of: group_of(tape.len(), &groups),
        };
        match plan.scope(None) {
            Some(items) => return (items, groups),
            // a cycle through merged guards: fall back to one guard per `if`,
            // which is always acyclic (everything a guard needs comes before it)
            None if groups.iter().any(|g| g.members.len() > 1) => {
                groups = groups
                    .iter()
                    .flat_map(|g| {
                        g.members.iter().map(|&m| Group {
                            members: vec![m],
                            x: g.x,
                            eps: g.eps,
                        })
                    })
                    .collect();
            }
            None => unreachable!("single guards cannot form a cycle"),
        }
    }
}

fn readers(tape: &[Op]) -> Vec<Vec<usize>> {
    let mut r: Vec<Vec<usize>> = vec![Vec::new(); tape.len()];
    for (i, op) in tape.iter().enumerate() {
        for o in op.operands() {
            r[o as usize].push(i);
        }
    }
    r
}

fn group_of(n: usize, groups: &[Group]) -> Vec<Option<usize>> {
    let mut of = vec![None; n];
    for (g, grp) in groups.iter().enumerate() {
        for &m in &grp.members {
            of[m] = Some(g);
        }
    }
    of
}

/// Guards with the same condition, merged while none reads another.
fn group_guards(tape: &[Op]) -> Vec<Group> {
    let mut groups: Vec<Group> = Vec::new();
    for (k, op) in tape.iter().enumerate() {
        let Op::NearZero { x, eps, .. } = *op else {
            continue;
        };
        // everything k reads, transitively
        let mut cone = vec![false; k];
        let mut stack: Vec<u32> = op.operands();
        while let Some(s) = stack.pop() {
            let s = s as usize;
            if !cone[s] {
                cone[s] = true;
                stack.extend(tape[s].operands());
            }
        }
        let joinable = groups.iter_mut().find(|g| {
            g.x == x && g.eps.to_bits() == eps.to_bits() && !g.members.iter().any(|&m| cone[m])
        });
        match joinable {
            Some(g) => g.members.push(k),
            None => groups.push(Group {
                members: vec![k],
                x,
                eps,
            }),
        }
    }
    groups
}

fn root(op: &Op, near_side: bool) -> usize {
    match *op {
        Op::NearZero { near, far, .. } => (if near_side { near } else { far }) as usize,
        _ => unreachable!("a guard group holds NearZero slots"),
    }
}

/// For every slot, the side of the guard group it is emitted in, as (group,
/// near?), or None for the function body. A slot belongs to a side when the side
/// needs it and nothing outside that side does (not an output, not a guard's
/// condition, every reader inside the side or one of the group's members reading
/// it as that side's value). Inner groups claim their sides inside their
/// parent's. The 3x3 pseudo-inverse stays in the body (one decomposition per
/// matrix, shared).
fn owners(tape: &[Op], outputs: &[u32], groups: &[Group]) -> Vec<Option<(usize, bool)>> {
    let n = tape.len();
    let readers = readers(tape);
    let group_of = group_of(n, groups);
    let mut pinned = vec![false; n];
    for &o in outputs {
        pinned[o as usize] = true;
    }
    for (i, op) in tape.iter().enumerate() {
        match *op {
            Op::NearZero { x, .. } => pinned[x as usize] = true,
            Op::PinvSym3 { .. } => pinned[i] = true,
            _ => {}
        }
    }
    let mut owner: Vec<Option<(usize, bool)>> = vec![None; n];
    // outer groups first (an outer guard comes after everything inside it), so an
    // inner group's later claim is the innermost
    let mut order: Vec<usize> = (0..groups.len()).collect();
    order.sort_by_key(|&g| std::cmp::Reverse(*groups[g].members.last().unwrap()));
    for g in order {
        for side in [true, false] {
            let roots: Vec<usize> = groups[g]
                .members
                .iter()
                .map(|&m| root(&tape[m], side))
                .collect();
            let both_sides = |s: usize| {
                groups[g]
                    .members
                    .iter()
                    .any(|&m| root(&tape[m], true) == s && root(&tape[m], false) == s)
            };
            let top = *roots.iter().max().unwrap();
            let mut inside = vec![false; n];
            for s in (0..=top).rev() {
                let is_root = roots.contains(&s);
                let reachable = is_root || readers[s].iter().any(|&c| c <= top && inside[c]);
                inside[s] = reachable
                    && !pinned[s]
                    && !both_sides(s)
                    && readers[s].iter().all(|&c| {
                        (c <= top && inside[c])
                            || (group_of[c] == Some(g) && root(&tape[c], side) == s)
                    });
            }
            for s in 0..=top {
                if inside[s] {
                    owner[s] = Some((g, side));
                }
            }
        }
    }
    owner
}

struct Planner<'a> {
    tape: &'a [Op],
    owner: &'a [Option<(usize, bool)>],
    groups: &'a [Group],
    group_of: Vec<Option<usize>>,
}

#[derive(Clone, Copy, PartialEq)]
enum Unit {
    Slot(usize),
    Guard(usize),
}

impl Planner<'_> {
    /// The unit of `scope` that slot `s` is emitted in (itself, its guard group,
    /// or the group holding the side it sits in), or None when it belongs to an
    /// enclosing scope (already emitted before this one).
    fn unit_in(&self, mut s: usize, scope: Option<(usize, bool)>) -> Option<Unit> {
        loop {
            if self.owner[s] == scope {
                return Some(match self.group_of[s] {
                    Some(g) => Unit::Guard(g),
                    None => Unit::Slot(s),
                });
            }
            match self.owner[s] {
                None => return None,
                Some((g, _)) => s = self.groups[g].members[0],
            }
        }
    }

    /// Whether slot `s` is emitted inside group `g` (in one of its sides, at any depth).
    fn within(&self, mut s: usize, g: usize) -> bool {
        while let Some((h, _)) = self.owner[s] {
            if h == g {
                return true;
            }
            s = self.groups[h].members[0];
        }
        false
    }

    fn deps(&self, u: Unit, scope: Option<(usize, bool)>) -> Vec<Unit> {
        let reads: Vec<u32> = match u {
            Unit::Slot(s) => self.tape[s].operands(),
            Unit::Guard(g) => (0..self.tape.len())
                .filter(|&t| self.group_of[t] == Some(g) || self.within(t, g))
                .flat_map(|t| self.tape[t].operands())
                .filter(|&d| {
                    let d = d as usize;
                    self.group_of[d] != Some(g) && !self.within(d, g)
                })
                .collect(),
        };
        reads
            .into_iter()
            .filter_map(|d| self.unit_in(d as usize, scope))
            .filter(|&d| d != u)
            .collect()
    }

    /// The items of one scope in dependency order; None on a cycle.
    fn scope(&self, scope: Option<(usize, bool)>) -> Option<Vec<Item>> {
        // 0 unvisited, 1 in progress, 2 done; per slot and per group
        let mut slot_state = vec![0u8; self.tape.len()];
        let mut group_state = vec![0u8; self.groups.len()];
        let mut out = Vec::new();
        for s in 0..self.tape.len() {
            if self.owner[s] == scope {
                let u = self.unit_in(s, scope)?;
                self.visit(u, scope, &mut slot_state, &mut group_state, &mut out)?;
            }
        }
        Some(out)
    }

    fn visit(
        &self,
        u: Unit,
        scope: Option<(usize, bool)>,
        slot_state: &mut [u8],
        group_state: &mut [u8],
        out: &mut Vec<Item>,
    ) -> Option<()> {
        let state = match u {
            Unit::Slot(s) => &mut slot_state[s],
            Unit::Guard(g) => &mut group_state[g],
        };
        match *state {
            2 => return Some(()),
            1 => return None,
            _ => *state = 1,
        }
        for d in self.deps(u, scope) {
            self.visit(d, scope, slot_state, group_state, out)?;
        }
        out.push(match u {
            Unit::Slot(s) => Item::Slot(s),
            Unit::Guard(g) => Item::Guard {
                group: g,
                near: self.scope(Some((g, true)))?,
                far: self.scope(Some((g, false)))?,
            },
        });
        match u {
            Unit::Slot(s) => slot_state[s] = 2,
            Unit::Guard(g) => group_state[g] = 2,
        }
        Some(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// out = guard(x: x*x + 1 | sin(x)/x) + x*x: the sine and the division are the
    /// far side's alone, the 1 and the sum the near side's; x*x is also read
    /// outside, so it stays in the body.
    #[test]
    fn only_what_one_side_alone_needs_goes_inside_it() {
        let tape = vec![
            Op::Arg(0, 0),
            Op::Mul(0, 0),
            Op::Sin(0),
            Op::Div(2, 0),
            Op::Const(1.0),
            Op::Add(1, 4),
            Op::NearZero {
                x: 0,
                eps: 1e-3,
                near: 5,
                far: 3,
            },
            Op::Add(6, 1),
        ];
        let (items, groups) = schedule(&tape, &[7]);
        assert_eq!(groups.len(), 1);
        assert_eq!(
            items,
            vec![
                Item::Slot(0),
                Item::Slot(1),
                Item::Guard {
                    group: 0,
                    near: vec![Item::Slot(4), Item::Slot(5)],
                    far: vec![Item::Slot(2), Item::Slot(3)],
                },
                Item::Slot(7),
            ]
        );
        // an output never moves inside
        let (items, _) = schedule(&tape, &[7, 3]);
        assert!(items.contains(&Item::Slot(3)) && items.contains(&Item::Slot(2)));
    }

    /// Two guards on the same condition share one `if`, and what both of their
    /// near sides need (x^2) goes inside it.
    #[test]
    fn guards_on_one_condition_share_their_sides() {
        let tape = vec![
            Op::Arg(0, 0), // 0 x
            Op::Mul(0, 0), // 1 x^2 (both near sides)
            Op::Sin(0),    // 2 sin x (both far sides)
            Op::Div(2, 0), // 3 far a
            Op::NearZero {
                x: 0,
                eps: 1e-3,
                near: 1,
                far: 3,
            }, // 4
            Op::Cos(0),    // 5
            Op::Mul(1, 0), // 6 near b = x^3
            Op::Mul(2, 5), // 7 far b
            Op::NearZero {
                x: 0,
                eps: 1e-3,
                near: 6,
                far: 7,
            }, // 8
            Op::Add(4, 8), // 9
        ];
        let (items, groups) = schedule(&tape, &[9]);
        assert_eq!(groups[0].members, vec![4, 8]);
        assert_eq!(
            items,
            vec![
                Item::Slot(0),
                Item::Guard {
                    group: 0,
                    near: vec![Item::Slot(1), Item::Slot(6)],
                    far: vec![Item::Slot(2), Item::Slot(3), Item::Slot(5), Item::Slot(7)],
                },
                Item::Slot(9),
            ]
        );
    }

    /// A guard that reads another guard with the same condition is not merged
    /// with it (that would be a cycle), and comes after it.
    #[test]
    fn a_guard_reading_another_stays_apart() {
        let tape = vec![
            Op::Arg(0, 0),
            Op::Sin(0),
            Op::NearZero {
                x: 0,
                eps: 1e-3,
                near: 0,
                far: 1,
            },
            Op::Mul(2, 2),
            Op::Cos(0),
            Op::NearZero {
                x: 0,
                eps: 1e-3,
                near: 3,
                far: 4,
            },
        ];
        let (items, groups) = schedule(&tape, &[5]);
        assert_eq!(groups.len(), 2);
        let pos = |g: usize| {
            items
                .iter()
                .position(|i| matches!(i, Item::Guard { group, .. } if *group == g))
        };
        assert!(pos(0) < pos(1));
    }
}
