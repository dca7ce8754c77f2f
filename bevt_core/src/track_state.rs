//! Track state: tracking → uncertain → lost → re-acquired → tracking.
//!
//! ```text
//!            confidence < lost_threshold           … for lost_frames frames in a row
//! Tracking ───────────────────────────▶ Uncertain ─────────────────────────────▶ Lost
//!    ▲  ◀──────────────────────────────────┘                                      │
//!    │        confidence ≥ lost_threshold                                          │
//!    │                          a re-detection candidate confident for            │
//!    └──────── Reacquired ◀──── reacquire_frames frames in a row ◀────────────────┘
//! Tracking ── a drift check fails, and its re-check fails too ─────────────────▶ Lost
//! ```
//!
//! [`TrackState::Reacquired`] is
//! reported on the one frame the track is taken back; the next frame is `Tracking` or
//! `Uncertain` again. The drift check (`tracker/drift.rs`) also overrules what is reported
//! without moving the machine: a confident frame whose box the verifier disputes is
//! reported `Uncertain` ([`StateMachine::off_target`]), an unconfident one it confirms
//! `Tracking` ([`StateMachine::confirmed`]). Each state comes with a [`StateReason`] that
//! prints as the operator reads it ("target lost: confidence 0.08 below 0.25 for 10
//! frames").

use crate::config::TrackStateConfig;
use serde::{Deserialize, Serialize};
use std::fmt;

/// The state of the track after one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrackState {
    /// Confident of the target.
    Tracking,
    /// Below the confidence threshold for fewer than `lost_frames` frames: the box is
    /// still the tracker's best guess.
    Uncertain,
    /// The target is lost; the box is the last known one (or the current re-detection
    /// candidate) and must not be used.
    Lost,
    /// The target was found again on this frame after being lost.
    Reacquired,
}

impl TrackState {
    /// Lower-case name, as in result files.
    pub fn name(self) -> &'static str {
        match self {
            Self::Tracking => "tracking",
            Self::Uncertain => "uncertain",
            Self::Lost => "lost",
            Self::Reacquired => "reacquired",
        }
    }
}

/// Why the track is in its state.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StateReason {
    /// Tracking normally.
    Confident,
    /// Confidence below the threshold, not yet for long enough to drop the track.
    LowConfidence {
        /// This frame's confidence.
        confidence: f32,
        /// The threshold.
        threshold: f32,
        /// Consecutive frames below it.
        frames: usize,
    },
    /// Lost: below the threshold for `frames` frames (the best re-detection candidate's
    /// confidence while searching).
    Lost {
        /// This frame's (best) confidence.
        confidence: f32,
        /// The threshold.
        threshold: f32,
        /// Consecutive frames below it, the search included.
        frames: usize,
    },
    /// Drift: the confidence is fine, but the learned verifier, cross-checking the box
    /// against the first frame's template, scores it below `threshold` (the box is off the
    /// target or on something else). Held until its next check agrees.
    OffTarget {
        /// The verifier's score at the box (NanoTrack foreground logit margin).
        score: f32,
        /// The threshold (`track_state.drift_threshold`).
        threshold: f32,
    },
    /// Lost on drift: a drift check failed and the re-check soon after failed too, or one
    /// check scored below `track_state.drift_lost_threshold` (the box is on something
    /// else); the model is frozen and re-detection searches from the drift point.
    Drifted {
        /// The verifier's score at the check that made the track lost.
        score: f32,
        /// The threshold (`track_state.drift_threshold`).
        threshold: f32,
        /// Frames spent lost, this one included.
        frames: usize,
    },
    /// The confidence is below the threshold, but the learned verifier, asked because of
    /// it, finds the first frame's target at the box (score at or above
    /// `redetection.verifier_threshold`, the bar of a re-acquisition): reported `tracking`.
    Confirmed {
        /// This frame's confidence.
        confidence: f32,
        /// The verifier's score at the box (or the learned box head's margin there).
        score: f32,
        /// The witness was the learned box's head pass of this frame
        /// (`track_state.drift_head`), not a verifier pass.
        head: bool,
    },
    /// Found again after `after` lost frames.
    Reacquired {
        /// Frames spent lost.
        after: usize,
    },
}

impl fmt::Display for StateReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Confident => Ok(()),
            Self::LowConfidence {
                confidence,
                threshold,
                frames,
            } => write!(
                f,
                "low confidence: {confidence:.2} below {threshold:.2} for {frames} frames"
            ),
            Self::Lost {
                confidence,
                threshold,
                frames,
            } if confidence >= threshold => write!(
                f,
                "target lost: searching for {frames} frames (a candidate at confidence {confidence:.2}, not yet confirmed)"
            ),
            Self::Lost {
                confidence,
                threshold,
                frames,
            } => write!(
                f,
                "target lost: confidence {confidence:.2} below {threshold:.2} for {frames} frames"
            ),
            Self::OffTarget { score, threshold } => write!(
                f,
                "drift: the box does not match the first frame's target (verifier score {score:.1} below {threshold:.1})"
            ),
            Self::Drifted {
                score,
                threshold,
                frames,
            } => write!(
                f,
                "target lost: the box drifted off the first frame's target (verifier score {score:.1} below {threshold:.1}); searching for {frames} frames"
            ),
            Self::Confirmed {
                confidence,
                score,
                head: false,
            } => write!(
                f,
                "low confidence {confidence:.2}, but the verifier finds the target at the box (score {score:.1})"
            ),
            Self::Confirmed {
                confidence,
                score,
                head: true,
            } => write!(
                f,
                "low confidence {confidence:.2}, but the learned box's head finds the target at the box (score {score:.1})"
            ),
            Self::Reacquired { after } => write!(f, "re-acquired after {after} frames"),
        }
    }
}

