//! What diagnosis says of an effect's parameters: each one's estimate and
//! standard deviation. Its own module because the motion's ranking
//! ([`super::diagnose`]) and the sensor's ([`super::sensor`]) both report
//! them, and neither should reach the other for it.
use serde::Serialize;

/// A calibrated parameter: its estimate and standard deviation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimate {
    pub estimate: f64,
    pub std: f64,
}

/// An effect's parameters by name, as calibrated.
pub type Estimates = std::collections::BTreeMap<String, Estimate>;

/// Why `effect`'s calibrated `params` are not the physical effect its
/// catalogue entry describes: an estimate outside the parameter's physical
/// range by more than two standard deviations (a depth share of -0.06 is
/// no camera reading depth). None when they are, or the effect is unknown.
pub fn unphysical(
    catalogue: &[kinegen_model::effects::Effect],
    effect: &str,
    params: &Estimates,
) -> Option<String> {
    let e = catalogue.iter().find(|e| e.name == effect)?;
    e.parameters.iter().find_map(|t| {
        let [low, high] = t.physical?;
        let est = params.get(&t.name)?;
        let margin = 2.0 * if est.std.is_finite() { est.std } else { 0.0 };
        (est.estimate + margin < low || est.estimate - margin > high).then(|| {
            format!(
                "{} = {:.4} is outside its physical range {low}..{high}",
                t.name, est.estimate
            )
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn depth_share(estimate: f64, std: f64) -> Estimates {
        [("range_depth".to_string(), Estimate { estimate, std })].into()
    }

    /// A depth share below 0 by more than two standard deviations is not a
    /// camera reading depth; one within them, or inside 0..1, may be.
    #[test]
    fn an_estimate_outside_its_physical_range_is_not_the_effect() {
        let cat = kinegen_model::effects::catalogue(&[]).unwrap();
        let why = unphysical(&cat, "range_as_depth", &depth_share(-0.058, 0.005));
        assert!(why.is_some_and(|w| w.contains("range_depth")));
        assert_eq!(
            unphysical(&cat, "range_as_depth", &depth_share(-0.01, 0.01)),
            None
        );
        assert_eq!(
            unphysical(&cat, "range_as_depth", &depth_share(0.97, 0.02)),
            None
        );
        assert!(unphysical(&cat, "range_as_depth", &depth_share(1.3, 0.05)).is_some());
        // effects without a physical range are never refused by it
        assert_eq!(
            unphysical(&cat, "range_scale", &depth_share(-9.0, 0.0)),
            None
        );
    }
}
