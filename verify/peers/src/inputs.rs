//! The benchmark's inputs, drawn from how robots move: body velocities and
//! time steps of real logs (`../shared/real/`, or `$KINEGEN_REAL_DATA`) and
//! of simulated random driving, turned into each model's inputs by its own
//! generated inverse kinematics. Where the real logs are absent only the
//! simulated driving is used, and the benchmark says so.
//!
//! The share of steps under the series switch (|omega dt| <= 0.05) follows
//! from the data, and so does the order in which the two sides of the
//! switch come (a robot drives straight for a while, then turns): the
//! branch predictor sees what it would see on a robot.
use crate::{Args, Model};
use kinegen_generated::{diff_drive as dd, omni_caster as oc, unicycle_ekf as uc};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};

/// A body twist held over one time step.
#[derive(Clone, Copy, Debug)]
pub struct Motion {
    pub vx: f64,
    pub vy: f64,
    pub omega: f64,
    pub dt: f64,
}

/// Where the motions came from, for the report.
#[derive(Clone, Debug, Default)]
pub struct Sources {
    /// (name, motions taken)
    pub used: Vec<(String, usize)>,
    /// why a real source was left out
    pub missing: Vec<String>,
}

/// The real logs' folder: `$KINEGEN_REAL_DATA`, else `../shared/real` beside
/// the checkout.
pub fn real_data_dir() -> PathBuf {
    std::env::var_os("KINEGEN_REAL_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/real"))
}

/// Columns `names` of a numeric CSV file with a header row.
fn columns(path: &Path, names: &[&str]) -> Option<Vec<Vec<f64>>> {
    let mut reader = csv::Reader::from_path(path).ok()?;
    let header = reader.headers().ok()?.clone();
    let at: Vec<usize> = names
        .iter()
        .map(|n| header.iter().position(|h| h == *n))
        .collect::<Option<_>>()?;
    let mut cols = vec![Vec::new(); names.len()];
    for record in reader.records() {
        let record = record.ok()?;
        for (c, &i) in cols.iter_mut().zip(&at) {
            c.push(record.get(i)?.trim().parse().ok()?);
        }
    }
    Some(cols)
}

fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
}

/// Body twists of a motion-capture track: central differences over the
/// neighbouring rows, rotated into the body frame; the step is to the next row.
fn from_ground_truth(t: &[f64], x: &[f64], y: &[f64], th: &[f64]) -> Vec<Motion> {
    (1..t.len().saturating_sub(1))
        .filter_map(|i| {
            let span = t[i + 1] - t[i - 1];
            let dt = t[i + 1] - t[i];
            if !(span > 0.0 && dt > 0.0) {
                return None;
            }
            let (dx, dy) = ((x[i + 1] - x[i - 1]) / span, (y[i + 1] - y[i - 1]) / span);
            let (s, c) = th[i].sin_cos();
            Some(Motion {
                vx: c * dx + s * dy,
                vy: -s * dx + c * dy,
                omega: wrap(th[i + 1] - th[i - 1]) / span,
                dt,
            })
        })
        .collect()
}

/// Every run of OptiOdom's sessions (four robot types, 20-25 Hz motion capture).
fn optiodom(dir: &Path) -> Vec<Motion> {
    let mut runs: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| e.path().is_dir())
        .flat_map(|e| std::fs::read_dir(e.path()).into_iter().flatten().flatten())
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    runs.sort();
    runs.iter()
        .filter_map(|p| columns(p, &["t", "gt_x", "gt_y", "gt_theta"]))
        .flat_map(|c| from_ground_truth(&c[0], &c[1], &c[2], &c[3]))
        .collect()
}

