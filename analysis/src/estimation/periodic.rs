//! Periodic structure in residuals: is a residual a sinusoid of a coordinate that
//! repeats physically (a wheel's cumulative angle, time)?
//!
//! An out-of-round or eccentric wheel, a wobbling tracker mount or a periodic
//! disturbance leaves a residual that is small in every step but phase-locked to
//! the coordinate. Binning by speed or heading averages it away; a periodogram
//! over the coordinate adds it up coherently. The coordinate need not be sampled
//! evenly or grow monotonically (wheels stop and reverse), so this is a direct
//! non-uniform Fourier sum, not an FFT.
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::decl::InputKind;

/// The strongest sinusoid found in one residual channel.
#[derive(Debug, Clone, Copy)]
pub struct Peak {
    /// Period, in the coordinate's unit.
    pub period: f64,
    /// Share of the residual's variance the sinusoid explains.
    pub eta2: f64,
    /// Explained sum of squares over the residual variance: chi-square with 2
    /// degrees of freedom when the residual is white noise.
    pub stat: f64,
    /// Amplitude of the sinusoid, in the channel's unit.
    pub amplitude: f64,
    /// The fitted sinusoid a cos(f (c - origin)) + b sin(f (c - origin)) (+ mean):
    /// (f, a, b, origin).
    fit: (f64, f64, f64, f64),
}

impl Peak {
    /// Take the fitted sinusoid out of `y` (sampled at `coord`), so weaker
    /// periodic structure under it can be looked for.
    pub fn remove(&self, coord: &[f64], y: &mut [f64]) {
        let (f, a, b, origin) = self.fit;
        for (c, v) in coord.iter().zip(y.iter_mut()) {
            let (s, co) = (f * (c - origin)).sin_cos();
            *v -= a * co + b * s;
        }
    }
}

/// Most trial frequencies per scan: the cost is samples x channels x this many
/// complex multiply-adds (10,000 samples: about 0.1 s).
const MAX_FREQS: usize = 3000;
/// Fewest cycles over the coordinate's range for a period to be believed.
const MIN_CYCLES: f64 = 3.0;
/// Fewest samples per cycle (a period shorter than this aliases).
const MIN_SAMPLES_PER_CYCLE: f64 = 4.0;
/// Trial frequencies per Fourier bin (1 / range): a sinusoid between two trial
/// frequencies loses at most ~20% of its power to the grid, and the peak is then
/// refined by least squares.
const OVERSAMPLE: f64 = 2.0;

/// Scan every channel of `ys` (equal lengths, one value per sample) for a
/// sinusoid of `coord`. None for a channel that is all zeros, or when the
/// coordinate covers too few cycles of any period worth testing.
pub fn scan(coord: &[f64], ys: &[Vec<f64>]) -> Vec<Option<Peak>> {
    let n = coord.len();
    let none = vec![None; ys.len()];
    if n < 40 {
        return none;
    }
    let (lo, hi) = coord
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &c| {
            (a.min(c), b.max(c))
        });
    let range = hi - lo;
    let mut steps: Vec<f64> = coord.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    steps.sort_by(f64::total_cmp);
    let typical_step = steps[steps.len() / 2];
    // (NaN-safe: a NaN range or step is not positive either)
    if !matches!(range.partial_cmp(&0.0), Some(std::cmp::Ordering::Greater))
        || !matches!(
            typical_step.partial_cmp(&0.0),
            Some(std::cmp::Ordering::Greater)
        )
    {
        return none;
    }
    // trial frequencies m / (OVERSAMPLE * range), m = first..=last
    let first = (MIN_CYCLES * OVERSAMPLE).ceil() as usize;
    let last = ((range / (MIN_SAMPLES_PER_CYCLE * typical_step)) * OVERSAMPLE).floor() as usize;
    let last = last.min(first + MAX_FREQS);
    if last < first {
        return none;
    }
    // phases from the start of the range keep the arguments small (accurate sin/cos)
    let shifted: Vec<f64> = coord.iter().map(|c| c - lo).collect();
    let coord = shifted.as_slice();
    let centred: Vec<Vec<f64>> = ys
        .iter()
        .map(|y| {
            let m = y.iter().sum::<f64>() / n as f64;
            y.iter().map(|v| v - m).collect()
        })
        .collect();
    let base = 2.0 * std::f64::consts::PI / (OVERSAMPLE * range);
    // phasors e^{i m base (c - lo)}, advanced one trial frequency at a time by
    // multiplication (no trigonometry in the inner loop)
    let step: Vec<(f64, f64)> = coord
        .iter()
        .map(|c| {
            let a = base * c;
            (a.cos(), a.sin())
        })
        .collect();
    let mut w: Vec<(f64, f64)> = coord
        .iter()
        .map(|c| {
            let a = first as f64 * base * c;
            (a.cos(), a.sin())
        })
        .collect();
    let mut best = vec![(0.0f64, first); ys.len()];
    for m in first..=last {
        for (ch, y) in centred.iter().enumerate() {
            let (mut re, mut im) = (0.0, 0.0);
            for (v, z) in y.iter().zip(&w) {
                re += v * z.0;
                im += v * z.1;
            }
            let power = re * re + im * im;
            if power > best[ch].0 {
                best[ch] = (power, m);
            }
        }
        for (z, s) in w.iter_mut().zip(&step) {
            *z = (z.0 * s.0 - z.1 * s.1, z.0 * s.1 + z.1 * s.0);
        }
    }
    centred
        .iter()
        .zip(&best)
        .map(|(y, &(power, m))| {
            if power == 0.0 {
                return None;
            }
            // refine around the grid peak, then fit the sinusoid by least squares
            let f0 = m as f64 * base;
            let (f, fit) = [-0.25, -0.125, 0.0, 0.125, 0.25]
                .iter()
                .map(|d| {
                    let f = f0 + d * base;
                    (f, sinusoid(coord, y, f))
                })
                .max_by(|a, b| a.1 .0.total_cmp(&b.1 .0))?;
            let (explained, a, b) = fit;
            let total: f64 = y.iter().map(|v| v * v).sum();
            let eta2 = explained / total;
            let noise = (total - explained).max(1e-300) / (n as f64 - 3.0);
            Some(Peak {
                period: 2.0 * std::f64::consts::PI / f,
                eta2,
                stat: explained / noise,
                amplitude: a.hypot(b),
                fit: (f, a, b, lo),
            })
        })
        .collect()
}

