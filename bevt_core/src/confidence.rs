//! Per-frame confidence: how sure the tracker is that its box is on the target, in `[0, 1]`,
//! and the relative score that gates learning.
//!
//! The multi-frame consensus of [`crate::consensus`] compares whole response maps and does
//! not separate good frames from lost ones (issue 8: ROC-AUC 0.47 on the dev set); peak
//! based scores do. Two numbers come out of one frame's winning response:
//!
//! ```text
//! r = peak / peak₀            peak₀: the filter's in-sample peak on its initial model
//! q = PSR = (peak − μ) / σ    μ, σ: the response outside ±exclusion cells of the peak
//! s = r·q  (measure peak_psr; r for `peak`, q for `psr`)
//! confidence = s / (s + half_score)          absolute: comparable across sequences
//! relative   = s / R,  R = mean of s over the first warmup_frames frames, then
//!              R ← (1 − ρ)·R + ρ·s on every frame tracked (not while lost)
//! ```
//!
//! `confidence` drives the track state and is what drivers report. Both `r` and `q` are
//! invariant to the overall scale of the responses (feature gain, feature type), so one
//! `half_score` serves every mode. A running reference is *not* used for it: on the dev
//! set a tracker that has drifted onto background keeps a self-consistent response, and
//! every confidence relative to a running level scored ROC-AUC 0.40–0.80 where the
//! absolute `s` scores 0.94 (README "Confidence and lost state").
//!
//! `relative` drives the learning gate ([`crate::consensus::LearningGate`]): a sudden drop
//! against the recent level (an occlusion) is what learning must not absorb, and a level
//! that keeps adapting cannot lock the tracker out of learning after a slow change.
//!
//! The peak-to-sidelobe ratio (PSR) is that of MOSSE (Bolme et al. 2010).

use crate::config::ConfidenceConfig;
use crate::filter::peak::argmax;
use crate::geometry::GridSize;
use serde::{Deserialize, Serialize};

/// Smallest sidelobe standard deviation used as a divisor (a flat map has PSR 0).
const MIN_SIDELOBE_STD: f64 = 1e-12;
/// Smallest reference level used as a divisor.
const MIN_REFERENCE: f32 = 1e-12;

/// Which measure the confidence is made of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConfidenceMeasure {
    /// `r`: the response peak over the initial filter's in-sample peak.
    Peak,
    /// `q`: the peak-to-sidelobe ratio of the response.
    Psr,
    /// `r·q`, their product (the default).
    PeakPsr,
}

/// Peak-to-sidelobe ratio of a row-major response `map` on `grid` (unshifted or shifted:
/// the exclusion square wraps around the borders). 0 for a flat or degenerate map.
pub fn psr(map: &[f32], grid: GridSize, exclusion: usize) -> f32 {
    let (h, w) = (grid.h, grid.w);
    if map.len() < grid.len() || grid.is_empty() {
        return 0.0;
    }
    let (pr, pc, peak) = argmax(map, grid);
    let near = |i: usize, p: usize, n: usize| {
        let d = i.abs_diff(p);
        d.min(n - d) <= exclusion
    };
    let (mut n, mut sum, mut sq) = (0usize, 0.0f64, 0.0f64);
    for r in 0..h {
        let row_near = near(r, pr, h);
        for c in 0..w {
            if row_near && near(c, pc, w) {
                continue;
            }
            let v = map[r * w + c] as f64;
            if v.is_finite() {
                n += 1;
                sum += v;
                sq += v * v;
            }
        }
    }
    if n == 0 {
        return 0.0;
    }
    let mean = sum / n as f64;
    let std = (sq / n as f64 - mean * mean).max(0.0).sqrt();
    if std < MIN_SIDELOBE_STD {
        return 0.0;
    }
    let v = ((peak as f64 - mean) / std) as f32;
    if v.is_finite() {
        v.max(0.0)
    } else {
        0.0
    }
}

/// One frame's raw measures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measures {
    /// Response peak.
    pub peak: f32,
    /// Peak-to-sidelobe ratio.
    pub psr: f32,
}

/// The confidence and the gate's running reference level.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfidenceModel {
    params: ConfidenceConfig,
    initial_peak: f32,
    reference: f32,
    seen: usize,
}

impl ConfidenceModel {
    /// A model for a filter whose in-sample peak on its initial model is `initial_peak`.
    pub fn new(params: ConfidenceConfig, initial_peak: f32) -> Self {
        Self {
            params,
            initial_peak: if initial_peak.is_finite() {
                initial_peak.max(MIN_REFERENCE)
            } else {
                MIN_REFERENCE
            },
            reference: 0.0,
            seen: 0,
        }
    }

    /// Replaces the parameters, keeping the running reference level and the initial peak
    /// (for [`crate::BevtTracker::retune`]).
    pub fn set_params(&mut self, params: ConfidenceConfig) {
        self.params = params;
    }

    /// True while the gate's reference is still the plain mean of the first frames.
    pub fn warming_up(&self) -> bool {
        self.seen < self.params.warmup_frames
    }

    /// The gate's current reference level of `s`.
    pub fn reference(&self) -> f32 {
        self.reference
    }