/// The state machine (the re-detection decides when a lost target is found again).
#[derive(Debug, Clone, PartialEq)]
pub struct StateMachine {
    params: TrackStateConfig,
    state: TrackState,
    below: usize,
    lost_for: usize,
    /// Set while lost on drift: the verifier's score and threshold that made it lost.
    drifted: Option<(f32, f32)>,
}

impl StateMachine {
    /// Starts in [`TrackState::Tracking`].
    pub fn new(params: TrackStateConfig) -> Self {
        Self {
            params,
            state: TrackState::Tracking,
            below: 0,
            lost_for: 0,
            drifted: None,
        }
    }

    /// Replaces the thresholds, keeping the state and its counters (for
    /// [`crate::BevtTracker::retune`]).
    pub fn set_params(&mut self, params: TrackStateConfig) {
        self.params = params;
    }

    /// The current state.
    pub fn state(&self) -> TrackState {
        self.state
    }

    /// Lost on drift ([`Self::drift_lost`]) rather than on low confidence.
    pub fn drifted(&self) -> bool {
        self.state == TrackState::Lost && self.drifted.is_some()
    }

    /// Frames spent lost so far (0 unless lost).
    pub fn lost_for(&self) -> usize {
        self.lost_for
    }

    /// One frame tracked normally with `confidence`; returns the new state and its reason.
    /// Must not be called while lost (use [`Self::searching`]).
    pub fn track(&mut self, confidence: f32) -> (TrackState, StateReason) {
        let p = self.params;
        if confidence >= p.lost_threshold {
            self.below = 0;
            self.state = TrackState::Tracking;
            return (self.state, StateReason::Confident);
        }
        self.below = self.below.saturating_add(1);
        if self.below >= p.lost_frames {
            self.state = TrackState::Lost;
            self.lost_for = 0;
            self.drifted = None;
            (self.state, self.lost_reason(confidence))
        } else {
            self.state = TrackState::Uncertain;
            (
                self.state,
                StateReason::LowConfidence {
                    confidence,
                    threshold: p.lost_threshold,
                    frames: self.below,
                },
            )
        }
    }

    /// A frame [`Self::track`] found confident, overruled by a drift check: the verifier
    /// scored the box `score`, below `threshold`. The reported state is `uncertain`; the
    /// machine itself stays where the confidence put it ([`Self::state`] is unchanged, the
    /// counter of unconfident frames is not advanced), so the drift check changes what is
    /// reported, not when the track is lost or which model the lost state freezes.
    pub fn off_target(&self, score: f32, threshold: f32) -> (TrackState, StateReason) {
        (
            TrackState::Uncertain,
            StateReason::OffTarget { score, threshold },
        )
    }

    /// A frame the confidence found confident, made lost by a confirmed drift check: the
    /// verifier scored the box `score`, below `threshold`. The lost state starts on this
    /// frame, as after `lost_frames` unconfident ones.
    pub fn drift_lost(&mut self, score: f32, threshold: f32) -> (TrackState, StateReason) {
        self.state = TrackState::Lost;
        self.lost_for = 0;
        self.drifted = Some((score, threshold));
        (
            self.state,
            StateReason::Drifted {
                score,
                threshold,
                frames: 1,
            },
        )
    }

    /// A frame [`Self::track`] found unconfident (`uncertain`, not lost), overruled by the
    /// verifier (or, `head`, the learned box's head) finding the target at the box with
    /// `score`: reported `tracking`. As for
    /// [`Self::off_target`], the machine itself is unchanged (the unconfident frame still
    /// counts towards `lost_frames`).
    pub fn confirmed(&self, confidence: f32, score: f32, head: bool) -> (TrackState, StateReason) {
        (
            TrackState::Tracking,
            StateReason::Confirmed {
                confidence,
                score,
                head,
            },
        )
    }

    /// One lost frame searched without success; `confidence` is the best candidate's.
    pub fn searching(&mut self, confidence: f32) -> (TrackState, StateReason) {
        self.below = self.below.saturating_add(1);
        self.lost_for = self.lost_for.saturating_add(1);
        self.state = TrackState::Lost;
        let reason = match self.drifted {
            Some((score, threshold)) => StateReason::Drifted {
                score,
                threshold,
                frames: self.lost_for.saturating_add(1),
            },
            None => self.lost_reason(confidence),
        };
        (self.state, reason)
    }

