//! Whether a log's landmark sightings are in the units and the sign
//! convention that the map and the spec's observation assume (CONTRACT.md:
//! SI units, angles in radians, the bearing relative to the robot's
//! heading).
//!
//! A range in millimetres against a map in metres, or a bearing measured
//! clockwise, does not stop a filter. It absorbs the mismatch into its
//! estimated noise and ends far off, without a word. On MRCLAM's robot 1
//! with its bearings negated, localize's RMSE is 0.27 m against 0.14, and
//! its noise estimate puts the bearing's lingering errors at 17-35x the
//! spec's sigma.
//!
//! Two checks, neither of which needs ground truth:
//! - [`spacing`]: two landmarks seen at one instant lie as far apart, by
//!   the law of cosines on their ranges and bearings, as the map places
//!   them. This catches a range in another unit than the map's, and most
//!   bearings in degrees.
//! - [`turning`]: as the robot turns, a landmark's bearing changes as the
//!   spec's observation predicts along the model's own dead reckoning.
//!   Over a second or less, dead reckoning is good however far it drifts
//!   later. This catches a bearing of the other sign.
use crate::logs::log::{typical, wrap};
use crate::model_on_log::evaluation::tracks;
use crate::model_on_log::innovations::predicted_along;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::{LandmarkObs, Run};
use std::collections::HashMap;

/// Sightings at most this far apart in time are seen together (one camera
/// frame), s. Loggers that stamp each detection of a frame on its own differ
/// by microseconds; a robot moves a centimetre or two in this time, far
/// below what a factor-of-2 test on the spacing can notice.
const TOGETHER_S: f64 = 0.02;

/// The longest interval between two sightings of one landmark that the
/// turning check compares, s.
const TURN_WINDOW_S: f64 = 1.0;

/// The least bearing change, as predicted, that a pair of sightings must
/// have to count, rad. This is well above a camera's bearing noise (about
/// 0.01 rad), so the pair's measured change is mostly the turn.
const MIN_TURN_RAD: f64 = 0.05;

/// The fewest pairs either check needs before it says anything.
const MIN_PAIRS: usize = 10;

/// How far apart landmarks seen together are, by their sightings, against
/// the map: the median ratio over every pair seen together.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spacing {
    pub ratio: f64,
    pub pairs: usize,
}

impl Spacing {
    /// Whether the ratio is beyond what a camera's errors can explain. A
    /// range reading a few percent long, or read as depth along the
    /// camera's axis across a wide field of view, moves the ratio a few
    /// tens of percent at most; a factor of 2 is another unit.
    pub fn in_another_unit(&self) -> bool {
        !(0.5..=2.0).contains(&self.ratio)
    }

    /// The units that would explain the ratio, in words, if a common one
    /// does (within 15%).
    pub fn unit_hint(&self) -> Option<String> {
        const UNITS: [(&str, f64); 4] = [
            ("millimetres", 1000.0),
            ("centimetres", 100.0),
            ("inches", 39.37),
            ("feet", 3.281),
        ];
        let near = |r: f64, f: f64| (r / f - 1.0).abs() < 0.15;
        UNITS.iter().find_map(|&(unit, per_m)| {
            if near(self.ratio, per_m) {
                Some(format!("ranges in {unit} against a map in metres?"))
            } else if near(1.0 / self.ratio, per_m) {
                Some(format!("a map in {unit} against ranges in metres?"))
            } else {
                None
            }
        })
    }
}

/// The spacing of the landmarks seen together in `obs` (in time order), or
/// None where fewer than [`MIN_PAIRS`] pairs are seen together.
pub fn spacing(obs: &[LandmarkObs]) -> Option<Spacing> {
    let mut ratios = Vec::new();
    for (k, a) in obs.iter().enumerate() {
        for b in obs[k + 1..].iter().take_while(|b| b.t - a.t <= TOGETHER_S) {
            let mapped = (a.xl - b.xl).hypot(a.yl - b.yl);
            if a.id == b.id || mapped <= 0.0 {
                // one landmark twice, or two ids at one place: no spacing
                continue;
            }
            let squared = a.range.powi(2) + b.range.powi(2)
                - 2.0 * a.range * b.range * (a.bearing - b.bearing).cos();
            ratios.push(squared.max(0.0).sqrt() / mapped);
        }
    }
    let pairs = ratios.len();
    (pairs >= MIN_PAIRS)
        .then(|| typical(ratios))
        .flatten()
        .map(|ratio| Spacing { ratio, pairs })
}

/// How a landmark's measured bearing changes against the change the
/// model predicts, over pairs of sightings of one landmark less than
/// [`TURN_WINDOW_S`] apart: the least-squares slope through the origin.
/// It is 1 for a bearing as the spec predicts it (less where the robot turns
/// less than its model says), and -1 for one of the other sign.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Turning {
    pub slope: f64,
    pub standard_error: f64,
    pub pairs: usize,
}

impl Turning {
    /// Whether the bearings clearly turn the other way: the slope is
    /// negative beyond three standard errors, and by a quarter at least.
    pub fn against(&self) -> bool {
        self.slope < -0.25 && self.slope + 3.0 * self.standard_error < 0.0
    }

