//! Metrics of the confidence and the lost state against ground truth (issue 8).
//!
//! A frame the tracker produced an output for is **good** when the target is annotated and
//! the box overlaps it with IoU ≥ [`GOOD_IOU`], **bad** when the target is absent from the
//! ground truth (NaN row) or IoU < [`BAD_IOU`]; frames in between are neither. Then:
//! - the ROC-AUC of the confidence for good frames against bad ones (the probability that a
//!   random good frame is more confident than a random bad one, ties counting one half);
//! - the precision and recall of the `lost` state against the bad frames;
//! - for every reappearance of the target after an absence, the frames from its first
//!   annotated frame to the first frame tracked again (state not `lost`, IoU ≥ [`GOOD_IOU`]).

use crate::geometry::BBox;
use crate::track_state::TrackState;
use serde::{Deserialize, Serialize};

/// IoU at or above which a frame is good.
pub const GOOD_IOU: f32 = 0.5;
/// IoU below which a frame is bad.
pub const BAD_IOU: f32 = 0.1;

/// One scored frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameLabel {
    /// The tracker's confidence.
    pub confidence: f32,
    /// In the `lost` state.
    pub lost: bool,
    /// `Some(true)` good, `Some(false)` bad, `None` neither.
    pub good: Option<bool>,
}

/// Labels the frames with an output: `outputs[i] = Some((box, confidence, state))`,
/// `truth[i]` the annotation (`None` = target absent). Frames past either list are dropped.
pub fn label_frames(
    outputs: &[Option<(BBox, f32, TrackState)>],
    truth: &[Option<BBox>],
) -> Vec<FrameLabel> {
    outputs
        .iter()
        .zip(truth)
        .filter_map(|(o, t)| {
            let (b, confidence, state) = (*o)?;
            let good = match t {
                None => Some(false),
                Some(t) => {
                    let iou = if b.is_finite() { b.iou(t) } else { 0.0 };
                    if iou >= GOOD_IOU {
                        Some(true)
                    } else if iou < BAD_IOU {
                        Some(false)
                    } else {
                        None
                    }
                }
            };
            Some(FrameLabel {
                confidence,
                lost: state == TrackState::Lost,
                good,
            })
        })
        .collect()
}

/// Scores of the confidence and the lost state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LostScores {
    /// Good frames.
    pub good_frames: usize,
    /// Bad frames.
    pub bad_frames: usize,
    /// ROC-AUC of the confidence, good against bad (NaN without both kinds).
    pub confidence_auc: f64,
    /// Frames in the lost state.
    pub lost_frames: usize,
    /// Fraction of lost frames that are bad (NaN without lost frames).
    pub lost_precision: f64,
    /// Fraction of bad frames in the lost state (NaN without bad frames).
    pub lost_recall: f64,
}

/// Mann–Whitney ROC-AUC of `pos` scores over `neg` scores (NaN when either is empty).
pub fn roc_auc(pos: &[f32], neg: &[f32]) -> f64 {
    if pos.is_empty() || neg.is_empty() {
        return f64::NAN;
    }
    let mut all: Vec<(f32, bool)> = pos
        .iter()
        .map(|&v| (v, true))
        .chain(neg.iter().map(|&v| (v, false)))
        .collect();
    all.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Sum of positive ranks with ties given their mean rank.
    let mut rank_sum = 0.0f64;
    let mut i = 0;
    while i < all.len() {
        let mut j = i;
        while j < all.len() && all[j].0.total_cmp(&all[i].0).is_eq() {
            j += 1;
        }
        let mean_rank = (i + 1 + j) as f64 / 2.0;
        rank_sum += all[i..j].iter().filter(|x| x.1).count() as f64 * mean_rank;
        i = j;
    }
    let (np, nn) = (pos.len() as f64, neg.len() as f64);
    (rank_sum - np * (np + 1.0) / 2.0) / (np * nn)
}

/// Scores labelled frames (of one sequence, or pooled over many).
pub fn score_lost(frames: &[FrameLabel]) -> LostScores {
    let good: Vec<f32> = frames
        .iter()
        .filter(|f| f.good == Some(true))
        .map(|f| f.confidence)
        .collect();
    let bad: Vec<f32> = frames
        .iter()
        .filter(|f| f.good == Some(false))
        .map(|f| f.confidence)
        .collect();
    let lost = frames.iter().filter(|f| f.lost).count();
    let lost_bad = frames
        .iter()
        .filter(|f| f.lost && f.good == Some(false))
        .count();
    let ratio = |a: usize, b: usize| {
        if b == 0 {
            f64::NAN
        } else {
            a as f64 / b as f64
        }
    };
    LostScores {
        good_frames: good.len(),
        bad_frames: bad.len(),
        confidence_auc: roc_auc(&good, &bad),
        lost_frames: lost,
        lost_precision: ratio(lost_bad, lost),
        lost_recall: ratio(lost_bad, bad.len()),
    }
}

