//! Drift detection of [`super::BevtTracker`] (issue 20): a confident track whose box has
//! slid onto background or another object keeps a steady confidence, because the filter has
//! learned what it now sees. The learned verifier (`redetection.verifier`, NanoTrack) holds
//! the first frame's template and never learns, so it is an independent witness:
//!
//! - every `track_state.drift_check_frames` confident frames it scores the box (every
//!   `track_state.drift_calm_frames` while calm: the last check scored at least the
//!   re-acquisition bar `redetection.verifier_threshold` and the learning gate has refused
//!   no frame since, the filter's score holding its recent level); a score
//!   below `track_state.drift_threshold` makes the state `uncertain` (reason
//!   [`StateReason::OffTarget`]) and brings the next check forward to
//!   `track_state.drift_recheck_frames` frames later. A second failure in a row makes the
//!   track lost on drift ([`StateReason::Drifted`]): [`super::lost`] freezes the model of
//!   the last agreeing check and starts re-detection from the drift point. An agreeing
//!   check ends the hold and saves the model as the one a loss on drift goes back to
//!   ([`super::lost::verified`]). After a re-acquisition the first confident frame is
//!   checked at once, so a candidate the verifier disputes is soon lost again.
//! - with `track_state.drift_anchor`, a periodic check with nothing in dispute asks the
//!   first frame's filter first (frozen at initialisation, like the verifier's template):
//!   when it finds the target where the live filter does, at the confidence a filter
//!   window needs to be a re-acquisition candidate, the check agrees without a network
//!   pass. It never disputes a box: what it does not confirm goes to the verifier.
//! - with `track_state.verify_low_confidence`, a low-confidence (`uncertain`) frame is
//!   scored too: when the verifier's hit reaches `redetection.verifier_threshold` (the bar
//!   of a re-acquisition) *at the box* (its centre inside the box, one cell of the
//!   verifier's grid to spare), it is reported `tracking` ([`StateReason::Confirmed`]). A
//!   hit elsewhere in its region (twice the target's context) leaves the frame uncertain:
//!   a box beside a small target still has the target in view.
//!
//! - with `track_state.drift_head` and the learned box on (`box_refine`), the head's pass of
//!   the frame (the same network and template on a crop at the box) answers what it can
//!   in the same way: a periodic check agrees, and a low-confidence frame is confirmed,
//!   when the head's margin at the box reaches `redetection.verifier_threshold`. It never
//!   disputes: below that bar the verifier is asked.
//!
//! The published confidence follows the reported state, so a ground station thresholding
//! the confidence at `track_state.lost_threshold` sees what the state says: a disputed or
//! drift-lost box publishes at most `lost_threshold · score / drift_threshold`, a confirmed
//! one at least `lost_threshold`. The cost is one network pass every `drift_check_frames`
//! confident frames (none when the frozen filter confirms the box), one per failed check's
//! re-check, and one per low-confidence frame.

use super::{lost, State};
use crate::config::TrackerSpec;
use crate::error::TrackError;
use crate::geometry::{Point2, Size2};
use crate::image::Frame;
use crate::redetect::{context_side, Scored, Verifier};
use crate::track_state::{StateReason, TrackState};

/// The frozen filter's peak within this many cells of the live filter's is at the box (as
/// a re-detection search result within this many cells of its candidate is the candidate).
const ANCHOR_NEAR_CELLS: f32 = 3.0;

/// Between checks: confident frames since the last check, its result when it disagreed
/// (the verifier's score), and whether the track is calm: the last check scored at least
/// the re-acquisition bar and the learning gate has taken every frame since.
#[derive(Debug, Default)]
pub(super) struct DriftCheck {
    since: usize,
    off: Option<f32>,
    calm: bool,
}

/// What a tracked frame reports: state, reason and the published confidence.
pub(super) type Report = (TrackState, StateReason, f32);

/// Side, pixels, of the verifier's search region around the box: twice the target's
/// context, so a box beside a small target still has the target in view.
fn region_side(st: &State) -> f32 {
    let size = st.target_size();
    2.0 * context_side(size.w, size.h)
}

