//! Robust statistics of residuals: a median and a standard deviation that a
//! few outliers (a misread barcode, a landmark half hidden) do not move.
//! Hand-written: two sorts, not worth a statistics crate.

/// The median of `v` (the upper one of an even count; 0 for none). Sorts
/// `v` in place.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// 1.4826 times the median absolute deviation from the median: a Gaussian's
/// standard deviation, unmoved by outliers (0 for none or no spread).
pub fn robust_sd(v: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = v.collect();
    let med = median(&mut v);
    let mut dev: Vec<f64> = v.iter().map(|x| (x - med).abs()).collect();
    1.4826 * median(&mut dev)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_outlier_does_not_move_the_robust_sd() {
        let v = [-1.0, -0.5, 0.0, 0.5, 1.0];
        let with = [-1.0, -0.5, 0.0, 0.5, 1.0e6];
        assert_eq!(robust_sd(v.into_iter()), robust_sd(with.into_iter()));
        assert!((robust_sd(v.into_iter()) - 1.4826 * 0.5).abs() < 1e-12);
        assert_eq!(robust_sd(std::iter::empty()), 0.0);
    }
}