    /// The score `s` of the configured measure (≥ 0; 0 for non-finite input).
    pub fn score(&self, m: Measures) -> f32 {
        let r = m.peak / self.initial_peak;
        let s = match self.params.measure {
            ConfidenceMeasure::Peak => r,
            ConfidenceMeasure::Psr => m.psr,
            ConfidenceMeasure::PeakPsr => r * m.psr,
        };
        if s.is_finite() {
            s.max(0.0)
        } else {
            0.0
        }
    }

    /// Confidence in `[0, 1)` of a score: `s / (s + half_score)`.
    pub fn confidence(&self, s: f32) -> f32 {
        let c = s / (s + self.params.half_score);
        if c.is_finite() {
            c.clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// `s` relative to the running reference (1 before any reference exists).
    pub fn relative(&self, s: f32) -> f32 {
        if self.seen == 0 {
            return 1.0;
        }
        let v = s / self.reference.max(MIN_REFERENCE);
        if v.is_finite() {
            v.max(0.0)
        } else {
            0.0
        }
    }

    /// Folds a tracked frame's score into the reference: the mean during the warm-up, then
    /// the running average. Non-finite scores are ignored.
    pub fn observe(&mut self, s: f32) {
        if !s.is_finite() {
            return;
        }
        if self.warming_up() {
            let k = self.seen as f32;
            self.reference = (self.reference * k + s) / (k + 1.0);
        } else {
            let r = self.params.reference_rate;
            self.reference = (1.0 - r) * self.reference + r * s;
        }
        self.seen = self.seen.saturating_add(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(measure: ConfidenceMeasure) -> ConfidenceConfig {
        ConfidenceConfig {
            measure,
            half_score: 5.0,
            warmup_frames: 3,
            reference_rate: 0.1,
            psr_exclusion_cells: 2,
        }
    }

    fn peaked(grid: GridSize, height: f32) -> Vec<f32> {
        (0..grid.len())
            .map(|i| {
                let (r, c) = (i / grid.w, i % grid.w);
                let noise = ((i * 37) % 11) as f32 * 0.01;
                if r == 3 && c == 4 {
                    height
                } else {
                    noise
                }
            })
            .collect()
    }

    #[test]
    fn psr_grows_with_the_peak_and_is_zero_on_flat_maps() {
        let g = GridSize { h: 12, w: 10 };
        let low = psr(&peaked(g, 0.2), g, 1);
        let high = psr(&peaked(g, 1.0), g, 1);
        assert!(high > low && low > 0.0, "{low} {high}");
        assert_eq!(psr(&vec![0.5; g.len()], g, 1), 0.0);
        assert_eq!(psr(&[], g, 1), 0.0);
    }

    #[test]
    fn psr_exclusion_wraps_around_the_border() {
        let g = GridSize { h: 8, w: 8 };
        let mut m = vec![0.0f32; g.len()];
        m[0] = 1.0;
        // A sidelobe just across the border is excluded with exclusion 1.
        m[7] = 0.9;
        m[20] = 0.05;
        m[27] = 0.03;
        let excluded = psr(&m, g, 1);
        let included = psr(&m, g, 0);
        assert!(excluded > included, "{excluded} {included}");
    }

    #[test]
    fn scores_combine_as_documented_and_are_scale_invariant() {
        let m = Measures {
            peak: 0.02,
            psr: 8.0,
        };
        let both = ConfidenceModel::new(params(ConfidenceMeasure::PeakPsr), 0.04);
        assert!((both.score(m) - 4.0).abs() < 1e-6);
        // The same responses ten times larger (another feature gain) score the same.
        let big = ConfidenceModel::new(params(ConfidenceMeasure::PeakPsr), 0.4);
        let m10 = Measures { peak: 0.2, ..m };
        assert!((big.score(m10) - both.score(m)).abs() < 1e-5);
        let peak = ConfidenceModel::new(params(ConfidenceMeasure::Peak), 0.04);
        assert!((peak.score(m) - 0.5).abs() < 1e-6);
        let q = ConfidenceModel::new(params(ConfidenceMeasure::Psr), 0.04);
        assert_eq!(q.score(m), 8.0);
        assert_eq!(
            q.score(Measures {
                peak: f32::NAN,
                psr: f32::NAN
            }),
            0.0
        );
        // Confidence: 0.5 at half_score, monotone, in [0, 1).
        assert!((both.confidence(5.0) - 0.5).abs() < 1e-6);
        assert!(both.confidence(1.0) < both.confidence(2.0));
        assert!(both.confidence(1e30) <= 1.0 && both.confidence(0.0) == 0.0);
        assert_eq!(both.confidence(f32::NAN), 0.0);
    }

    #[test]
    fn relative_score_follows_a_warmup_mean_then_a_running_average() {
        let mut c = ConfidenceModel::new(params(ConfidenceMeasure::PeakPsr), 0.01);
        assert_eq!(c.relative(0.1), 1.0);
        for s in [2.0, 4.0, 3.0] {
            c.observe(s);
        }
        assert!(!c.warming_up());
        assert!((c.reference() - 3.0).abs() < 1e-6);
        assert!((c.relative(1.5) - 0.5).abs() < 1e-6);
        c.observe(13.0);
        assert!((c.reference() - 4.0).abs() < 1e-5);
        c.observe(f32::INFINITY);
        assert!((c.reference() - 4.0).abs() < 1e-5);
    }
}
