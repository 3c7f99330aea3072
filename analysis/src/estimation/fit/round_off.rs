//! Directions that only the normal equations' round-off hides
//! ([`FitResult::below_round_off`]), taken over from a stage that resolved
//! them.
use super::options::BelowRoundOff;
use super::FitResult;

/// `whole` (the refinement on whole runs) with the directions only its
/// normal equations' round-off hid ([`FitResult::below_round_off`]) taken
/// as the segments determined them: they keep the segments' estimate (the
/// refinement held them there) and are not reported undetermined; the
/// drift-aware sandwich, whose square root resolves them, gives their
/// standard deviations. The whole runs carry more information than their
/// re-anchored segments, never less, so a direction the segments determine
/// and the whole runs do not is round-off: on a 1,000,000-row simulated log
/// the track width had 1e-14 of the radii's information in the whole run's
/// sums (and was called "not identifiable") but 6e-7 of the scale in the
/// sandwich's square root.
pub(super) fn resolved_by_segments(mut whole: FitResult, searched: &FitResult) -> FitResult {
    if whole.free != searched.free {
        return whole;
    }
    let determined = |b: &BelowRoundOff| {
        b.params
            .iter()
            .all(|&k| searched.std.get(k).is_some_and(|s| s.is_finite()))
    };
    let (taken, left): (Vec<_>, Vec<_>) = std::mem::take(&mut whole.below_round_off)
        .into_iter()
        .partition(determined);
    for b in &taken {
        whole.warnings.retain(|w| *w != b.warning);
        whole.undetermined.retain(|d| *d != b.direction);
        for &k in &b.params {
            whole.std[k] = searched.std[k];
        }
    }
    whole.below_round_off = left;
    whole
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DVector;

    const HIDDEN: &str = "not identifiable from these logs: b (kept at its starting value)";

    fn whole() -> FitResult {
        let b = DVector::from_vec(vec![0.0, 0.0, 1.0]);
        FitResult {
            undetermined: vec![b.clone()],
            below_round_off: vec![BelowRoundOff {
                direction: b,
                params: vec![2],
                warning: HIDDEN.into(),
            }],
            ..FitResult::of_three([1e-6, 1e-6, f64::INFINITY], &[HIDDEN, "another warning"])
        }
    }

    #[test]
    fn a_direction_the_segments_determined_is_taken_over() {
        let taken = resolved_by_segments(whole(), &FitResult::of_three([1e-6, 1e-6, 3e-5], &[]));
        assert_eq!(taken.std[2], 3e-5);
        assert_eq!(taken.warnings, vec!["another warning".to_string()]);
        assert!(taken.undetermined.is_empty() && taken.below_round_off.is_empty());
    }

    #[test]
    fn a_direction_the_segments_did_not_determine_stays_undetermined() {
        let segments = FitResult::of_three([1e-6, 1e-6, f64::INFINITY], &[HIDDEN]);
        let kept = resolved_by_segments(whole(), &segments);
        assert!(kept.std[2].is_infinite());
        assert_eq!(kept.warnings.len(), 2);
        assert_eq!(
            (kept.undetermined.len(), kept.below_round_off.len()),
            (1, 1)
        );
    }
}
