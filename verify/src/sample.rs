//! Sampling a model's domain: poses, physically meaningful inputs (obtained from a
//! random body twist through the model's own inverse kinematics), parameters around
//! their nominal values within their bounds, noise at a few sigma, landmarks.
use kinegen_model::ir::{ArgRole, Function, ModelIr};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

pub struct Sampler<'a> {
    pub ir: &'a ModelIr,
    pub rng: SmallRng,
    /// Twist rows (vx, vy, omega) that the model can produce at all.
    pub twist_rows: [bool; 3],
}

pub fn twist_rows(ir: &ModelIr) -> [bool; 3] {
    let tw = ir.twist();
    let mut rows = [false; 3];
    let mut rng = SmallRng::seed_from_u64(7);
    // over the sampled parameter domain, not only at nominal values (an effect
    // parameter is nominally zero, and so is the motion it adds)
    let mut sampler = Sampler {
        ir,
        rng: SmallRng::seed_from_u64(8),
        twist_rows: [true; 3],
    };
    for _ in 0..8 {
        let p = sampler.params();
        let u: Vec<f64> = ir
            .inputs
            .iter()
            .map(|_| rng.gen_range(-50.0..50.0))
            .collect();
        let t = tw.interpret(&[&u, &p]);
        for r in 0..3 {
            rows[r] |= t[r].abs() > 1e-12;
        }
    }
    rows
}

impl<'a> Sampler<'a> {
    pub fn new(ir: &'a ModelIr, seed: u64) -> Self {
        Sampler {
            ir,
            rng: SmallRng::seed_from_u64(seed),
            twist_rows: twist_rows(ir),
        }
    }

    pub fn params(&mut self) -> Vec<f64> {
        let ps: Vec<_> = self.ir.runtime_params().into_iter().cloned().collect();
        ps.iter()
            .map(|p| {
                let spread = if p.nominal == 0.0 {
                    0.05
                } else {
                    0.2 * p.nominal.abs()
                };
                let lo = p
                    .min
                    .map_or(p.nominal - spread, |m| (p.nominal - spread).max(m + 1e-9));
                let hi = p
                    .max
                    .map_or(p.nominal + spread, |m| (p.nominal + spread).min(m));
                if hi > lo {
                    self.rng.gen_range(lo..hi)
                } else {
                    p.nominal
                }
            })
            .collect()
    }

    pub fn pose(&mut self) -> Vec<f64> {
        vec![
            self.rng.gen_range(-10.0..10.0),
            self.rng.gen_range(-10.0..10.0),
            self.rng.gen_range(-3.1..3.1),
        ]
    }

