//! The filter's noise as data: the process-noise sigmas, the observation
//! sigmas' factors, the lingering parts of the observation errors and the
//! sensor's range reading. What the filter runs with; [`super::noise`]
//! estimates it (with the filter), so this module needs neither.
use super::reading::RangeReading;

/// Where the filter's noise comes from when the user does not give all of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseSource {
    /// The spec's `[[noise]]` sigmas and observation sigmas as written.
    Spec,
    /// Estimated from the log (see the module documentation).
    Estimate,
}

/// The noise of one filter: one sigma per process-noise input (the spec's
/// `[[noise]]`, or the body twist's vx, vy, omega for a model without any),
/// and a factor on each of the observation's declared sigmas (range and
/// bearing: a camera's range is often ten times worse than its bearing
/// relative to what a spec guesses, so one common factor cannot fit both).
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseModel {
    pub names: Vec<String>,
    pub sigma: Vec<f64>,
    /// Whether `sigma[i]` is a density (variance sigma^2 per second) rather
    /// than seed 001's per-row sigma.
    pub density: Vec<bool>,
    pub obs_scale: [f64; 2],
    /// The part of each observation error that lasts minutes (a camera's
    /// range and bearing errors stay alike when it sees one landmark from
    /// about one place).
    pub persistent: Lingering,
    /// The part every landmark shares, lasting seconds: the camera's own
    /// (against Vicon, the bearing errors of two landmarks in one frame of
    /// the MRCLAM robots' cameras correlate 0.68-0.87, their range errors
    /// per metre 0.43-0.70, and a frame's errors last some seconds).
    pub shared: Lingering,
    /// How the sensor reads range (not noise, but estimated with it: the
    /// likelihood cannot tell a reading's bias from noise unless it is given
    /// the choice).
    pub range_reading: RangeReading,
}

/// A part of the observation errors that lingers (a first-order
/// Gauss-Markov process per landmark, or one for all: see
/// [`super::belief`]): a factor on
/// each of the spec's sigmas and how long it lasts. The range's part grows
/// with the range: it is this factor on the spec's range sigma per metre of
/// range (a camera that ranges by a target's apparent size errs in
/// proportion: on the MRCLAM robots the spread of the range error is about
/// 4% of the range from 1 to 5 m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lingering {
    /// [range per metre, bearing]; 0: no such part.
    pub factor: [f64; 2],
    /// How long (s) it lasts.
    pub memory_s: f64,
}

impl Lingering {
    /// No lingering error (white sightings), with a memory to start an
    /// estimate from.
    pub const fn none(memory_s: f64) -> Lingering {
        Lingering {
            factor: [0.0; 2],
            memory_s,
        }
    }

    pub fn is_none(&self) -> bool {
        self.factor.iter().all(|f| *f <= 0.0)
    }
}

/// Where an estimate of the persistent and shared parts' memories starts (s).
pub const PERSISTENT_START_S: f64 = 10.0;
pub const SHARED_START_S: f64 = 1.0;

impl NoiseModel {
    /// White noise on the body twist, for a model that declares none: 0.05 m/s
    /// and 0.05 rad/s per sqrt(Hz), a start for estimation.
    pub fn twist_default() -> NoiseModel {
        NoiseModel {
            names: vec!["twist_vx".into(), "twist_vy".into(), "twist_omega".into()],
            sigma: vec![0.05; 3],
            density: vec![true; 3],
            obs_scale: [1.0; 2],
            persistent: Lingering::none(PERSISTENT_START_S),
            shared: Lingering::none(SHARED_START_S),
            range_reading: RangeReading::STRAIGHT,
        }
    }

    /// The variance of noise input `i` held over `h` seconds of a row of
    /// `dt_row` seconds. A density q gives q/h (white noise averaged over h:
    /// the pose variance G q/h G^T grows as q h, whatever the log's rate). A
    /// per-row sigma is seed 001's variance per row: spread over the pieces a
    /// sighting cuts the row into, so the row adds the same as uncut.
    pub fn step_variance(&self, i: usize, h: f64, dt_row: f64) -> f64 {
        let s2 = self.sigma[i] * self.sigma[i];
        if self.density[i] {
            s2 / h
        } else {
            s2 * dt_row / h
        }
    }

    /// A line per sigma, for people: the observation errors in metres and
    /// radians, and as the factors on `base`, the observation's range and
    /// bearing sigmas ([`crate::model_on_log::landmarks::sigma`]), which are `whose`
    /// ("the spec's", or the defaults' where the spec gives none).
    pub fn describe(&self, base: [f64; 2], whose: &str) -> Vec<String> {
        let mut out: Vec<String> = self
            .names
            .iter()
            .zip(&self.sigma)
            .zip(&self.density)
            .map(|((n, s), d)| {
                if *d {
                    format!(
                        "{n} = {s:.4e} per sqrt(s) (density: variance {:.3e} per second)",
                        s * s
                    )
                } else {
                    format!("{n} = {s:.4e} per row (a sigma per log row)")
                }
            })
            .collect();
        let [range, bearing] = base;
        out.push(format!(
            "observation sigmas, white part: {:.4} m (range) and {:.4} rad (bearing), {whose} {range} m and {bearing} rad times {:.3} and {:.3}",
            range * self.obs_scale[0],
            bearing * self.obs_scale[1],
            self.obs_scale[0],
            self.obs_scale[1]
        ));
        let parts = [
            ("persistent", "per landmark", &self.persistent),
            ("shared", "one for every landmark", &self.shared),
        ];
        for (what, which, part) in parts {
            if !part.is_none() {
                out.push(format!(
                    "observation errors, {what} part ({which}, lasting about {}): {:.4} m per metre of range and {:.4} rad of bearing, {whose} sigmas times {:.3} and {:.3}",
                    seconds(part.memory_s),
                    range * part.factor[0],
                    bearing * part.factor[1],
                    part.factor[0],
                    part.factor[1]
                ));
            }
        }
        let r = &self.range_reading;
        if !r.is_straight() {
            let [(share, share_v), (scale, scale_v)] = r.parameters();
            out.push(format!(
                "range read as {:.0}% depth along the sensor's axis, {:+.1}% long (the catalogue's {}: {share} = {share_v:.3}, {scale} = {scale_v:.4})",
                100.0 * r.depth_share,
                100.0 * r.scale,
                RangeReading::EFFECT,
            ));
        }
        out
    }
}

/// A duration for people: whole seconds from 10 s, two digits below.
fn seconds(s: f64) -> String {
    if s >= 10.0 {
        format!("{s:.0} s")
    } else {
        format!("{s:.2} s")
    }
}
