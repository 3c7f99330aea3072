//! 95% bounds of a consistency statistic's mean (NIS, NEES) for a filter
//! that is consistent.
//!
//! A consistent filter's NEES at one row is chi-square with 3 degrees of
//! freedom, but the mean over a run's rows is not that of as many
//! independent values: the estimation error of one row is nearly the
//! error of the next for as long as the filter goes without correcting it.
//! The mean of n values whose series has an integrated autocorrelation time
//! of tau rows varies as much as the mean of n / tau independent ones
//! (Sokal 1997, "Monte Carlo methods in statistical mechanics", eq. 2.20),
//! so the bounds are chi-square's for n / tau values. Counted as
//! independent, MRCLAM robot 1's 760 s run of 49,235 rows has NEES bounds
//! 2.98-3.02; its errors lasting about 16 s, the rows are worth 27
//! independent values and the bounds are 2.15-3.99. A consistent filter's innovations are white, so the
//! NIS's tau is near 1 and its bounds barely move; a filter whose
//! innovations linger gets bounds as wide as its evidence is thin.

/// 95% bounds of a statistic's mean, and how many independent values the
/// series it averages is worth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    pub lo: f64,
    pub hi: f64,
    /// The values' count over their integrated autocorrelation time (the
    /// count itself for a white series).
    pub independent: f64,
}

/// Chi-square quantile (Wilson-Hilferty; within 1% for k >= 3): the p-quantile
/// of a chi-square variable with k degrees of freedom, for the z-score of p.
pub fn chi2_quantile(k: f64, z: f64) -> f64 {
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + z * a.sqrt()).powi(3)
}

/// 95% bounds of the mean of n independent chi-square values with `dof`
/// degrees of freedom (n need not be whole: see [`Bounds::of_series`]).
pub fn mean_bounds(n: f64, dof: f64) -> (f64, f64) {
    let k = n * dof;
    (
        chi2_quantile(k, -1.959964) / n,
        chi2_quantile(k, 1.959964) / n,
    )
}

impl Bounds {
    /// The bounds of the mean of `n` independent values.
    pub fn independent(n: usize, dof: f64) -> Bounds {
        let (lo, hi) = mean_bounds(n as f64, dof);
        Bounds {
            lo,
            hi,
            independent: n as f64,
        }
    }

    /// The bounds of the mean of `series` (chi-square values with `dof`
    /// degrees of freedom, in time order), counting how long its values stay
    /// alike. None for an empty series.
    pub fn of_series(series: &[f64], dof: f64) -> Option<Bounds> {
        if series.is_empty() {
            return None;
        }
        let n = series.len() as f64;
        // at least one value, and never more than there are
        let independent = (n / correlation_time(series)).clamp(1.0, n);
        let (lo, hi) = mean_bounds(independent, dof);
        Some(Bounds {
            lo,
            hi,
            independent,
        })
    }
}

/// Sokal's window: the autocorrelation is summed up to the first lag M with
/// M >= C * tau(M), where the sum's noise has not yet swamped it (Sokal
/// 1997, section 3; emcee's `integrated_time` uses the same rule and C).
const SOKAL_WINDOW: f64 = 5.0;

/// The integrated autocorrelation time of `x` in samples, 1 + 2 * (the sum
/// of its autocorrelation over lags 1..M, M by [`SOKAL_WINDOW`]); at least 1
/// (a series anticorrelated at short lags is not counted as worth more
/// values than it has). 1 for a series too short or constant to tell.
pub fn correlation_time(x: &[f64]) -> f64 {
    let rho = autocorrelation(x);
    if rho.len() < 2 {
        return 1.0;
    }
    let mut tau = 1.0;
    for (m, r) in rho.iter().enumerate().skip(1) {
        tau += 2.0 * r;
        if m as f64 >= SOKAL_WINDOW * tau {
            return tau.max(1.0);
        }
    }
    // no window short enough: the series is shorter than its own memory
    tau.max(1.0)
}

/// The normalised autocorrelation of `x` at lags 0..n (empty for a series of
/// under two values or a constant one), through the FFT: a direct sum over
/// every lag would take seconds on an hour's rows.
fn autocorrelation(x: &[f64]) -> Vec<f64> {
    let n = x.len();
    // a non-finite value has no autocorrelation (the FFT would panic on it)
    if n < 2 || x.iter().any(|v| !v.is_finite()) {
        return Vec::new();
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    // zero-padded to twice the length: the circular correlation is then the
    // linear one
    let size = (2 * n).next_power_of_two();
    let mut planner = realfft::RealFftPlanner::<f64>::new();
    let (forward, inverse) = (
        planner.plan_fft_forward(size),
        planner.plan_fft_inverse(size),
    );
    let mut buffer: Vec<f64> = x.iter().map(|v| v - mean).collect();
    buffer.resize(size, 0.0);
    let mut spectrum = forward.make_output_vec();
    forward
        .process(&mut buffer, &mut spectrum)
        .expect("buffers sized by their own plan");
    spectrum.iter_mut().for_each(|c| *c *= c.conj());
    let mut acf = inverse.make_output_vec();
    inverse
        .process(&mut spectrum, &mut acf)
        .expect("buffers sized by their own plan");
    let zero = acf[0];
    if zero <= 0.0 || !zero.is_finite() {
        return Vec::new();
    }
    acf.truncate(n);
    acf.iter().map(|v| v / zero).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    #[test]
    fn chi_square_bounds_bracket_the_degrees_of_freedom() {
        let (lo, hi) = mean_bounds(100.0, 2.0);
        assert!(lo < 2.0 && hi > 2.0 && (hi - lo) < 1.2, "{lo} {hi}");
        // 95% of chi2(30): 16.79 .. 46.98
        assert!((chi2_quantile(30.0, -1.959964) - 16.79).abs() < 0.3);
        assert!((chi2_quantile(30.0, 1.959964) - 46.98).abs() < 0.3);
    }

    /// An AR(1) series with coefficient `a`: its integrated autocorrelation
    /// time is (1 + a) / (1 - a).
    fn ar1(n: usize, a: f64, seed: u64) -> Vec<f64> {
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut v = 0.0;
        (0..n)
            .map(|_| {
                v = a * v + rng.gen_range(-1.0..1.0);
                v
            })
            .collect()
    }

    #[test]
    fn a_series_is_worth_its_length_over_its_memory() {
        // white: worth (nearly) every value
        let white = correlation_time(&ar1(20_000, 0.0, 1));
        assert!((0.9..1.2).contains(&white), "white: {white}");
        // a = 0.9: tau = 19
        let slow = correlation_time(&ar1(50_000, 0.9, 2));
        assert!((15.0..23.0).contains(&slow), "AR(1) 0.9: {slow}");
        // too short or constant to tell
        assert_eq!(correlation_time(&[1.0]), 1.0);
        assert_eq!(correlation_time(&[2.0; 50]), 1.0);
    }

    #[test]
    fn lingering_values_widen_the_bounds() {
        // chi-square(1) values from a slowly varying error: e^2 with e AR(1)
        let e = ar1(40_000, 0.98, 3);
        let var = e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64;
        let nees: Vec<f64> = e.iter().map(|v| v * v / var).collect();
        let b = Bounds::of_series(&nees, 1.0).unwrap();
        let (lo, hi) = mean_bounds(nees.len() as f64, 1.0);
        assert!(b.independent < 0.05 * nees.len() as f64, "{b:?}");
        assert!(b.lo < lo && b.hi > hi && b.lo < 1.0 && b.hi > 1.0, "{b:?}");
        assert!(Bounds::of_series(&[], 2.0).is_none());
    }
}
