//! One localised run's figures: position RMSE of the filter, of the
//! smoother and of dead reckoning against the ground truth, the mean NIS and
//! NEES with their chi-square bounds, and how their values spread (median,
//! share in the tail), which tells a filter wrong at times from one wrong
//! throughout.
use super::{chi2_quantile, nees_of, truth_noise, Bounds, GateTail, Localization, Nees, Sensed};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;

/// One run's figures: errors against ground truth, consistency.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub rmse: Option<f64>,
    pub dead_reckoning: Option<f64>,
    pub nis: Option<f64>,
    pub nis_bounds: Option<Bounds>,
    /// The gate's rejections against a consistent filter's: the NIS's tail,
    /// which its mean over the sightings let through does not count.
    pub gate_tail: Option<GateTail>,
    pub nees: Option<f64>,
    pub nees_bounds: Option<Bounds>,
    /// The smoother's figures (with `--smooth`).
    pub smoothed: Option<SmoothedSummary>,
    /// The ground truth's own noise the NEES counts ([`truth_noise`]), when
    /// there is a NEES.
    pub truth_noise: Option<[f64; 3]>,
    pub nis_spread: Option<Spread>,
    pub nees_spread: Option<Spread>,
    /// The NEES taken apart, when there is one.
    pub nees_parts: Option<NeesParts>,
}

/// The smoother's figures: its errors last longer than the filter's (each
/// estimate leans on the motion from both sides), so its NEES has bounds of
/// its own.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmoothedSummary {
    pub rmse: Option<f64>,
    pub nees: Option<f64>,
    pub nees_bounds: Option<Bounds>,
}

/// The NEES taken apart: which of the filter's beliefs is wrong, and when.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NeesParts {
    /// Mean NEES of the position alone (2 degrees of freedom) and its 95%
    /// bounds.
    pub position: (f64, Bounds),
    /// The same for the heading alone (1 degree of freedom).
    pub heading: (f64, Bounds),
    /// Mean NEES of the pose over the half of the rows nearest in time
    /// after a sighting the filter used, and over the other half (rows
    /// before the first sighting among them): a filter whose sightings
    /// place it more tightly than they should is most overconfident just
    /// after them; one whose motion errs more than its noise says, far from
    /// them.
    pub near_sightings: f64,
    pub far_from_sightings: f64,
}

/// Which of the filter's beliefs its NEES finds overconfident.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Overconfident {
    /// The heading (with the position or not).
    Heading,
    /// The position alone, most just after the sightings.
    PositionNearSightings,
    /// The position alone, most far from the sightings.
    PositionFarFromSightings,
    /// The position alone, as much near the sightings as far from them.
    Position,
}

/// One half's mean NEES must exceed the other's by this factor for the
/// report to say the filter is overconfident "most" in that half (a word,
/// not a test: the rows are far from independent).
const HALF_CONTRAST: f64 = 1.25;

impl NeesParts {
    /// The parts of `nees`, the NEES of a run with row times `t` and whose
    /// used sightings came at `sightings` (s, in time order).
    /// None with fewer than two rows (no halves to compare).
    pub fn of(nees: &[Nees], t: &[f64], sightings: &[f64]) -> Option<NeesParts> {
        if nees.len() < 2 {
            return None;
        }
        let position = mean(nees.iter().map(|n| n.position))?;
        let heading = mean(nees.iter().map(|n| n.heading))?;
        // time since the last sighting used, at each row
        let since = |n: &Nees| {
            let at = t[n.row];
            match sightings.partition_point(|&s| s <= at) {
                0 => f64::INFINITY,
                i => at - sightings[i - 1],
            }
        };
        let mut by_time: Vec<(f64, f64)> = nees.iter().map(|n| (since(n), n.pose)).collect();
        by_time.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (near, far) = by_time.split_at(by_time.len() / 2);
        let series = |part: fn(&Nees) -> f64| nees.iter().map(part).collect::<Vec<_>>();
        Some(NeesParts {
            position: (position, Bounds::of_series(&series(|n| n.position), 2.0)?),
            heading: (heading, Bounds::of_series(&series(|n| n.heading), 1.0)?),
            near_sightings: mean(near.iter().map(|x| x.1))?,
            far_from_sightings: mean(far.iter().map(|x| x.1))?,
        })
    }