    /// The search confirmed the target on this frame.
    pub fn reacquired(&mut self) -> (TrackState, StateReason) {
        let after = self.lost_for.saturating_add(1);
        self.below = 0;
        self.lost_for = 0;
        self.drifted = None;
        self.state = TrackState::Reacquired;
        (self.state, StateReason::Reacquired { after })
    }

    fn lost_reason(&self, confidence: f32) -> StateReason {
        StateReason::Lost {
            confidence,
            threshold: self.params.lost_threshold,
            frames: self.below,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn walks_tracking_uncertain_lost_reacquired_tracking() {
        let mut m = StateMachine::new(TrackStateConfig {
            lost_threshold: 0.25,
            lost_frames: 3,
            ..TrackStateConfig::default()
        });
        assert_eq!(m.track(0.9).0, TrackState::Tracking);
        assert_eq!(m.track(0.1).0, TrackState::Uncertain);
        assert_eq!(m.track(0.9).0, TrackState::Tracking);
        assert_eq!(m.track(0.1).0, TrackState::Uncertain);
        assert_eq!(m.track(0.1).0, TrackState::Uncertain);
        let (s, r) = m.track(0.08);
        assert_eq!(s, TrackState::Lost);
        assert_eq!(
            r.to_string(),
            "target lost: confidence 0.08 below 0.25 for 3 frames"
        );
        for _ in 0..30 {
            assert_eq!(m.searching(0.1).0, TrackState::Lost);
        }
        assert_eq!(m.lost_for(), 30);
        let (s, r) = m.reacquired();
        assert_eq!(s, TrackState::Reacquired);
        assert_eq!(r.to_string(), "re-acquired after 31 frames");
        assert_eq!(m.track(0.9).0, TrackState::Tracking);
        assert_eq!(StateReason::Confident.to_string(), "");
    }

    #[test]
    fn a_drift_check_makes_a_confident_frame_uncertain_without_counting_towards_lost() {
        let mut m = StateMachine::new(TrackStateConfig {
            lost_threshold: 0.25,
            lost_frames: 2,
            ..TrackStateConfig::default()
        });
        assert_eq!(m.track(0.1).0, TrackState::Uncertain);
        assert_eq!(m.track(0.9).0, TrackState::Tracking);
        let (s, r) = m.off_target(2.34, 4.0);
        assert_eq!(s, TrackState::Uncertain);
        assert_eq!(m.state(), TrackState::Tracking);
        assert_eq!(
            r.to_string(),
            "drift: the box does not match the first frame's target (verifier score 2.3 below 4.0)"
        );
        // One unconfident frame after it is the first of `lost_frames`, not the second.
        assert_eq!(m.track(0.1).0, TrackState::Uncertain);
        assert_eq!(m.track(0.1).0, TrackState::Lost);
    }

    #[test]
    fn a_confirmed_drift_is_lost_until_reacquired_and_says_why_while_searching() {
        let mut m = StateMachine::new(TrackStateConfig {
            lost_threshold: 0.25,
            lost_frames: 5,
            ..TrackStateConfig::default()
        });
        assert_eq!(m.track(0.9).0, TrackState::Tracking);
        assert!(!m.drifted());
        let (s, r) = m.drift_lost(1.04, 4.0);
        assert_eq!((s, m.state()), (TrackState::Lost, TrackState::Lost));
        assert!(m.drifted());
        assert_eq!(
            r.to_string(),
            "target lost: the box drifted off the first frame's target (verifier score 1.0 below 4.0); searching for 1 frames"
        );
        let (s, r) = m.searching(0.7);
        assert_eq!(s, TrackState::Lost);
        assert!(matches!(r, StateReason::Drifted { frames: 2, .. }), "{r:?}");
        assert_eq!(m.reacquired().0, TrackState::Reacquired);
        assert!(!m.drifted());
        // A later loss on confidence says so.
        for _ in 0..4 {
            assert_eq!(m.track(0.1).0, TrackState::Uncertain);
        }
        let (s, r) = m.track(0.1);
        assert_eq!(s, TrackState::Lost);
        assert!(!m.drifted());
        assert!(
            matches!(m.searching(0.1).1, StateReason::Lost { .. }),
            "{r:?}"
        );
    }

    #[test]
    fn a_confirmed_low_confidence_frame_is_reported_tracking_and_still_counts() {
        let mut m = StateMachine::new(TrackStateConfig {
            lost_threshold: 0.25,
            lost_frames: 2,
            ..TrackStateConfig::default()
        });
        assert_eq!(m.track(0.1).0, TrackState::Uncertain);
        let (s, r) = m.confirmed(0.1, 6.23, false);
        assert_eq!(s, TrackState::Tracking);
        assert_eq!(m.state(), TrackState::Uncertain);
        assert_eq!(
            r.to_string(),
            "low confidence 0.10, but the verifier finds the target at the box (score 6.2)"
        );
        // The learned box's head as the witness says so.
        let (s, r) = m.confirmed(0.1, 6.23, true);
        assert_eq!(s, TrackState::Tracking);
        assert_eq!(
            r.to_string(),
            "low confidence 0.10, but the learned box's head finds the target at the box (score 6.2)"
        );
        assert_eq!(m.track(0.1).0, TrackState::Lost);
    }
}