/// Least-squares fit of y = a cos(f c) + b sin(f c): (explained sum of squares, a, b).
fn sinusoid(coord: &[f64], y: &[f64], f: f64) -> (f64, f64, f64) {
    let (mut cc, mut ss, mut cs, mut yc, mut ys) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (c, v) in coord.iter().zip(y) {
        let (s, co) = (f * c).sin_cos();
        cc += co * co;
        ss += s * s;
        cs += co * s;
        yc += v * co;
        ys += v * s;
    }
    let det = cc * ss - cs * cs;
    if det.abs() < 1e-12 * (cc * ss).max(1e-300) {
        return (0.0, 0.0, 0.0);
    }
    let a = (ss * yc - cs * ys) / det;
    let b = (cc * ys - cs * yc) / det;
    (a * yc + b * ys, a, b)
}

/// A physically repeating coordinate of the steps of a set of runs.
pub struct Coordinate {
    /// For people: "n_r", "time".
    pub name: String,
    /// Unit of the coordinate ("count", "rad", "s").
    pub unit: String,
    /// Length of one wheel revolution in the coordinate's unit, when it is known:
    /// 2 pi for wheel angles in rad, or a model parameter (or ratio of two) in the
    /// input's unit that matches the measured period.
    pub revolution_candidates: Vec<(String, f64)>,
    /// Value at the midpoint of every step (runs with ground truth, in order).
    pub values: Vec<f64>,
    /// Whether the coordinate moves during the step: a stopped wheel's residual
    /// carries no phase information (and a bias there would look periodic).
    pub moving: Vec<bool>,
}

/// The cumulative inputs (wheel angles, counts) and time, per step of the runs
/// that have ground truth, in the order `diagnose::one_step` produces residuals.
pub fn coordinates(r: &Runner, runs: &[Run]) -> Vec<Coordinate> {
    let mut out = Vec::new();
    for (i, inp) in r.ir.inputs.iter().enumerate() {
        if inp.kind != InputKind::Cumulative {
            continue;
        }
        let unit = inp.unit.strip_suffix("/s").unwrap_or(&inp.unit).to_string();
        let (mut values, mut moving) = (Vec::new(), Vec::new());
        for run in runs.iter().filter(|run| run.gt.is_some()) {
            let mut acc = 0.0;
            for k in 0..run.steps() {
                let d = run.u[k][i] * run.dt[k];
                values.push(acc + 0.5 * d);
                moving.push(d != 0.0);
                acc += d;
            }
        }
        out.push(Coordinate {
            name: inp.name.clone(),
            revolution_candidates: revolution_candidates(r, &unit),
            unit,
            values,
            moving,
        });
    }
    let (mut values, mut moving) = (Vec::new(), Vec::new());
    for run in runs.iter().filter(|run| run.gt.is_some()) {
        for k in 0..run.steps() {
            values.push(0.5 * (run.t[k] + run.t[k + 1]));
            moving.push(true);
        }
    }
    out.push(Coordinate {
        name: "time".into(),
        unit: "s".into(),
        revolution_candidates: Vec::new(),
        values,
        moving,
    });
    out
}