/// MRCLAM's robots: the commanded speed and turn rate, held from each row to
/// the next (rows come at irregular times).
fn mrclam(dir: &Path) -> Vec<Motion> {
    let mut logs: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path().join("log.csv"))
        .filter(|p| p.is_file())
        .collect();
    logs.sort();
    logs.iter()
        .filter_map(|p| columns(p, &["t", "v", "omega"]))
        .flat_map(|c| {
            (0..c[0].len().saturating_sub(1))
                .map(|i| Motion {
                    vx: c[1][i],
                    vy: 0.0,
                    omega: c[2][i],
                    dt: c[0][i + 1] - c[0][i],
                })
                .filter(|m| m.dt > 0.0)
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Random driving at 50 Hz: speed, sideways speed (omni robots) and turn
/// rate held for 0.5-3 s, then drawn again.
fn simulated(rng: &mut SmallRng, n: usize) -> Vec<Motion> {
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let hold = (rng.gen_range(0.5..3.0) / 0.02) as usize;
        let (vx, vy, omega) = (
            rng.gen_range(-0.5..1.0),
            rng.gen_range(-0.3..0.3),
            rng.gen_range(-2.0..2.0),
        );
        out.extend((0..hold).map(|_| Motion {
            vx,
            vy,
            omega,
            dt: 0.02,
        }));
    }
    out.truncate(n);
    out
}

/// `n` motions from `from` in stretches of 500 consecutive steps spread
/// over the whole source, so that every session is represented and each
/// stretch keeps its order.
fn spread(from: &[Motion], n: usize) -> Vec<Motion> {
    if from.len() <= n || n == 0 {
        return from[..from.len().min(n)].to_vec();
    }
    let stretch = n.min(500);
    let stretches = n.div_ceil(stretch);
    let gap = (from.len() - stretch) / stretches;
    (0..stretches)
        .flat_map(|k| &from[k * gap..k * gap + stretch])
        .copied()
        .take(n)
        .collect()
}

/// `n` motions: a third from each real source where present, the rest
/// simulated.
pub fn motions(n: usize, rng: &mut SmallRng) -> (Vec<Motion>, Sources) {
    let root = real_data_dir();
    let mut sources = Sources::default();
    let mut all = Vec::with_capacity(n);
    for (name, dir, read) in [
        (
            "OptiOdom motion capture",
            root.join("optiodom-dev"),
            optiodom as fn(&Path) -> Vec<Motion>,
        ),
        ("MRCLAM commands", root.join("mrclam-dataset6"), mrclam),
    ] {
        let found = read(&dir);
        if found.is_empty() {
            sources
                .missing
                .push(format!("{name} (no logs at {})", dir.display()));
            continue;
        }
        let taken = spread(&found, n / 3);
        sources.used.push((name.to_string(), taken.len()));
        all.extend(taken);
    }
    let rest = n - all.len();
    all.extend(simulated(rng, rest));
    sources
        .used
        .push(("simulated random driving".to_string(), rest));
    (all, sources)
}

/// The arrays behind one call's [`Args`].
#[derive(Clone, Debug)]
pub struct Sample {
    pub x: [f64; 3],
    pub u: Vec<f64>,
    pub w: Vec<f64>,
    pub p: Vec<f64>,
    pub lm: [f64; 2],
    pub dt: f64,
    /// omega dt of the step (0 for an observation)
    pub turn: f64,
}

impl Sample {
    /// The call's arguments, pointing into this sample (which must outlive them).
    pub fn args(&self) -> Args {
        Args {
            x: self.x.as_ptr(),
            u: self.u.as_ptr(),
            w: self.w.as_ptr(),
            p: self.p.as_ptr(),
            lm: self.lm.as_ptr(),
            dt: self.dt,
        }
    }
}

/// Nominal parameters, each off by up to 2% (a calibrated robot).
fn parameters<const N: usize>(nominal: [f64; N], rng: &mut SmallRng) -> Vec<f64> {
    nominal
        .iter()
        .map(|v| v * rng.gen_range(0.98..1.02))
        .collect()
}

/// Each motion as the model's inputs: its wheel (and caster) rates from the
/// model's generated inverse kinematics, a pose anywhere, zero process noise
/// (an EKF's mean prediction), and for the landmark model a landmark 0.3-8 m
/// away in any direction.
pub fn samples(model: Model, motions: &[Motion], seed: u64) -> Vec<Sample> {
    let mut rng = SmallRng::seed_from_u64(seed);
    motions
        .iter()
        .map(|m| {
            let x = [
                rng.gen_range(-5.0..5.0),
                rng.gen_range(-5.0..5.0),
                rng.gen_range(-3.1..3.1),
            ];
            let (u, w, p, turn) = match model {
                Model::DiffDrive => {
                    let p = parameters(dd::PARAM_NOMINAL, &mut rng);
                    let pa: [f64; 5] = p.clone().try_into().unwrap();
                    let u = dd::inverse_twist(&[m.vx, 0.0, m.omega], &pa).to_vec();
                    let turn = dd::twist(&u.clone().try_into().unwrap(), &pa)[2] * m.dt;
                    (u, vec![0.0; 2], p, turn)
                }
                Model::OmniCaster => {
                    let p = parameters(oc::PARAM_NOMINAL, &mut rng);
                    let pa: [f64; 12] = p.clone().try_into().unwrap();
                    let beta = [
                        rng.gen_range(-3.1..3.1),
                        rng.gen_range(-3.1..3.1),
                        rng.gen_range(-3.1..3.1),
                    ];
                    let rates = oc::inverse_twist(&[m.vx, m.vy, m.omega], &beta, &pa);
                    let u: Vec<f64> = beta.iter().chain(&rates).copied().collect();
                    let turn = oc::twist(&u.clone().try_into().unwrap(), &pa)[2] * m.dt;
                    (u, vec![0.0; 3], p, turn)
                }
                Model::Unicycle => (
                    vec![m.vx, m.omega],
                    Vec::new(),
                    uc::PARAM_NOMINAL.to_vec(),
                    0.0,
                ),
            };
            let (r, b) = (rng.gen_range(0.3..8.0), rng.gen_range(-3.1..3.1));
            Sample {
                lm: [x[0] + r * f64::cos(b), x[1] + r * f64::sin(b)],
                x,
                u,
                w,
                p,
                dt: m.dt,
                turn,
            }
        })
        .collect()
}
