//! Multi-frame consensus verification (paper §III-D, Algorithm 1; ALGORITHM.md §6).
//!
//! The consensus score `C = exp(−‖M_ideal − M_curr‖)` compares the current (fftshifted)
//! response map with an ideal response model kept as a slow running average. `C` lies in
//! `(0, 1]`: 1 for identical maps, smaller as they differ. Learning is skipped at or below
//! the low threshold and reinforced at or above the high one.

use crate::geometry::GridSize;
use serde::{Deserialize, Serialize};

/// Power-iteration limit of the spectral norm.
const POWER_ITERATIONS: usize = 100;
/// Relative change below which power iteration stops.
const POWER_TOLERANCE: f64 = 1e-7;

/// Which matrix norm measures the distance between response maps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConsensusNorm {
    /// Reference MATLAB `norm(abs(A))`: the largest singular value of the element-wise
    /// absolute difference.
    Spectral,
    /// The paper's squared L2 (Frobenius) norm `Σ (A_ij)²`.
    FrobeniusSq,
}

/// What to do with a frame after verification.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// Do not learn from this frame.
    Skip,
    /// Learn with this appearance-model rate.
    Learn {
        /// Learning rate η.
        rate: f32,
    },
}

/// Which score drives the learning decision.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VerificationScore {
    /// The reference consensus `C` with `threshold_low`/`threshold_high` (paper fidelity).
    Reference,
    /// The per-frame confidence of [`crate::confidence`] through a [`LearningGate`].
    Confidence,
}

/// Verification thresholds and rates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VerifyParams {
    /// Norm used for the distance.
    pub norm: ConsensusNorm,
    /// At or below: skip learning.
    pub threshold_low: f32,
    /// At or above: reinforced learning.
    pub threshold_high: f32,
    /// Normal appearance learning rate.
    pub rate: f32,
    /// Reinforced appearance learning rate.
    pub reinforced_rate: f32,
}

/// Consensus score `exp(−‖a − b‖)` of two maps on `grid` (row-major). `scratch` holds
/// `grid.w + grid.h` values.
pub fn consensus_score(
    a: &[f32],
    b: &[f32],
    grid: GridSize,
    norm: ConsensusNorm,
    scratch: &mut Vec<f64>,
) -> f32 {
    let n = match norm {
        ConsensusNorm::FrobeniusSq => a
            .iter()
            .zip(b)
            .map(|(x, y)| ((x - y) as f64).powi(2))
            .sum::<f64>(),
        ConsensusNorm::Spectral => spectral_norm_abs_diff(a, b, grid, scratch),
    };
    let c = (-n).exp() as f32;
    if c.is_finite() {
        c
    } else {
        0.0
    }
}

/// Largest singular value of `|a − b|` by power iteration on `AᵀA` (A non-negative, so
/// the all-ones start vector is never orthogonal to the leading singular vector).
fn spectral_norm_abs_diff(a: &[f32], b: &[f32], grid: GridSize, scratch: &mut Vec<f64>) -> f64 {
    let (h, w) = (grid.h, grid.w);
    scratch.resize(w + h, 0.0);
    let (v, u) = scratch.split_at_mut(w);
    v.iter_mut().for_each(|x| *x = 1.0 / (w as f64).sqrt());
    let m = |r: usize, c: usize| (a[r * w + c] - b[r * w + c]).abs() as f64;
    let mut sigma = 0.0f64;
    for _ in 0..POWER_ITERATIONS {
        // u = A v
        for (r, ur) in u.iter_mut().enumerate() {
            *ur = (0..w).map(|c| m(r, c) * v[c]).sum();
        }
        let un = u.iter().map(|x| x * x).sum::<f64>().sqrt();
        if un == 0.0 {
            return 0.0;
        }
        // v = Aᵀ u / ‖Aᵀ u‖ ; σ = ‖A v‖ estimate
        for (c, vc) in v.iter_mut().enumerate() {
            *vc = (0..h).map(|r| m(r, c) * u[r]).sum::<f64>() / un;
        }
        let vn = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if vn == 0.0 {
            return 0.0;
        }
        v.iter_mut().for_each(|x| *x /= vn);
        let prev = sigma;
        sigma = vn;
        if (sigma - prev).abs() <= POWER_TOLERANCE * sigma {
            break;
        }
    }
    sigma
}

/// Algorithm 1's decision for a score `c`.
pub fn verdict(c: f32, p: &VerifyParams) -> Verdict {
    if c <= p.threshold_low || !c.is_finite() {
        Verdict::Skip
    } else if c >= p.threshold_high {
        Verdict::Learn {
            rate: p.reinforced_rate,
        }
    } else {
        Verdict::Learn { rate: p.rate }
    }
}

/// Parameters of the [`LearningGate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateParams {
    /// Relative score below this: skip learning.
    pub skip_below: f32,
    /// Relative score at or above this: reinforced learning.
    pub reinforce_from: f32,
    /// Normal rate.
    pub rate: f32,
    /// Reinforced rate.
    pub reinforced_rate: f32,
    /// Skipped frames in a row after which the next frame is learned at the normal rate
    /// whatever its confidence, so verification cannot lock the tracker out of learning.
    pub max_consecutive_skips: usize,
}

/// Skip / normal / reinforced learning driven by the score relative to its running level
/// ([`crate::confidence::ConfidenceModel::relative`]), with a warm-up (always the
/// reinforced rate, which is what the reference does on every HOG frame) and a bound on
/// consecutive skips.
#[derive(Debug, Clone, PartialEq)]
pub struct LearningGate {
    params: GateParams,
    skipped_in_a_row: usize,
}

impl LearningGate {
    /// A gate that has skipped nothing yet.
    pub fn new(params: GateParams) -> Self {
        Self {
            params,
            skipped_in_a_row: 0,
        }
    }

