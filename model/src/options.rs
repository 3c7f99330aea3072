//! Generation options every stage reads from one place: the derivation builds
//! series branches with them, the emitters write the switch, verification
//! probes both sides of it.

/// Removable singularities (omega dt -> 0, dtheta -> 0): below `series_switch`
/// in |s| the kernels evaluate the Taylor series of order `series_order`
/// instead of the closed form. Chosen together so that the truncation error
/// (< switch^(order+1)/(order+1)! ~ 1e-19) and the closed form's cancellation
/// at the switch (~1e-16/switch^2 ~ 4e-14) are both negligible in f64. The
/// generated crate's `f32` feature moves the switch for single precision
/// (`math::series_switch`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GenOptions {
    pub series_switch: f64,
    pub series_order: i64,
}

impl GenOptions {
    pub const DEFAULT: GenOptions = GenOptions {
        series_switch: 0.05,
        series_order: 8,
    };
}

impl Default for GenOptions {
    fn default() -> Self {
        GenOptions::DEFAULT
    }
}
