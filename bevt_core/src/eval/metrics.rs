//! One-pass-evaluation metrics (ALGORITHM.md §8): centre location error, IoU, precision
//! at 20 px and the success-plot AUC. Frames whose ground truth is missing (`None`, NaN
//! in annotation files) are excluded.

use crate::geometry::BBox;
use serde::{Deserialize, Serialize};

/// Precision threshold of the headline score, pixels.
pub const PRECISION_THRESHOLD_PX: f32 = 20.0;
/// Largest threshold of the precision curve, pixels (curve sampled at 0, 1, …, 50).
pub const PRECISION_CURVE_MAX_PX: usize = 50;
/// Number of IoU thresholds of the success curve: 0, 0.05, …, 1.
pub const SUCCESS_STEPS: usize = 21;

/// Per-sequence scores.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SequenceScores {
    /// Frames with ground truth.
    pub frames_scored: usize,
    /// Fraction of scored frames with centre error ≤ 20 px.
    pub precision_20: f64,
    /// Mean of the success curve (area under it).
    pub auc: f64,
    /// Success at IoU 0.5.
    pub success_50: f64,
    /// Mean centre error, pixels.
    pub mean_center_error: f64,
    /// Precision at 0..=50 px.
    pub precision_curve: Vec<f64>,
    /// Success at IoU 0, 0.05, …, 1 (IoU strictly greater than the threshold).
    pub success_curve: Vec<f64>,
}

/// Centre error in pixels (infinite when the prediction is not finite).
pub fn center_error(pred: &BBox, gt: &BBox) -> f32 {
    if !pred.is_finite() {
        return f32::INFINITY;
    }
    pred.center().distance(&gt.center())
}

/// Scores predictions against ground truth; `gt[i] == None` frames are skipped. Missing
/// predictions (shorter list) count as failures.
pub fn score_sequence(pred: &[BBox], gt: &[Option<BBox>]) -> SequenceScores {
    let mut errs = Vec::new();
    let mut ious = Vec::new();
    for (i, g) in gt.iter().enumerate() {
        let Some(g) = g else { continue };
        match pred.get(i) {
            Some(p) if p.is_finite() => {
                errs.push(center_error(p, g));
                ious.push(p.iou(g));
            }
            _ => {
                errs.push(f32::INFINITY);
                ious.push(0.0);
            }
        }
    }
    let n = errs.len().max(1) as f64;
    let precision_curve: Vec<f64> = (0..=PRECISION_CURVE_MAX_PX)
        .map(|t| errs.iter().filter(|&&e| e <= t as f32).count() as f64 / n)
        .collect();
    let success_curve: Vec<f64> = (0..SUCCESS_STEPS)
        .map(|k| {
            let t = k as f32 / (SUCCESS_STEPS - 1) as f32;
            ious.iter().filter(|&&v| v > t).count() as f64 / n
        })
        .collect();
    let finite: Vec<f64> = errs
        .iter()
        .filter(|e| e.is_finite())
        .map(|&e| e as f64)
        .collect();
    SequenceScores {
        frames_scored: errs.len(),
        precision_20: errs
            .iter()
            .filter(|&&e| e <= PRECISION_THRESHOLD_PX)
            .count() as f64
            / n,
        auc: success_curve.iter().sum::<f64>() / SUCCESS_STEPS as f64,
        success_50: ious.iter().filter(|&&v| v > 0.5).count() as f64 / n,
        mean_center_error: if finite.is_empty() {
            f64::NAN
        } else {
            finite.iter().sum::<f64>() / finite.len() as f64
        },
        precision_curve,
        success_curve,
    }
}

/// Element-wise mean of several curves (sequence-mean averaging, as the UAV123/OTB toolkit).
pub fn mean_curve(curves: &[&[f64]]) -> Vec<f64> {
    let Some(first) = curves.first() else {
        return Vec::new();
    };
    (0..first.len())
        .map(|i| {
            curves
                .iter()
                .map(|c| c.get(i).copied().unwrap_or(0.0))
                .sum::<f64>()
                / curves.len() as f64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn perfect_tracking_scores_one() {
        let b = BBox::new(10.0, 10.0, 20.0, 20.0);
        let s = score_sequence(&[b, b], &[Some(b), Some(b)]);
        assert_eq!(s.precision_20, 1.0);
        // IoU 1 exceeds every threshold but the last (1.0): 20 of 21 points.
        assert!((s.auc - 20.0 / 21.0).abs() < 1e-12);
    }

    #[test]
    fn hand_computed_case() {
        let g = BBox::new(0.0, 0.0, 10.0, 10.0);
        // Frame 0: shifted by 5 px (IoU 50/150 = 1/3, error 5); frame 1: 30 px away (IoU 0);
        // frame 2: no ground truth (excluded).
        let p = [
            BBox::new(5.0, 0.0, 10.0, 10.0),
            BBox::new(30.0, 0.0, 10.0, 10.0),
            BBox::new(0.0, 0.0, 1.0, 1.0),
        ];
        let s = score_sequence(&p, &[Some(g), Some(g), None]);
        assert_eq!(s.frames_scored, 2);
        assert_eq!(s.precision_20, 0.5);
        // IoU 1/3 > t for t = 0, .05, …, .30 (7 thresholds) → curve 0.5 there, 0 after.
        assert!((s.auc - 7.0 * 0.5 / 21.0).abs() < 1e-12);
        assert_eq!(s.success_50, 0.0);
        assert!((s.mean_center_error - 17.5).abs() < 1e-9);
    }

    #[test]
    fn missing_and_nan_predictions_are_failures() {
        let g = BBox::new(0.0, 0.0, 10.0, 10.0);
        let s = score_sequence(&[BBox::new(f32::NAN, 0.0, 1.0, 1.0)], &[Some(g), Some(g)]);
        assert_eq!(s.precision_20, 0.0);
        assert_eq!(s.auc, 0.0);
    }

    #[test]
    fn mean_curve_averages_pointwise() {
        let a = [1.0, 0.0];
        let b = [0.0, 0.0];
        assert_eq!(mean_curve(&[&a, &b]), vec![0.5, 0.0]);
    }
}
