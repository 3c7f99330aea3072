//! The gate's rejections against a consistent filter's: the NIS's tail.
//!
//! The mean NIS counts only the sightings the gate let through. A filter
//! whose innovations are small most of the time and far too large at times
//! (heavier tails than its Gaussian) has a low mean NIS over what it let
//! through, and reads as pessimistic, while its gate rejects many times the
//! share a consistent filter's would: the rejections are the NIS's own
//! evidence of overconfidence, which its mean hides. On the MRCLAM robots
//! the 99.9% gate rejects 1.0-2.3% of the sightings, 10-23 times the 0.1% a
//! consistent filter rejects, while the mean NIS of the rest is below its
//! bounds on all five.
//!
//! Rejections come in bursts (a filter far off rejects several sightings in
//! a row), so the bound on their share counts the sightings as the NIS
//! series' independent ones ([`super::Bounds::independent`]).
use statrs::distribution::{ChiSquared, ContinuousCDF, DiscreteCDF, Poisson};

/// How many sightings the gate rejected, against a consistent filter's
/// share.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateTail {
    pub rejected: usize,
    /// Sightings the gate judged: those it let through and those it
    /// rejected.
    pub judged: usize,
    /// The share a consistent filter rejects: chi-square's tail beyond the
    /// gate.
    pub expected: f64,
    /// The largest share a consistent filter rejects by chance, 95% one-sided.
    pub bound: f64,
}

impl GateTail {
    /// The tail of `judged` sightings of `dof` degrees of freedom, `rejected`
    /// of them beyond `gate`, the sightings worth `independent` independent
    /// ones. None without sightings or with a gate that is not a number.
    pub fn new(
        rejected: usize,
        judged: usize,
        gate: f64,
        dof: f64,
        independent: f64,
    ) -> Option<GateTail> {
        if judged == 0 || !gate.is_finite() || gate <= 0.0 {
            return None;
        }
        let expected = ChiSquared::new(dof).ok()?.sf(gate);
        // rejections among n independent sightings: Poisson with mean
        // n * expected (the share is small); a burst of rejections counts as
        // the independent sightings it spans
        let n = independent.clamp(1.0, judged as f64);
        let most = poisson_95(n * expected)? as f64;
        Some(GateTail {
            rejected,
            judged,
            expected,
            bound: (most / n).max(expected),
        })
    }

    /// The share of the judged sightings the gate rejected.
    pub fn share(&self) -> f64 {
        self.rejected as f64 / self.judged as f64
    }

    /// More rejected than a consistent filter rejects by chance: the
    /// innovations' tail is heavier than the filter's covariance says.
    pub fn overconfident(&self) -> bool {
        self.share() > self.bound
    }
}

/// The 95% point of a Poisson count of mean `lambda`: the least k with
/// P(X <= k) >= 0.95 (0 for a mean of 0; None for one that is not a
/// number). Counted up from the mean, at most a few standard deviations:
/// statrs's own `inverse_cdf` (0.18) panics where the answer is 0, a mean
/// under 0.051 (a run of a few dozen sightings).
fn poisson_95(lambda: f64) -> Option<u64> {
    if !lambda.is_finite() || lambda < 0.0 {
        return None;
    }
    let Ok(p) = Poisson::new(lambda) else {
        // a gate so far out that a consistent filter rejects nothing
        return Some(0);
    };
    let mut k = lambda.floor() as u64;
    while p.cdf(k) < 0.95 {
        k += 1;
    }
    Some(k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_consistent_filters_rejections_are_within_the_bound() {
        // the 99.9% gate of 2 degrees of freedom: 0.1% expected
        let t = GateTail::new(1, 1500, 13.82, 2.0, 1500.0).unwrap();
        assert!((t.expected - 0.001).abs() < 1e-5, "{t:?}");
        // 1.5 expected among 1500: at most 4 by chance (P(X > 4) = 1.9%)
        assert!((t.bound - 4.0 / 1500.0).abs() < 1e-12, "{t:?}");
        assert!(!t.overconfident());
        assert!(!GateTail::new(4, 1500, 13.82, 2.0, 1500.0)
            .unwrap()
            .overconfident());
        // MRCLAM robot 1: 16 of 1534, the sightings worth 581 independent
        let r1 = GateTail::new(16, 1534, 13.82, 2.0, 581.0).unwrap();
        assert!(r1.overconfident(), "{r1:?}");
    }

    #[test]
    fn bursts_of_rejections_are_counted_as_the_sightings_they_span() {
        // 6 of 1500 is beyond chance for independent sightings, not for
        // sightings worth 100 independent ones
        assert!(GateTail::new(6, 1500, 13.82, 2.0, 1500.0)
            .unwrap()
            .overconfident());
        let burst = GateTail::new(6, 1500, 13.82, 2.0, 100.0).unwrap();
        assert!(!burst.overconfident(), "{burst:?}");
        assert!(GateTail::new(0, 0, 13.82, 2.0, 1.0).is_none());
        assert!(GateTail::new(0, 10, f64::NAN, 2.0, 1.0).is_none());
        // every count of sightings, small to large, has a bound
        for judged in [1, 7, 100, 2_500, 1_000_000] {
            let t = GateTail::new(judged / 2, judged, 13.82, 2.0, judged as f64).unwrap();
            assert!(
                t.bound >= t.expected && t.bound.is_finite(),
                "{judged}: {t:?}"
            );
        }
    }

    #[test]
    fn poissons_95_point_is_the_least_count_at_95_percent() {
        assert_eq!(poisson_95(0.0), Some(0));
        // a mean under 0.051: 0 (where statrs's `inverse_cdf` panics)
        assert_eq!(poisson_95(0.01), Some(0));
        // mean 1.5: P(X <= 3) = 0.934, P(X <= 4) = 0.981
        assert_eq!(poisson_95(1.5), Some(4));
        // mean 1000: about 1000 + 1.645 sqrt(1000) = 1052
        assert!((1050..=1054).contains(&poisson_95(1000.0).unwrap()));
        assert_eq!(poisson_95(f64::NAN), None);
    }
}
