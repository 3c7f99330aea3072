//! Property tests: proptest draws the seeds of the domain samplers, so every run
//! explores new states, inputs, parameters and step lengths.
use kinegen_verify::checks::{
    exact_vs_euler, inverse_round_trips, jacobians_vs_finite_differences, se2_equivariance, where_,
};
use kinegen_verify::{models, Generated};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn jacobians_match_finite_differences(seed in any::<u64>()) {
        for ir in models::all() {
            for f in jacobians_vs_finite_differences(&ir, &Generated(ir.name.clone()), 2, seed) {
                prop_assert!(f.passed(), "{}", where_(&f));
            }
        }
    }

    #[test]
    fn exact_integration_is_the_limit_of_euler(seed in any::<u64>()) {
        for ir in models::all() {
            for f in exact_vs_euler(&ir, &Generated(ir.name.clone()), 2, seed) {
                prop_assert!(f.passed(), "{}", where_(&f));
            }
        }
    }

    #[test]
    fn inverse_kinematics_round_trips(seed in any::<u64>()) {
        for ir in models::all() {
            for f in inverse_round_trips(&ir, &Generated(ir.name.clone()), 4, seed) {
                prop_assert!(f.passed(), "{}", where_(&f));
            }
        }
    }

    #[test]
    fn motion_and_observations_are_se2_equivariant(seed in any::<u64>()) {
        for ir in models::all() {
            for f in se2_equivariance(&ir, &Generated(ir.name.clone()), 4, seed) {
                prop_assert!(f.passed(), "{}", where_(&f));
            }
        }
    }
}