/// What one revolution of a wheel driven by an input of `unit` may measure:
/// 2 pi for an angle; otherwise each parameter in that unit (counts per
/// revolution), alone or divided by a dimensionless one (a gear ratio).
fn revolution_candidates(r: &Runner, unit: &str) -> Vec<(String, f64)> {
    if unit == "rad" {
        return vec![("2 pi rad".into(), 2.0 * std::f64::consts::PI)];
    }
    let value = |name: &str, nominal: f64| r.param_index(name).map_or(nominal, |i| r.p[i]);
    let mut out = Vec::new();
    for a in r.ir.params.iter().filter(|p| p.unit == unit) {
        let va = value(&a.name, a.nominal);
        out.push((a.name.clone(), va));
        for b in r.ir.params.iter().filter(|p| p.unit == "1") {
            let vb = value(&b.name, b.nominal);
            if vb != 0.0 {
                out.push((format!("{}/{}", a.name, b.name), va / vb));
            }
        }
    }
    out.retain(|(_, v)| v.is_finite() && *v > 0.0);
    out
}

/// Words an engineer acts on, for a period found along `c`.
pub fn describe(c: &Coordinate, period: f64) -> String {
    if c.name == "time" {
        return format!(
            "repeats every {period:.3} s (a vibration, a wobbling sensor mount or a periodic disturbance)"
        );
    }
    for (what, rev) in &c.revolution_candidates {
        for (k, times) in [(1.0, "once"), (2.0, "twice"), (3.0, "three times")] {
            if (period * k / rev - 1.0).abs() < 0.04 {
                let why = if k == 1.0 {
                    "out-of-round or eccentric wheel"
                } else {
                    "an oval or unevenly worn wheel"
                };
                return format!(
                    "{times} per `{}` wheel revolution ({period:.4} {} per cycle, {what} = {rev:.4} per revolution): {why}",
                    c.name, c.unit
                );
            }
        }
    }
    format!(
        "repeats every {period:.4} {} of `{}` (if that is one wheel revolution: out-of-round or eccentric wheel)",
        c.unit, c.name
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic noise (a linear congruential generator, so the test needs no
    /// RNG crate): uniform in [-1, 1).
    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 52) as f64 - 1.0
            })
            .collect()
    }

    #[test]
    fn a_sinusoid_in_an_unevenly_sampled_wheel_angle_is_found_at_its_period() {
        // a wheel that speeds up, stops and reverses; the residual has a 0.3-sigma
        // sinusoid of period 2 pi in its angle
        let n = 10_000;
        let mut c = 0.0;
        let coord: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 * 0.02;
                c += 0.02 * (3.0 * (0.05 * t).sin() + 1.5);
                c
            })
            .collect();
        let e = noise(n, 7);
        let y: Vec<f64> = coord
            .iter()
            .zip(&e)
            .map(|(c, e)| 0.3 * 0.577 * (c + 0.4).sin() + 0.577 * e)
            .collect();
        let p = scan(&coord, &[y, e.clone()]);
        let hit = p[0].expect("peak");
        assert!(
            (hit.period / (2.0 * std::f64::consts::PI) - 1.0).abs() < 0.01,
            "{hit:?}"
        );
        assert!((hit.amplitude / (0.3 * 0.577) - 1.0).abs() < 0.1, "{hit:?}");
        assert!(hit.stat > 200.0, "{hit:?}");
        // pure noise: the best of the scanned frequencies stays near chance
        let miss = p[1].expect("scanned");
        assert!(miss.stat < 40.0, "{miss:?}");
    }

    #[test]
    fn too_short_a_coordinate_is_not_scanned() {
        let coord: Vec<f64> = (0..100).map(|k| k as f64 * 1e-3).collect();
        let y: Vec<f64> = coord.iter().map(|c| c.sin()).collect();
        assert!(scan(&coord[..30], &[y[..30].to_vec()])[0].is_none());
        // 0.1 rad of travel is a small part of one cycle of the 2 pi sinusoid:
        // only periods that fit MIN_CYCLES times into the range are tried
        let p = scan(&coord, &[y])[0];
        assert!(
            p.is_none_or(|p| p.period < 0.1 / (MIN_CYCLES - 0.5)),
            "{p:?}"
        );
    }
}
