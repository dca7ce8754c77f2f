//! Metrics of the confidence and the track states against ground truth (issues 8 and 20).
//!
//! A frame the tracker produced an output for is **good** when the target is annotated and
//! the box overlaps it with IoU ≥ [`GOOD_IOU`], **bad** when the target is absent from the
//! ground truth (NaN row) or IoU < [`BAD_IOU`]; frames in between are neither. A frame is
//! **flagged** when its state is `uncertain` or `lost`. Then:
//! - the ROC-AUC of the confidence for good frames against bad ones (the probability that a
//!   random good frame is more confident than a random bad one, ties counting one half);
//! - the precision and recall of the flags against the bad frames, and the same for the
//!   `lost` state alone (precision: flagged frames that are bad; recall: bad frames that
//!   are flagged; frames that are neither count as not bad);
//! - the time to flag each **failure episode**. Walking a sequence's processed frames in
//!   order and ignoring the frames that are neither, an episode starts at a bad frame that
//!   is the first labelled frame or follows a good one, and lasts until (not including) the
//!   next good frame or the sequence's end; the frames that are neither inside it belong to
//!   it. Its time to flag is the number of frames from its first frame to its first flagged
//!   frame (0: flagged on the first bad frame); an episode with no flagged frame is never
//!   flagged. The median is over the flagged episodes (see [`flag_delays`]);
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
    /// In the `uncertain` or `lost` state.
    pub flagged: bool,
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
                flagged: matches!(state, TrackState::Uncertain | TrackState::Lost),
                good,
            })
        })
        .collect()
}

/// Scores of the confidence, the flags and the lost state.
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
    /// Frames flagged (`uncertain` or `lost`).
    pub flagged_frames: usize,
    /// Fraction of flagged frames that are bad (NaN without flagged frames).
    pub flag_precision: f64,
    /// Fraction of bad frames that are flagged (NaN without bad frames).
    pub flag_recall: f64,
    /// Failure episodes (module doc).
    pub episodes: usize,
    /// Episodes with no flagged frame.
    pub episodes_never_flagged: usize,
    /// Median frames from an episode's start to its first flag, over the flagged episodes
    /// (the mean of the two middle ones for an even count; NaN when none was flagged).
    pub time_to_flag_median: f64,
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

/// Scores labelled frames: `sequences[i]` holds one sequence's frames in order (pass one
/// slice for one sequence; several are pooled, episodes never spanning two sequences).
pub fn score_lost(sequences: &[&[FrameLabel]]) -> LostScores {
    let frames = || sequences.iter().flat_map(|s| s.iter());
    let good: Vec<f32> = frames()
        .filter(|f| f.good == Some(true))
        .map(|f| f.confidence)
        .collect();
    let bad: Vec<f32> = frames()
        .filter(|f| f.good == Some(false))
        .map(|f| f.confidence)
        .collect();
    let count = |pick: &dyn Fn(&FrameLabel) -> bool| {
        let all = frames().filter(|f| pick(f)).count();
        let bad = frames()
            .filter(|f| pick(f) && f.good == Some(false))
            .count();
        (all, bad)
    };
    let (lost, lost_bad) = count(&|f| f.lost);
    let (flagged, flagged_bad) = count(&|f| f.flagged);
    let delays: Vec<Option<usize>> = sequences.iter().flat_map(|s| flag_delays(s)).collect();
    let mut found: Vec<usize> = delays.iter().flatten().copied().collect();
    LostScores {
        good_frames: good.len(),
        bad_frames: bad.len(),
        confidence_auc: roc_auc(&good, &bad),
        lost_frames: lost,
        lost_precision: ratio(lost_bad, lost),
        lost_recall: ratio(lost_bad, bad.len()),
        flagged_frames: flagged,
        flag_precision: ratio(flagged_bad, flagged),
        flag_recall: ratio(flagged_bad, bad.len()),
        episodes: delays.len(),
        episodes_never_flagged: delays.len() - found.len(),
        time_to_flag_median: median(&mut found),
    }
}

/// `a / b`, NaN when `b` is 0.
fn ratio(a: usize, b: usize) -> f64 {
    if b == 0 {
        f64::NAN
    } else {
        a as f64 / b as f64
    }
}

/// Median of `v` (mean of the two middle values for an even count; NaN when empty).
fn median(v: &mut [usize]) -> f64 {
    v.sort_unstable();
    let n = v.len();
    match n {
        0 => f64::NAN,
        _ if n % 2 == 1 => v[n / 2] as f64,
        _ => (v[n / 2 - 1] + v[n / 2]) as f64 / 2.0,
    }
}

