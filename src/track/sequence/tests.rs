use super::relocated::lost;
use super::*;
use crate::energy::{BINS, Counts, MASK_OWN};
use crate::track::search::GaussNewtonSettings;

/// Both arches' energies with these area errors (uncovered of 10 000 mask pixels).
fn with_area_errors(upper: f64, lower: f64) -> [Energy; 2] {
    [upper, lower].map(|a| with_uncovered((a * 10_000.0).round() as u64, 10_000))
}

/// An arch's energy that leaves `uncovered` of its `mask` pixels uncovered.
fn with_uncovered(uncovered: u64, mask: u64) -> Energy {
    let mut bins = [0; BINS];
    bins[MASK_OWN * 3] = uncovered;
    bins[MASK_OWN * 3 + 1] = mask - uncovered;
    Energy {
        cameras: vec![Counts { bins }],
    }
}

/// A frame is looked for afresh where an arch leaves much of its mask uncovered, not where the
/// lips close over its teeth: `bench track`'s hard seed 5, frame 15, had its upper arch leave
/// 11 of 34 mask pixels uncovered (area error 0.32), and a fresh look there cost 8 of the
/// take's 13 s and found nothing better.
#[test]
fn a_frame_is_lost_where_its_masks_are_left_uncovered() {
    let threshold = TrackSettings::default().relocate_area_error;
    let fits = with_uncovered(100, 10_000);
    assert!(!lost(&[with_uncovered(11, 34), fits.clone()], threshold));
    assert!(lost(
        &[fits.clone(), with_uncovered(3_000, 10_000)],
        threshold
    ));
    assert!(!lost(
        &[fits.clone(), with_uncovered(1_000, 10_000)],
        threshold
    ));
}

/// The paper's search, asked for a frame that fits worse than the recent ones, overrules
/// Gauss-Newton only with a clearly better fit of the worse arch: a mouth opening wide
/// (the other program's hard photos, seed 1, frames 13-15: 0.0334 against 0.0322) keeps
/// Gauss-Newton's answer; a lower arch lost on the way (seed 2, frame 22: 0.049 against
/// 0.032) takes the second opinion.
#[test]
fn a_second_opinion_overrules_only_with_a_clearly_better_fit() {
    let gain = GaussNewtonSettings::default().fallback_gain;
    let first = with_area_errors(0.0125, 0.0334);
    assert!(!overrules(&with_area_errors(0.0095, 0.0322), &first, gain));
    let lost = with_area_errors(0.0116, 0.0492);
    assert!(overrules(&with_area_errors(0.0122, 0.0319), &lost, gain));
    // The worse arch of each is what counts, whichever arch it is.
    assert!(!overrules(&with_area_errors(0.048, 0.010), &lost, gain));
    assert!(overrules(&with_area_errors(0.040, 0.010), &lost, gain));
}

#[test]
fn restarts_take_the_best_starts_that_lie_apart() {
    let at = |x: f64, turn: f64| ArchPoses {
        upper: Pose::IDENTITY,
        lower: Pose::from_euler_tuple(&[0.0, turn, 0.0, x, 0.0, 0.0]),
    };
    // Scores 1..6: the second is 0.5 mm from the first, the fourth turned 0.02 rad
    // (0.6 mm at an arch's radius) from the third.
    let options = [
        at(0.0, 0.0),
        at(0.5, 0.0),
        at(3.0, 0.0),
        at(3.0, 0.02),
        at(-4.0, 0.0),
        at(8.0, 0.0),
    ];
    let scores = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    let picked = best_distinct(Arch::Lower, &options, &scores, 3);
    assert_eq!(picked, vec![options[0], options[2], options[4]]);
    assert_eq!(
        best_distinct(Arch::Lower, &options, &scores, 1),
        vec![options[0]]
    );
    // The upper arch's poses are all the same: one start.
    assert_eq!(best_distinct(Arch::Upper, &options, &scores, 3).len(), 1);
}