/// The verifier's best score around the box (`None`: no template, nothing to witness):
/// the score alone, no box regression.
fn score_at_box(
    st: &mut State,
    frame: &Frame<'_>,
    v: &mut (dyn Verifier + 'static),
) -> Result<Option<f32>, TrackError> {
    let side = region_side(st);
    st.verifier_passes += 1;
    Ok(v.search_above(frame, st.pos, side, f32::INFINITY)?
        .map(|s| s.score()))
}

/// The frozen first-frame filter confirms the box: its confidence on the frame's detection
/// features (scale `best`) reaches the bar a filter window needs to be a re-acquisition
/// candidate (`redetection.reacquire_threshold`), and its peak is where the live filter's
/// is (within [`ANCHOR_NEAR_CELLS`], what the re-detection search counts as one place).
fn anchor_agrees(st: &mut State, spec: &TrackerSpec, best: usize) -> bool {
    let bar = spec.config.redetection.reacquire_threshold;
    match st.anchor_evidence(best, spec.config.confidence.psr_exclusion_cells) {
        Some((c, dist)) => c >= bar && dist <= ANCHOR_NEAR_CELLS,
        None => false,
    }
}

/// The learned box's head pass of this frame as a witness (`track_state.drift_head`): its
/// largest foreground logit margin at the box when that reaches the re-acquisition bar
/// (`redetection.verifier_threshold`). The head runs NanoTrack's network with the first
/// frame's template, as the verifier does, on a crop centred on the box, so a margin at the
/// bar there is what a verifier hit at the box would say; below it (or when the head did not
/// run) `None`, and the verifier is asked.
fn head_at_box(st: &State, spec: &TrackerSpec) -> Option<f32> {
    let bar = spec.config.redetection.verifier_threshold;
    st.head_witness
        .filter(|m| spec.config.track_state.drift_head && *m >= bar)
}

/// Cells of the verifier's score map across its search region (NanoTrack: 255 px / 16).
const VERIFIER_CELLS: f32 = 16.0;

/// The verifier's score when it finds the target *at* the box ([`hit_at_box`]): its best
/// hit in the region around the box ([`region_side`]) reaches `bar`. `None` otherwise:
/// below the bar, a hit beside the box, or no template.
fn found_at_box(
    st: &mut State,
    frame: &Frame<'_>,
    v: &mut (dyn Verifier + 'static),
    bar: f32,
) -> Result<Option<f32>, TrackError> {
    let side = region_side(st);
    st.verifier_passes += 1;
    let b = st.box_size(st.scale);
    Ok(match v.search_above(frame, st.pos, side, bar)? {
        Some(Scored::Hit(h)) if hit_at_box(h.pos, st.pos, b, side / VERIFIER_CELLS) => {
            Some(h.score)
        }
        _ => None,
    })
}

/// A verifier hit centred at `hit` is at the box of size `size` centred at `pos`: inside
/// it, with one cell of the verifier's score map (`cell` pixels) to spare on each side, as
/// the hit's position is read off that grid. False for non-finite input.
fn hit_at_box(hit: Point2, pos: Point2, size: Size2, cell: f32) -> bool {
    (hit.x - pos.x).abs() <= 0.5 * size.w + cell && (hit.y - pos.y).abs() <= 0.5 * size.h + cell
}

/// The confidence published with a box the verifier scores `score` below `threshold`:
/// at most `lost_threshold · score / threshold` (0 for a NaN or negative score).
fn disputed(confidence: f32, score: f32, threshold: f32, lost_threshold: f32) -> f32 {
    let f = if threshold > 0.0 && score.is_finite() {
        (score / threshold).clamp(0.0, 1.0)
    } else {
        0.0
    };
    confidence.min(lost_threshold * f)
}

/// A tracked frame the state machine has just `decided` (state and reason) with
/// `confidence`: runs the checks that are due and returns what is reported. Only a
/// confirmed drift changes the state machine (it becomes lost, [`super::lost`] takes it
/// from there); the other outcomes change what is reported. Any state other than
/// `tracking` ends a hold, and the next confident frame is checked at once.
///
/// # Errors
/// [`TrackError::Feature`] when the verifier's network fails.
pub(super) fn check(
    st: &mut State,
    frame: &Frame<'_>,
    spec: &TrackerSpec,
    verifier: Option<&mut (dyn Verifier + 'static)>,
    decided: (TrackState, StateReason),
    best: usize,
    confidence: f32,
) -> Result<Report, TrackError> {
    let t = &spec.config.track_state;
    let unchanged = (decided.0, decided.1, confidence);
    let Some(v) = verifier else {
        st.drift = DriftCheck::default();
        return Ok(unchanged);
    };
    match decided {
        (TrackState::Tracking, _) if t.drift_check_frames > 0 => {}
        (TrackState::Uncertain, StateReason::LowConfidence { .. }) if t.verify_low_confidence => {
            st.drift = DriftCheck::default();
            let bar = spec.config.redetection.verifier_threshold;
            let found = match head_at_box(st, spec) {
                Some(m) => Some((m, true)),
                None => found_at_box(st, frame, v, bar)?.map(|s| (s, false)),
            };
            return Ok(match found {
                Some((s, head)) => {
                    let (state, reason) = st.states.confirmed(confidence, s, head);
                    (state, reason, confidence.max(t.lost_threshold))
                }
                _ => unchanged,
            });
        }
        _ => {
            st.drift = DriftCheck::default();
            return Ok(unchanged);
        }
    }
    // The filter's own evidence against its recent level: a frame the learning gate
    // refused (its score fell below the gate's share of its running reference) ends the
    // calm, so the next check is due after `drift_check_frames` again.
    if st.gate.skipped_in_a_row() > 0 {
        st.drift.calm = false;
    }
    let every = match (st.drift.off, t.drift_recheck_frames) {
        (Some(_), r) if r > 0 => r.min(t.drift_check_frames),
        _ if st.drift.calm => t.drift_calm_frames.max(t.drift_check_frames),
        _ => t.drift_check_frames,
    };
    if st.drift.since == 0 || st.drift.since >= every {
        // A periodic check with nothing in dispute may be answered by the frozen first-frame
        // filter; the check at once (a new track, after a re-acquisition or any other state)
        // and the re-check ask the verifier.
        let periodic = st.drift.since > 0 && st.drift.off.is_none();
        st.drift.since = 0;
        if periodic
            && ((t.drift_anchor && anchor_agrees(st, spec, best))
                || head_at_box(st, spec).is_some())
        {
            st.drift.since += 1;
            lost::verified(st);
            return Ok(unchanged);
        }
        match score_at_box(st, frame, v)? {
            Some(s) if s.is_nan() || s < t.drift_threshold => {
                if st.drift.off.is_some() && t.drift_recheck_frames > 0 {
                    st.drift = DriftCheck::default();
                    let (state, reason) = st.states.drift_lost(s, t.drift_threshold);
                    let c = disputed(confidence, s, t.drift_threshold, t.lost_threshold);
                    return Ok((state, reason, c));
                }
                st.drift.off = Some(s);
                st.drift.calm = false;
            }
            Some(s) => {
                st.drift.off = None;
                st.drift.calm = s >= spec.config.redetection.verifier_threshold;
                lost::verified(st);
            }
            // No hit at all (no template) counts as agreement: nothing to witness with.
            None => {
                st.drift.off = None;
                st.drift.calm = false;
            }
        }
    }
    st.drift.since += 1;
    Ok(match st.drift.off {
        Some(s) => {
            let (state, reason) = st.states.off_target(s, t.drift_threshold);
            let c = disputed(confidence, s, t.drift_threshold, t.lost_threshold);
            (state, reason, c)
        }
        None => unchanged,
    })
}

#[cfg(test)]
mod tests {
    use super::{disputed, hit_at_box};
    use crate::geometry::{Point2, Size2};

    #[test]
    fn a_hit_is_at_the_box_inside_it_or_within_one_cell_of_its_edge() {
        let pos = Point2 { x: 100.0, y: 50.0 };
        let size = Size2 { w: 20.0, h: 10.0 };
        let at = |x, y| hit_at_box(Point2 { x, y }, pos, size, 4.0);
        assert!(at(100.0, 50.0));
        assert!(at(110.0, 55.0)); // the corner
        assert!(at(114.0, 59.0)); // one cell beyond it
        assert!(!at(114.5, 50.0));
        assert!(!at(100.0, 40.5));
        assert!(!at(80.0, 50.0)); // a box width beside it
        assert!(!at(f32::NAN, 50.0));
        assert!(!hit_at_box(pos, pos, size, f32::NAN));
    }

    #[test]
    fn a_disputed_box_publishes_a_confidence_below_the_lost_threshold_by_its_score() {
        assert_eq!(disputed(0.9, 2.0, 4.0, 0.3), 0.15);
        assert_eq!(disputed(0.1, 2.0, 4.0, 0.3), 0.1);
        assert_eq!(disputed(0.9, -1.0, 4.0, 0.3), 0.0);
        assert_eq!(disputed(0.9, f32::NAN, 4.0, 0.3), 0.0);
        assert_eq!(disputed(0.9, 3.0, 0.0, 0.3), 0.0);
    }
}
