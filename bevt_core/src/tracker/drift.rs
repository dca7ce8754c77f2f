//! Drift detection of [`super::BevtTracker`] (issue 20): a confident track whose box has
//! slid onto background or another object keeps a steady confidence, because the filter has
//! learned what it now sees. The learned verifier (`redetection.verifier`, NanoTrack) holds
//! the first frame's template and never learns, so it is an independent witness: every
//! `track_state.drift_check_frames` confident frames it scores the box, and a score below
//! `track_state.drift_threshold` makes the state `uncertain` (reason
//! [`StateReason::OffTarget`]) until its next check agrees.
//!
//! The check only changes the reported state: the state machine, the lost state (which
//! model it freezes, which frames refresh the re-detection template) and learning follow
//! the confidence as before, so accuracy is unchanged. Going `lost` on drift (and
//! re-detecting from the drift point) is not done yet. Its cost is one network pass every
//! `drift_check_frames` confident frames.

use super::State;
use crate::config::TrackerSpec;
use crate::error::TrackError;
use crate::image::Frame;
use crate::redetect::{context_side, Verifier};
use crate::track_state::{StateReason, TrackState};

/// Between checks: confident frames since the last check, and its result when it
/// disagreed (the verifier's score).
#[derive(Debug, Default)]
pub(super) struct DriftCheck {
    since: usize,
    off: Option<f32>,
}

/// A tracked frame the state machine has just `decided` (state and reason): on confident
/// frames, runs the check when it is due and overrules the state while the last check
/// disagrees. Any other state ends the hold, and the next confident frame is checked at
/// once.
///
/// # Errors
/// [`TrackError::Feature`] when the verifier's network fails.
pub(super) fn check(
    st: &mut State,
    frame: &Frame<'_>,
    spec: &TrackerSpec,
    verifier: Option<&mut (dyn Verifier + 'static)>,
    decided: (TrackState, StateReason),
) -> Result<(TrackState, StateReason), TrackError> {
    let t = &spec.config.track_state;
    let every = t.drift_check_frames;
    let (Some(v), TrackState::Tracking, true) = (verifier, decided.0, every > 0) else {
        st.drift = DriftCheck::default();
        return Ok(decided);
    };
    if st.drift.since == 0 || st.drift.since >= every {
        st.drift.since = 0;
        let size = st.target_size();
        let side = 2.0 * context_side(size.w, size.h);
        // No hit at all (no template) counts as agreement: nothing to witness with.
        let score = v.search(frame, st.pos, side)?.map(|h| h.score);
        st.drift.off = score.filter(|&s| s.is_nan() || s < t.drift_threshold);
    }
    st.drift.since += 1;
    Ok(match st.drift.off {
        Some(score) => st.states.off_target(score, t.drift_threshold),
        None => decided,
    })
}