/// Frames to re-acquire after each reappearance of the target (`None`: never, before the
/// sequence ends or the target leaves again). Reappearances before the tracker's first
/// output are ignored.
pub fn reacquire_frames(
    outputs: &[Option<(BBox, f32, TrackState)>],
    truth: &[Option<BBox>],
) -> Vec<Option<usize>> {
    let Some(first) = outputs.iter().position(Option::is_some) else {
        return Vec::new();
    };
    let n = outputs.len().min(truth.len());
    let mut res = Vec::new();
    let mut t = first.saturating_add(1);
    while t < n {
        if truth[t].is_some() && truth[t - 1].is_none() {
            let start = t;
            let mut found = None;
            while t < n {
                let Some(g) = truth[t] else { break };
                if let Some((b, _, s)) = outputs[t] {
                    if s != TrackState::Lost && b.is_finite() && b.iou(&g) >= GOOD_IOU {
                        found = Some(t - start);
                        break;
                    }
                }
                t += 1;
            }
            res.push(found);
        }
        t += 1;
    }
    res
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roc_auc_is_a_probability_of_correct_ordering() {
        assert_eq!(roc_auc(&[0.9, 0.8], &[0.1, 0.2]), 1.0);
        assert_eq!(roc_auc(&[0.1], &[0.9]), 0.0);
        assert_eq!(roc_auc(&[0.5, 0.5], &[0.5]), 0.5);
        assert!((roc_auc(&[0.3, 0.9], &[0.5]) - 0.5).abs() < 1e-12);
        assert!(roc_auc(&[], &[0.5]).is_nan());
    }

    #[test]
    fn frames_are_labelled_and_lost_state_scored() {
        let b = BBox::new(0.0, 0.0, 10.0, 10.0);
        let far = BBox::new(50.0, 50.0, 10.0, 10.0);
        let half = BBox::new(3.0, 0.0, 10.0, 10.0); // IoU 7/13 ≥ 0.5: good
        let mid = BBox::new(6.0, 0.0, 10.0, 10.0); // IoU 4/16 = 0.25: neither
        let outputs = vec![
            None,
            Some((b, 0.9, TrackState::Tracking)),
            Some((half, 0.8, TrackState::Tracking)),
            Some((mid, 0.5, TrackState::Uncertain)),
            Some((far, 0.2, TrackState::Uncertain)),
            Some((b, 0.1, TrackState::Lost)),
            Some((b, 0.7, TrackState::Lost)),
        ];
        let truth = vec![Some(b), Some(b), Some(b), Some(b), Some(b), None, Some(b)];
        let labels = label_frames(&outputs, &truth);
        assert_eq!(labels.len(), 6);
        let s = score_lost(&labels);
        assert_eq!((s.good_frames, s.bad_frames), (3, 2));
        assert_eq!(s.confidence_auc, 1.0);
        assert_eq!(s.lost_frames, 2);
        // Frame 6 is lost but the box is on the target: not bad.
        assert_eq!(s.lost_precision, 0.5);
        assert_eq!(s.lost_recall, 0.5);
    }

    #[test]
    fn reacquisition_counts_frames_from_the_reappearance() {
        let b = BBox::new(0.0, 0.0, 10.0, 10.0);
        let far = BBox::new(50.0, 50.0, 10.0, 10.0);
        let truth = vec![
            Some(b),
            None,
            None,
            Some(b),
            Some(b),
            Some(b),
            None,
            Some(b),
        ];
        let outputs = vec![
            None,
            Some((far, 0.1, TrackState::Lost)),
            Some((far, 0.1, TrackState::Lost)),
            Some((far, 0.1, TrackState::Lost)),
            Some((b, 0.9, TrackState::Lost)),
            Some((b, 0.9, TrackState::Reacquired)),
            Some((b, 0.1, TrackState::Lost)),
            Some((far, 0.1, TrackState::Lost)),
        ];
        assert_eq!(reacquire_frames(&outputs, &truth), vec![Some(2), None]);
        assert!(reacquire_frames(&[None], &truth).is_empty());
    }
}