/// The time to flag of each failure episode of one sequence's labelled frames, in order
/// (module doc): `Some(frames)` from the episode's first frame to its first flagged
/// frame, `None` when no frame of it was flagged.
pub fn flag_delays(frames: &[FrameLabel]) -> Vec<Option<usize>> {
    let mut res = Vec::new();
    // The open episode: its first frame's index and its first flag's, if any.
    let mut open: Option<(usize, Option<usize>)> = None;
    for (i, f) in frames.iter().enumerate() {
        match f.good {
            Some(true) => {
                if let Some((start, flag)) = open.take() {
                    res.push(flag.map(|k| k - start));
                }
            }
            Some(false) if open.is_none() => open = Some((i, None)),
            _ => {}
        }
        if let Some((_, flag)) = open.as_mut() {
            if flag.is_none() && f.flagged {
                *flag = Some(i);
            }
        }
    }
    if let Some((start, flag)) = open {
        res.push(flag.map(|k| k - start));
    }
    res
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
        let s = score_lost(&[&labels]);
        assert_eq!((s.good_frames, s.bad_frames), (3, 2));
        assert_eq!(s.confidence_auc, 1.0);
        assert_eq!(s.lost_frames, 2);
        // Frame 6 is lost but the box is on the target: not bad.
        assert_eq!(s.lost_precision, 0.5);
        assert_eq!(s.lost_recall, 0.5);
        // Flagged: frames 3 (neither), 4 and 5 (bad), 6 (good).
        assert_eq!(s.flagged_frames, 4);
        assert_eq!(s.flag_precision, 0.5);
        assert_eq!(s.flag_recall, 1.0);
        // One episode (frames 4-5), flagged on its first frame.
        assert_eq!((s.episodes, s.episodes_never_flagged), (1, 0));
        assert_eq!(s.time_to_flag_median, 0.0);
    }

    /// A hand-made labelled frame: `g` is `'g'` good, `'b'` bad, `'n'` neither; `flag` is
    /// `'-'` tracking, `'u'` uncertain, `'l'` lost.
    fn frames(g: &str, flag: &str) -> Vec<FrameLabel> {
        g.chars()
            .zip(flag.chars())
            .map(|(g, f)| FrameLabel {
                confidence: if g == 'g' { 0.9 } else { 0.1 },
                lost: f == 'l',
                flagged: f != '-',
                good: match g {
                    'g' => Some(true),
                    'b' => Some(false),
                    _ => None,
                },
            })
            .collect()
    }

    #[test]
    fn episodes_run_from_a_bad_frame_after_a_good_one_to_the_next_good_one() {
        // Flags on the good frames that end episodes 1 (2-4) and 2 (6-7) do not count;
        // episode 3 (10-end) is flagged at 11 (lost): 1 frame.
        let f = frames("gnbbngbbggbbb", "-----u--u--ll");
        assert_eq!(flag_delays(&f), vec![None, None, Some(1)]);
        // Episode 1 starts at 2 (the neither frame 1 is not its start) and is flagged at
        // 4, a neither frame inside it: 2 frames. Episode 2 is never flagged (the flag at
        // 9 comes after it ended).
        let f = frames("gnbbngbbggbbb", "----u----u-l-");
        assert_eq!(flag_delays(&f), vec![Some(2), None, Some(1)]);
        let s = score_lost(&[&f]);
        assert_eq!((s.episodes, s.episodes_never_flagged), (3, 1));
        assert_eq!(s.time_to_flag_median, 1.5);
        // A flag before the episode (on a neither frame) does not count; one still up on
        // its first frame does (0).
        assert_eq!(flag_delays(&frames("gnb", "-u-")), vec![None]);
        assert_eq!(flag_delays(&frames("gnb", "-uu")), vec![Some(0)]);
        // The first labelled frame bad opens an episode.
        assert_eq!(flag_delays(&frames("nbg", "---")), vec![None]);
    }

    #[test]
    fn sequences_without_bad_frames_or_with_every_frame_flagged_score_sensibly() {
        // No bad frames: no episodes, recall undefined, every flag wrong.
        let clean = frames("ggng", "-u--");
        let s = score_lost(&[&clean]);
        assert_eq!(
            (s.bad_frames, s.episodes, s.episodes_never_flagged),
            (0, 0, 0)
        );
        assert!(s.flag_recall.is_nan() && s.lost_recall.is_nan());
        assert!(s.time_to_flag_median.is_nan() && s.confidence_auc.is_nan());
        assert_eq!(s.flag_precision, 0.0);
        assert!(s.lost_precision.is_nan());
        // Every frame flagged: recall 1, precision the bad share.
        let all = frames("gbbg", "uull");
        let s = score_lost(&[&all]);
        assert_eq!((s.flag_recall, s.flag_precision), (1.0, 0.5));
        assert_eq!((s.lost_recall, s.lost_precision), (0.5, 0.5));
        assert_eq!(s.time_to_flag_median, 0.0);
        // Nothing at all.
        let s = score_lost(&[]);
        assert_eq!((s.flagged_frames, s.episodes), (0, 0));
        assert!(s.flag_precision.is_nan());
    }

    #[test]
    fn pooled_episodes_do_not_span_sequences() {
        // Alone, each sequence has one episode; joined end to start they would make one.
        let a = frames("gbb", "---");
        let b = frames("bbg", "-u-");
        let s = score_lost(&[&a, &b]);
        assert_eq!((s.episodes, s.episodes_never_flagged), (2, 1));
        assert_eq!(s.time_to_flag_median, 1.0);
        let joined: Vec<FrameLabel> = a.iter().chain(&b).copied().collect();
        assert_eq!(score_lost(&[&joined]).episodes, 1);
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