    /// The belief the parts find overconfident (None: neither part's mean
    /// lies above its bounds).
    pub fn overconfident(&self) -> Option<Overconfident> {
        let above = |(m, b): (f64, Bounds)| side(Some(m), Some(b)) == Some(Side::Above);
        if above(self.heading) {
            return Some(Overconfident::Heading);
        }
        if !above(self.position) {
            return None;
        }
        let (near, far) = (self.near_sightings, self.far_from_sightings);
        Some(if near > HALF_CONTRAST * far {
            Overconfident::PositionNearSightings
        } else if far > HALF_CONTRAST * near {
            Overconfident::PositionFarFromSightings
        } else {
            Overconfident::Position
        })
    }
}

/// How a consistency statistic's values spread against their chi-square
/// law. Its mean alone is dominated by its largest values: a filter right
/// within its covariance most of the time and far off at times can have a
/// mean above the bounds while most values lie below chi-square's median.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    pub median: f64,
    /// Chi-square's median for the statistic's degrees of freedom.
    pub chi2_median: f64,
    /// The share of values beyond chi-square's 95% point (0.05 for a
    /// consistent filter).
    pub beyond_95: f64,
    pub point_95: f64,
}

/// Chi-square's median and 95% point: exact for 2 degrees of freedom (a
/// range-bearing sighting's NIS), Wilson-Hilferty otherwise (within 1% for
/// 3, a planar pose's NEES).
fn chi2_points(dof: f64) -> (f64, f64) {
    if dof == 2.0 {
        (2.0 * std::f64::consts::LN_2, -2.0 * 0.05f64.ln())
    } else {
        (chi2_quantile(dof, 0.0), chi2_quantile(dof, 1.644854))
    }
}

/// The spread of `values` (NIS or NEES) against chi-square with `dof`
/// degrees of freedom; None without values.
pub fn spread(values: impl Iterator<Item = f64>, dof: f64) -> Option<Spread> {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let (chi2_median, point_95) = chi2_points(dof);
    let beyond = v.iter().filter(|&&x| x > point_95).count();
    Some(Spread {
        median: v[v.len() / 2],
        chi2_median,
        beyond_95: beyond as f64 / v.len() as f64,
        point_95,
    })
}

/// What NIS and NEES say together about the filter's covariance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Consistency {
    /// Their means do not contradict each other.
    Agree,
    /// Their means contradict each other while their medians agree on the
    /// side given (true: pessimistic) and their tails are heavier than
    /// chi-square's: right within the covariance most of the time, far off
    /// at times (errors with heavier tails than the filter's Gaussian).
    HeavyTails { pessimistic_core: bool },
    /// Their means contradict each other and so do their medians: the
    /// observation errors and the motion's noise are out of balance.
    Contradict,
}

/// Where a consistency statistic's mean lies against its 95% bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Below: the filter is pessimistic.
    Below,
    Within,
    /// Above: the filter is overconfident.
    Above,
}

/// The side of its 95% `bounds` that `mean` lies on (None without either).
pub fn side(mean: Option<f64>, bounds: Option<Bounds>) -> Option<Side> {
    let (m, b) = (mean?, bounds?);
    Some(if m < b.lo {
        Side::Below
    } else if m > b.hi {
        Side::Above
    } else {
        Side::Within
    })
}

impl Summary {
    /// The belief the NEES's parts find overconfident, where the pose's mean
    /// NEES is above its bounds (None otherwise).
    pub fn overconfident_part(&self) -> Option<Overconfident> {
        (side(self.nees, self.nees_bounds) == Some(Side::Above))
            .then(|| self.nees_parts?.overconfident())
            .flatten()
    }

    /// The mean NIS says pessimistic and the NEES overconfident, while the
    /// gate rejected more than a consistent filter would: the NIS's own tail
    /// agrees with the NEES.
    pub fn tail_sides_with_the_nees(&self) -> bool {
        side(self.nis, self.nis_bounds) == Some(Side::Below)
            && side(self.nees, self.nees_bounds) == Some(Side::Above)
            && self.gate_tail.is_some_and(|g| g.overconfident())
    }

    /// What NIS and NEES say together (None without a NEES).
    pub fn consistency(&self) -> Option<Consistency> {
        let (nis, nees) = (self.nis_spread?, self.nees_spread?);
        let opposite = matches!(
            (
                side(self.nis, self.nis_bounds),
                side(self.nees, self.nees_bounds)
            ),
            (Some(Side::Below), Some(Side::Above)) | (Some(Side::Above), Some(Side::Below))
        );
        if !opposite {
            return Some(Consistency::Agree);
        }
        let below = |s: Spread| s.median < s.chi2_median;
        let heavy = |s: Spread| s.beyond_95 > 0.05;
        Some(
            if below(nis) == below(nees) && (heavy(nis) || heavy(nees)) {
                Consistency::HeavyTails {
                    pessimistic_core: below(nis),
                }
            } else {
                Consistency::Contradict
            },
        )
    }
}