    /// Replaces the thresholds and rates, keeping the count of skipped frames (for
    /// [`crate::BevtTracker::retune`]).
    pub fn set_params(&mut self, params: GateParams) {
        self.params = params;
    }

    /// Frames skipped in a row so far.
    pub fn skipped_in_a_row(&self) -> usize {
        self.skipped_in_a_row
    }

    /// The decision for a frame of relative score `confidence` (non-finite counts as 0).
    pub fn decide(&mut self, confidence: f32, warming_up: bool) -> Verdict {
        let p = self.params;
        let c = if confidence.is_finite() {
            confidence
        } else {
            0.0
        };
        let v = if warming_up {
            Verdict::Learn {
                rate: p.reinforced_rate,
            }
        } else if c < p.skip_below {
            if self.skipped_in_a_row >= p.max_consecutive_skips {
                Verdict::Learn { rate: p.rate }
            } else {
                Verdict::Skip
            }
        } else if c >= p.reinforce_from {
            Verdict::Learn {
                rate: p.reinforced_rate,
            }
        } else {
            Verdict::Learn { rate: p.rate }
        };
        self.skipped_in_a_row = match v {
            Verdict::Skip => self.skipped_in_a_row.saturating_add(1),
            Verdict::Learn { .. } => 0,
        };
        v
    }
}

/// `m_ideal ← (1 − γ)·m_ideal + γ·m_curr`.
pub fn update_ideal(m_ideal: &mut [f32], m_curr: &[f32], gamma: f32) {
    for (a, b) in m_ideal.iter_mut().zip(m_curr) {
        *a = (1.0 - gamma) * *a + gamma * b;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    fn peak_map(g: GridSize, cy: f32, cx: f32) -> Vec<f32> {
        let mut m = vec![0.0; g.len()];
        for r in 0..g.h {
            for c in 0..g.w {
                let d2 = (r as f32 - cy).powi(2) + (c as f32 - cx).powi(2);
                m[r * g.w + c] = (-d2 / 8.0).exp();
            }
        }
        m
    }

    #[test]
    fn identical_maps_score_one_and_shifted_maps_score_lower() {
        let g = GridSize { h: 20, w: 20 };
        let a = peak_map(g, 10.0, 10.0);
        let mut s = Vec::new();
        for norm in [ConsensusNorm::Spectral, ConsensusNorm::FrobeniusSq] {
            assert_eq!(consensus_score(&a, &a, g, norm, &mut s), 1.0);
            let near = consensus_score(&a, &peak_map(g, 10.0, 11.0), g, norm, &mut s);
            let far = consensus_score(&a, &peak_map(g, 10.0, 15.0), g, norm, &mut s);
            assert!(
                near < 1.0 && far < near && far > 0.0,
                "{norm:?}: {near} {far}"
            );
        }
    }

    #[test]
    fn spectral_norm_matches_svd() {
        let g = GridSize { h: 7, w: 5 };
        let a: Vec<f32> = (0..35).map(|i| ((i * 13) % 7) as f32 * 0.1).collect();
        let b: Vec<f32> = (0..35).map(|i| ((i * 5) % 11) as f32 * 0.05).collect();
        let m = DMatrix::<f64>::from_fn(7, 5, |r, c| (a[r * 5 + c] - b[r * 5 + c]).abs() as f64);
        let want = m.singular_values().max();
        let got = spectral_norm_abs_diff(&a, &b, g, &mut Vec::new());
        assert!((got - want).abs() < 1e-5 * want, "{got} vs {want}");
    }

    #[test]
    fn verdict_follows_the_thresholds() {
        let p = VerifyParams {
            norm: ConsensusNorm::Spectral,
            threshold_low: 0.2,
            threshold_high: 0.5,
            rate: 0.013,
            reinforced_rate: 0.019,
        };
        assert_eq!(verdict(0.2, &p), Verdict::Skip);
        assert_eq!(verdict(0.3, &p), Verdict::Learn { rate: 0.013 });
        assert_eq!(verdict(0.5, &p), Verdict::Learn { rate: 0.019 });
        assert_eq!(verdict(f32::NAN, &p), Verdict::Skip);
    }

    fn gate(max: usize) -> LearningGate {
        LearningGate::new(GateParams {
            skip_below: 0.3,
            reinforce_from: 0.8,
            rate: 0.013,
            reinforced_rate: 0.019,
            max_consecutive_skips: max,
        })
    }

    #[test]
    fn gate_skips_learns_and_reinforces_by_confidence_and_learns_in_warmup() {
        let mut g = gate(5);
        assert_eq!(g.decide(0.0, true), Verdict::Learn { rate: 0.019 });
        assert_eq!(g.decide(0.1, false), Verdict::Skip);
        assert_eq!(g.decide(f32::NAN, false), Verdict::Skip);
        assert_eq!(g.skipped_in_a_row(), 2);
        assert_eq!(g.decide(0.5, false), Verdict::Learn { rate: 0.013 });
        assert_eq!(g.skipped_in_a_row(), 0);
        assert_eq!(g.decide(0.8, false), Verdict::Learn { rate: 0.019 });
    }

    #[test]
    fn gate_never_skips_more_than_its_bound_in_a_row() {
        for max in [0, 1, 3, 10] {
            let mut g = gate(max);
            let mut run = 0;
            let mut longest = 0;
            for _ in 0..100 {
                match g.decide(0.01, false) {
                    Verdict::Skip => run += 1,
                    Verdict::Learn { rate } => {
                        assert_eq!(rate, 0.013);
                        run = 0;
                    }
                }
                longest = longest.max(run);
            }
            assert_eq!(longest, max, "bound {max}");
        }
    }
}