    pub fn twist(&mut self) -> Vec<f64> {
        let ranges = [1.0, 1.0, 2.0];
        (0..3)
            .map(|r| {
                if self.twist_rows[r] {
                    self.rng.gen_range(-ranges[r]..ranges[r])
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// Inputs that produce `twist` with parameters `p` (through inverse_twist).
    /// A model without inverse kinematics gets inputs drawn in their ranges.
    pub fn inputs_for(&mut self, twist: &[f64], p: &[f64]) -> Vec<f64> {
        let Ok(inv) = self.ir.inverse_twist() else {
            let ranges: Vec<[f64; 2]> = self
                .ir
                .inputs
                .iter()
                .map(|i| i.range.unwrap_or([-1.0, 1.0]))
                .collect();
            return ranges
                .iter()
                .map(|r| self.rng.gen_range(r[0]..r[1]))
                .collect();
        };
        let cfg: Vec<f64> = inv
            .args
            .iter()
            .find(|a| a.role == ArgRole::Configuration)
            .map(|a| {
                a.names
                    .iter()
                    .map(|_| self.rng.gen_range(-1.0..1.0))
                    .collect()
            })
            .unwrap_or_default();
        let args: Vec<&[f64]> = inv
            .args
            .iter()
            .map(|a| match a.role {
                ArgRole::Twist => twist,
                ArgRole::Configuration => &cfg[..],
                _ => p,
            })
            .collect();
        let out = inv.interpret(&args);
        self.ir
            .inputs
            .iter()
            .map(|i| {
                inv.row_names
                    .iter()
                    .position(|r| *r == i.name)
                    .map(|k| out[k])
                    .unwrap_or_else(|| {
                        let k = inv
                            .args
                            .iter()
                            .find(|a| a.role == ArgRole::Configuration)
                            .and_then(|a| a.names.iter().position(|c| *c == i.name));
                        k.map(|k| cfg[k]).unwrap_or(0.0)
                    })
            })
            .collect()
    }

    pub fn noise(&mut self) -> Vec<f64> {
        let sig: Vec<f64> = self
            .ir
            .noise
            .iter()
            .map(|n| if n.sigma > 0.0 { n.sigma } else { 0.01 })
            .collect();
        sig.iter()
            .map(|s| self.rng.gen_range(-3.0 * s..3.0 * s))
            .collect()
    }

    /// A full argument set for `f`, consistent across groups, with the inputs
    /// inside the ranges the spec declares (e.g. a steering lock).
    pub fn args(&mut self, f: &Function) -> Vec<Vec<f64>> {
        let p = self.params();
        let pose = self.pose();
        let mut tw = self.twist();
        let mut u = self.inputs_for(&tw, &p);
        for _ in 0..200 {
            let inside = self
                .ir
                .inputs
                .iter()
                .zip(&u)
                .all(|(i, v)| i.range.is_none_or(|[lo, hi]| (lo..=hi).contains(v)));
            if inside {
                break;
            }
            tw = self.twist();
            u = self.inputs_for(&tw, &p);
        }
        f.args
            .iter()
            .map(|a| match a.role {
                ArgRole::State => pose.clone(),
                ArgRole::Inputs => u.clone(),
                ArgRole::Noise => self.noise(),
                ArgRole::Params => p.clone(),
                ArgRole::Dt => vec![self.rng.gen_range(0.005..0.2)],
                ArgRole::Landmark => {
                    let (r, b) = (self.rng.gen_range(1.0..10.0), self.rng.gen_range(-3.1..3.1));
                    vec![pose[0] + r * f64::cos(b), pose[1] + r * f64::sin(b)]
                }
                ArgRole::Twist => tw.clone(),
                ArgRole::YawRate => vec![tw[2]],
                ArgRole::PoseIncrement => {
                    let d: f64 = self.rng.gen_range(-1.0..1.0);
                    let dy = if self.twist_rows[1] {
                        self.rng.gen_range(-0.5..0.5)
                    } else {
                        0.0
                    };
                    vec![self.rng.gen_range(-1.0..1.0), dy, d]
                }
                ArgRole::Configuration | ArgRole::Values => a
                    .names
                    .iter()
                    .map(|_| self.rng.gen_range(-1.0..1.0))
                    .collect(),
            })
            .collect()
    }
}

/// `args` of the step kernel `f` re-aimed at the twist `twist` turning by
/// `s` over the step (omega = s/dt), the inputs from the model's own
/// inverse and the noise at zero: the exact step's singular limit, as
/// `checks::singularities` and `crosscheck` probe it. None for a kernel
/// without inputs, parameters or a step.
pub fn at_turn(
    sampler: &mut Sampler,
    f: &Function,
    args: &[Vec<f64>],
    twist: &[f64],
    s: f64,
) -> Option<Vec<Vec<f64>>> {
    let (ui, pi, dti) = (
        f.arg(ArgRole::Inputs)?,
        f.arg(ArgRole::Params)?,
        f.arg(ArgRole::Dt)?,
    );
    let mut at = args.to_vec();
    let mut tw = twist.to_vec();
    tw[2] = s / at[dti][0];
    at[ui] = sampler.inputs_for(&tw, &at[pi]);
    if let Some(wi) = f.arg(ArgRole::Noise) {
        at[wi].iter_mut().for_each(|w| *w = 0.0);
    }
    Some(at)
}