/// Position RMSE of `track` against the run's ground truth, if it has one,
/// where the motion capture sees the robot ([`Sensed`]), over the rows that
/// have it (the motion capture may lose the robot).
pub fn position_rmse(r: &Runner, run: &Run, track: &[[f64; 3]]) -> Option<f64> {
    let g = run.gt.as_ref()?;
    let sensor = Sensed::new(r, run);
    let (n, s) = track
        .iter()
        .zip(g)
        .enumerate()
        .filter(|(_, (_, g))| g[0].is_finite() && g[1].is_finite())
        .fold((0usize, 0.0), |(n, s), (k, (x, g))| {
            let m = sensor.at(k, x).0;
            (n + 1, s + (m[0] - g[0]).powi(2) + (m[1] - g[1]).powi(2))
        });
    (n > 0).then(|| (s / n as f64).sqrt())
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let (n, s) = v.fold((0usize, 0.0), |(n, s), x| (n + 1, s + x));
    (n > 0).then(|| s / n as f64)
}

/// The figures of `loc`, the filter's output on `run`.
pub fn summarise(r: &Runner, run: &Run, loc: &Localization) -> Summary {
    // dead reckoning from the filter's start, scored as the filter is (the
    // same figure as `evaluate`'s to rounding, and it skips the rows where
    // the motion capture lost the robot)
    let dead_reckoning = position_rmse(
        r,
        run,
        &crate::model_on_log::deadreckon::run(r, &r.p, run, false).pose,
    );
    let smoothed = loc.smoothed.as_ref().map(|(track, cov)| {
        let nees: Vec<f64> = nees_of(r, run, track, cov).iter().map(|n| n.pose).collect();
        SmoothedSummary {
            rmse: position_rmse(r, run, track),
            nees: mean(nees.iter().copied()),
            nees_bounds: Bounds::of_series(&nees, 3.0),
        }
    });
    let nis_bounds = Bounds::of_series(&loc.nis.iter().map(|n| n.1).collect::<Vec<_>>(), 2.0);
    Summary {
        rmse: position_rmse(r, run, &loc.track),
        dead_reckoning,
        nis: mean(loc.nis.iter().map(|n| n.1)),
        nis_bounds,
        gate_tail: gate_tail(loc, nis_bounds),
        nees: mean(loc.nees.iter().map(|n| n.pose)),
        truth_noise: truth_noise(run).filter(|_| !loc.nees.is_empty()),
        nees_bounds: Bounds::of_series(&loc.nees.iter().map(|n| n.pose).collect::<Vec<_>>(), 3.0),
        nis_spread: spread(loc.nis.iter().map(|n| n.1), 2.0),
        nees_spread: spread(loc.nees.iter().map(|n| n.pose), 3.0),
        nees_parts: NeesParts::of(
            &loc.nees,
            &run.t,
            &loc.nis.iter().map(|n| n.0).collect::<Vec<_>>(),
        ),
        smoothed,
    }
}