    /// Whether the bearings clearly fail to follow the turns: the slope is
    /// within a quarter of 0, and 1 lies beyond three standard errors.
    pub fn unrelated(&self) -> bool {
        self.slope.abs() < 0.25 && self.slope + 3.0 * self.standard_error < 1.0
    }
}

/// The turning check on `run`'s sightings, predicted along the model's dead
/// reckoning at its nominal parameters. None where fewer than
/// [`MIN_PAIRS`] pairs turned enough to count.
pub fn turning(r: &Runner, run: &Run) -> Option<Turning> {
    let track = &tracks(r, &r.p, std::slice::from_ref(run), &[])[0];
    let predicted = predicted_along(r, &r.p, run, track);
    let mut last: HashMap<&str, (f64, f64, f64)> = HashMap::new();
    let mut pairs = Vec::new();
    for (o, h) in run.landmarks.iter().zip(&predicted) {
        let Some(h) = h.filter(|h| h[1].is_finite()) else {
            continue;
        };
        let Some((t0, z0, h0)) = last.insert(&o.id, (o.t, o.bearing, h[1])) else {
            continue;
        };
        let dh = wrap(h[1] - h0);
        if o.t > t0 && o.t - t0 <= TURN_WINDOW_S && dh.abs() >= MIN_TURN_RAD {
            pairs.push((wrap(o.bearing - z0), dh));
        }
    }
    slope_through_origin(&pairs)
}

/// The least-squares slope of measured on predicted changes, (measured,
/// predicted) pairs, with its standard error.
fn slope_through_origin(pairs: &[(f64, f64)]) -> Option<Turning> {
    if pairs.len() < MIN_PAIRS {
        return None;
    }
    let hh: f64 = pairs.iter().map(|(_, h)| h * h).sum();
    let slope = pairs.iter().map(|(z, h)| z * h).sum::<f64>() / hh;
    let rss: f64 = pairs.iter().map(|(z, h)| (z - slope * h).powi(2)).sum();
    let standard_error = (rss / (pairs.len() - 1) as f64 / hh).sqrt();
    Some(Turning {
        slope,
        standard_error,
        pairs: pairs.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sighting at time `t` of landmark `id` at (`xl`, `yl`), read as
    /// `range` and `bearing` from a robot at the origin facing +x.
    fn seen(t: f64, id: &str, (xl, yl): (f64, f64), scale: f64, sign: f64) -> LandmarkObs {
        LandmarkObs {
            t,
            id: id.into(),
            xl,
            yl,
            range: scale * xl.hypot(yl),
            bearing: sign * yl.atan2(xl),
        }
    }

    /// Twelve frames of two landmarks each, read in `scale` times metres.
    fn frames(scale: f64, sign: f64) -> Vec<LandmarkObs> {
        (0..12)
            .flat_map(|k| {
                let t = k as f64;
                let far = 2.0 + 0.1 * k as f64;
                [
                    seen(t, "a", (far, 1.0), scale, sign),
                    seen(t + 0.001, "b", (1.5, -0.5 - 0.05 * k as f64), scale, sign),
                ]
            })
            .collect()
    }

    #[test]
    fn spacing_tells_metres_from_millimetres() {
        let m = spacing(&frames(1.0, 1.0)).expect("12 pairs");
        assert_eq!(m.pairs, 12);
        assert!((m.ratio - 1.0).abs() < 1e-9, "{m:?}");
        assert!(!m.in_another_unit());
        let mm = spacing(&frames(1000.0, 1.0)).expect("12 pairs");
        assert!(mm.in_another_unit(), "{mm:?}");
        assert_eq!(
            mm.unit_hint().as_deref(),
            Some("ranges in millimetres against a map in metres?")
        );
        let map_in_cm = spacing(&frames(0.01, 1.0)).expect("12 pairs");
        assert_eq!(
            map_in_cm.unit_hint().as_deref(),
            Some("a map in centimetres against ranges in metres?")
        );
    }

    #[test]
    fn spacing_needs_landmarks_seen_together() {
        let mut apart = frames(1.0, 1.0);
        for (k, o) in apart.iter_mut().enumerate() {
            o.t = k as f64;
        }
        assert_eq!(spacing(&apart), None);
    }

    #[test]
    fn a_slope_of_the_other_sign_is_against() {
        let pairs = |sign: f64| -> Vec<(f64, f64)> {
            (0..20)
                .map(|k| {
                    let h = 0.1 * if k % 2 == 0 { 1.0 } else { -1.0 };
                    (sign * 0.8 * h + 0.005 * (k % 3) as f64, h)
                })
                .collect()
        };
        let right = slope_through_origin(&pairs(1.0)).expect("20 pairs");
        assert!(!right.against() && !right.unrelated(), "{right:?}");
        let wrong = slope_through_origin(&pairs(-1.0)).expect("20 pairs");
        assert!(wrong.against(), "{wrong:?}");
        let none = slope_through_origin(&pairs(0.0)).expect("20 pairs");
        assert!(none.unrelated() && !none.against(), "{none:?}");
        assert_eq!(slope_through_origin(&pairs(1.0)[..5]), None);
    }
}
