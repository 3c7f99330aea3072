//! Linear interpolation between rows, and the chain rule through it.
//!
//! A measurement taken between two rows (a delayed pose, a landmark seen
//! mid-step) is compared with the model's pose interpolated to its time, and
//! its derivative with respect to the parameters is the observation's Jacobian
//! applied to the interpolated sensitivities. Every such place uses these.

/// `a + t (b - a)`, per component.
pub fn lerp3(a: &[f64; 3], b: &[f64; 3], t: f64) -> [f64; 3] {
    [0, 1, 2].map(|i| a[i] + t * (b[i] - a[i]))
}

/// `a + t (b - a)` for rows of any width.
pub fn lerp_rows(a: &[f64], b: &[f64], t: f64) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x + t * (y - x)).collect()
}

/// One entry of d h / d p_c for h(x(p), p): the row `hx` of the observation's
/// state Jacobian (3 entries) applied to the state's sensitivity `dx(m)` = d x_m
/// / d p_c, plus the direct term `hp` (0 for columns that are not parameters of
/// the observation, such as start-pose nuisances).
pub fn chain(hx: &[f64], dx: impl Fn(usize) -> f64, hp: f64) -> f64 {
    (0..3).map(|m| hx[m] * dx(m)).sum::<f64>() + hp
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_and_chains() {
        assert_eq!(
            lerp3(&[0.0, 2.0, -1.0], &[1.0, 4.0, 1.0], 0.25),
            [0.25, 2.5, -0.5]
        );
        assert_eq!(lerp_rows(&[1.0], &[3.0], 0.5), vec![2.0]);
        assert_eq!(chain(&[1.0, 2.0, 3.0], |m| m as f64, 0.5), 8.5);
    }
}