/// The gate's rejections in `loc` against a consistent filter's, the
/// judged sightings worth as many independent ones, in proportion, as the
/// NIS of those let through (`nis_bounds`).
fn gate_tail(loc: &Localization, nis_bounds: Option<Bounds>) -> Option<GateTail> {
    let judged = loc.accepted + loc.rejected;
    let worth = nis_bounds.map_or(1.0, |b| b.independent / loc.nis.len().max(1) as f64);
    GateTail::new(loc.rejected, judged, loc.gate, 2.0, judged as f64 * worth)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Chi-square with 2 degrees of freedom at evenly spaced probabilities:
    /// its law, without sampling noise.
    fn chi2_2(n: usize, scale: f64) -> Vec<f64> {
        (0..n)
            .map(|i| -2.0 * scale * (1.0 - (i as f64 + 0.5) / n as f64).ln())
            .collect()
    }

    /// A summary whose NIS and NEES are the given values (NEES taken as 3
    /// degrees of freedom, as localisation counts it).
    fn summary_of(nis: &[f64], nees: &[f64]) -> Summary {
        let m = |v: &[f64]| mean(v.iter().copied());
        Summary {
            rmse: None,
            dead_reckoning: None,
            nis: m(nis),
            // the values sorted, not a time series: counted as independent
            nis_bounds: Some(Bounds::independent(nis.len(), 2.0)),
            gate_tail: None,
            nees: m(nees),
            nees_bounds: Some(Bounds::independent(nees.len(), 3.0)),
            smoothed: None,
            truth_noise: None,
            nis_spread: spread(nis.iter().copied(), 2.0),
            nees_spread: spread(nees.iter().copied(), 3.0),
            nees_parts: None,
        }
    }

    #[test]
    fn a_consistent_statistic_spreads_as_chi_square() {
        let s = spread(chi2_2(2000, 1.0).into_iter(), 2.0).unwrap();
        assert!((s.median / s.chi2_median - 1.0).abs() < 0.01, "{s:?}");
        assert!((s.beyond_95 - 0.05).abs() < 0.002, "{s:?}");
        // 3 degrees of freedom: Wilson-Hilferty within 1% of the tables
        let (median, p95) = chi2_points(3.0);
        assert!((median / 2.366 - 1.0).abs() < 0.01 && (p95 / 7.815 - 1.0).abs() < 0.01);
    }

    /// Rows one second apart, sightings every tenth second: the rows just
    /// after a sighting (0-4 s since) and the others (5-9 s since) carry
    /// `near` and `far` times chi-square's law in their position part, the
    /// heading `heading` times its.
    fn parts_of(near: f64, far: f64, heading: f64) -> Option<Overconfident> {
        let n = 2000;
        let (p2, h1) = (chi2_2(n, 1.0), chi2_2(n, 0.5));
        let t: Vec<f64> = (0..n).map(|k| k as f64).collect();
        let sightings: Vec<f64> = (0..n).step_by(10).map(|k| k as f64).collect();
        let nees: Vec<Nees> = (0..n)
            .map(|k| {
                // chi-square's law shuffled (1 degree of freedom: half of
                // 2), so that the series is as white as a consistent
                // filter's, which its bounds count
                let position = p2[(k * 6007) % n] * if k % 10 < 5 { near } else { far };
                let heading = h1[(k * 7919) % n] * heading;
                Nees {
                    row: k,
                    pose: position + heading,
                    position,
                    heading,
                }
            })
            .collect();
        let parts = NeesParts::of(&nees, &t, &sightings).unwrap();
        let (m, b) = parts.heading;
        assert!(
            m > b.lo / 1.1 * heading && m < b.hi * 1.1 * heading,
            "{parts:?}"
        );
        parts.overconfident()
    }

    #[test]
    fn the_nees_parts_name_the_belief_that_is_overconfident() {
        assert_eq!(parts_of(1.0, 1.0, 1.0), None);
        assert_eq!(
            parts_of(3.0, 1.0, 0.5),
            Some(Overconfident::PositionNearSightings)
        );
        assert_eq!(
            parts_of(1.0, 3.0, 0.5),
            Some(Overconfident::PositionFarFromSightings)
        );
        assert_eq!(parts_of(2.0, 2.0, 0.5), Some(Overconfident::Position));
        assert_eq!(parts_of(1.0, 1.0, 2.0), Some(Overconfident::Heading));
        // one row has no halves: no parts rather than a NaN half
        let one = Nees {
            row: 0,
            pose: 3.0,
            position: 2.0,
            heading: 1.0,
        };
        assert_eq!(NeesParts::of(&[one], &[0.0], &[0.0]), None);
    }

    #[test]
    fn means_that_contradict_each_other_are_read_through_the_medians() {
        // pessimistic throughout: NIS at half its law; NEES the same, far off
        // in a fifth of the rows (heavy tails): its mean overconfident
        let nis = chi2_2(2000, 0.5);
        let mut nees = chi2_2(2000, 0.6);
        for (i, x) in nees.iter_mut().enumerate() {
            if i % 5 == 0 {
                *x *= 12.0;
            }
        }
        let s = summary_of(&nis, &nees);
        assert!(s.nees.unwrap() > s.nees_bounds.unwrap().hi, "{s:?}");
        assert_eq!(
            s.consistency(),
            Some(Consistency::HeavyTails {
                pessimistic_core: true
            })
        );
        // the NEES overconfident in its median too: a contradiction
        let nees = chi2_2(2000, 2.0);
        assert_eq!(
            summary_of(&nis, &nees).consistency(),
            Some(Consistency::Contradict)
        );
        // both pessimistic: they agree
        assert_eq!(
            summary_of(&nis, &chi2_2(2000, 0.5)).consistency(),
            Some(Consistency::Agree)
        );
    }
}
