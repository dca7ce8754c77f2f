//! Re-detection while the target is lost: where to look, and when to believe a candidate.
//!
//! When the track is lost the filter and appearance model are frozen as they were on the
//! last confident frame. Each lost frame then evaluates at most `windows_per_frame` search
//! windows (a window costs about what one scale of a normal frame costs, so the time per
//! lost frame is bounded):
//!
//! 1. the window at the current position is tracked with the frozen filter (the box keeps
//!    following whatever the filter still sees, e.g. a target that only looks different);
//! 2. the current candidate, if there is one elsewhere, is followed (one more window);
//! 3. the rest of the budget walks a [`SearchPlan`]: tiles covering the whole frame, at
//!    every configured scale, **ordered by distance from the last known position** (so the
//!    search radius grows frame by frame from where the target was), cycling once done.
//!
//! A window is *confident* when its confidence is at least the [`candidate_threshold`]:
//! `reacquire_threshold`, raised to what a score of `reacquire_relative` × the learning
//! gate's reference level on the last confident frame would give. The absolute part keeps
//! background out; the relative part keeps out a look-alike that the frozen filter scores
//! far below the target it was tracking (with colour names a same-coloured object of the
//! target's size reaches an absolute confidence of ~0.6 where the target scored ~0.9). The most confident window becomes the
//! [`Candidate`] (replacing a less confident one); a candidate that stops being confident is
//! dropped. The track is taken back only when one candidate has been confident for
//! `reacquire_frames` frames in a row, so a brief look-alike does not steal the track.

use crate::geometry::Point2;

/// Upper bound on the tiles of one plan (per scale); the stride grows to respect it.
pub const MAX_TILES: usize = 1024;

/// Re-detection parameters (validated by [`crate::TrackerConfig::validate`]).
#[derive(Debug, Clone, PartialEq)]
pub struct RedetectParams {
    /// Search beyond the last position; when off only the window at the last known
    /// position is searched (at the scale of the loss).
    pub enabled: bool,
    /// Search windows evaluated per lost frame.
    pub windows_per_frame: usize,
    /// Scales tried, relative to the target scale when it was lost.
    pub scales: Vec<f32>,
    /// Distance between tile centres as a fraction of the search-window side.
    pub tile_stride: f32,
    /// Confidence at or above which a window is a candidate.
    pub reacquire_threshold: f32,
    /// Fraction of the reference level at the loss a candidate's score must also reach
    /// (see [`candidate_threshold`]).
    pub reacquire_relative: f32,
    /// Frames in a row a candidate must be confident to be accepted.
    pub reacquire_frames: usize,
}

/// One search window: centre (image pixels) and scale relative to the scale at the loss.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    /// Window centre.
    pub center: Point2,
    /// Relative scale.
    pub scale: f32,
}

/// Tiles over the frame at every scale, nearest to the last known position first.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SearchPlan {
    windows: Vec<Window>,
    next: usize,
}

impl SearchPlan {
    /// Plans the search of a `frame_w × frame_h` frame for a target last seen at `from`,
    /// with search windows of side `window_side` pixels at relative scale 1.
    pub fn new(
        from: Point2,
        frame_w: usize,
        frame_h: usize,
        window_side: f32,
        p: &RedetectParams,
    ) -> Self {
        if !p.enabled {
            return Self {
                windows: vec![Window {
                    center: from,
                    scale: 1.0,
                }],
                next: 0,
            };
        }
        let (fw, fh) = (frame_w as f32, frame_h as f32);
        let smallest = p.scales.iter().copied().fold(f32::INFINITY, f32::min);
        let mut stride = (window_side * smallest.min(1.0) * p.tile_stride).max(1.0);
        let count = |s: f32| ((fw / s).ceil() as usize).max(1) * ((fh / s).ceil() as usize).max(1);
        while count(stride) > MAX_TILES {
            stride *= std::f32::consts::SQRT_2;
        }
        let (nx, ny) = (
            ((fw / stride).ceil() as usize).max(1),
            ((fh / stride).ceil() as usize).max(1),
        );
        // Tiles centred so the grid covers the frame symmetrically.
        let (ox, oy) = (
            (fw - (nx - 1) as f32 * stride) / 2.0,
            (fh - (ny - 1) as f32 * stride) / 2.0,
        );
        let mut centers: Vec<Point2> = (0..ny)
            .flat_map(|j| {
                (0..nx).map(move |i| Point2 {
                    x: ox + i as f32 * stride,
                    y: oy + j as f32 * stride,
                })
            })
            .collect();
        centers.insert(0, from);
        centers[1..].sort_by(|a, b| a.distance(&from).total_cmp(&b.distance(&from)));
        let windows = centers
            .iter()
            .flat_map(|&center| p.scales.iter().map(move |&scale| Window { center, scale }))
            .collect();
        Self { windows, next: 0 }
    }

    /// Windows in one full cycle.
    pub fn len(&self) -> usize {
        self.windows.len()
    }

    /// True for an empty plan.
    pub fn is_empty(&self) -> bool {
        self.windows.is_empty()
    }

    /// The next window to evaluate (cycling), `None` for an empty plan.
    pub fn next_window(&mut self) -> Option<Window> {
        let w = *self.windows.get(self.next)?;
        self.next = (self.next + 1) % self.windows.len();
        Some(w)
    }
}

/// The confidence a window needs to be a candidate: `reacquire_threshold`, or the
/// confidence `to_confidence` gives a score of `reacquire_relative × reference` (the
/// learning gate's reference level frozen on the last confident frame) if that is higher.
pub fn candidate_threshold(
    p: &RedetectParams,
    reference: f32,
    to_confidence: impl Fn(f32) -> f32,
) -> f32 {
    let relative = to_confidence(p.reacquire_relative * reference);
    if relative.is_finite() {
        p.reacquire_threshold.max(relative)
    } else {
        p.reacquire_threshold
    }
}

/// A possible target found by the search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// Position, image pixels.
    pub pos: Point2,
    /// Absolute tracker scale (image pixels per base pixel).
    pub scale: f32,
    /// Confidence on its latest frame.
    pub confidence: f32,
    /// Consecutive frames it has been confident.
    pub streak: usize,
}

/// Candidate bookkeeping over lost frames.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CandidateTracker {
    current: Option<Candidate>,
    seen_this_frame: bool,
    near: f32,
}

impl CandidateTracker {
    /// The current candidate.
    pub fn current(&self) -> Option<Candidate> {
        self.current
    }

    /// Forgets any candidate.
    pub fn clear(&mut self) {
        self.current = None;
        self.seen_this_frame = false;
    }

    /// Starts a frame; windows finding something within `near` pixels of the candidate
    /// are the candidate itself (see [`Self::offer`]).
    pub fn begin_frame(&mut self, near: f32) {
        self.seen_this_frame = false;
        self.near = near;
    }

    /// True when `pos` is the current candidate's position (within `near`).
    pub fn is_candidate(&self, pos: Point2) -> bool {
        self.current
            .is_some_and(|c| c.pos.distance(&pos) <= self.near)
    }

    /// The current candidate was re-evaluated this frame at `pos`/`scale` with `confidence`.
    pub fn followed(&mut self, pos: Point2, scale: f32, confidence: f32, threshold: f32) {
        if let Some(c) = self.current.as_mut() {
            if confidence >= threshold {
                c.pos = pos;
                c.scale = scale;
                c.confidence = confidence;
                c.streak = c.streak.saturating_add(1);
                self.seen_this_frame = true;
            } else {
                self.current = None;
            }
        }
    }

    /// A search window found something at `pos`/`scale` with `confidence`: it replaces the
    /// candidate when confident, more confident than the candidate and somewhere else (the
    /// candidate itself is only ever [`Self::followed`]).
    pub fn offer(&mut self, pos: Point2, scale: f32, confidence: f32, threshold: f32) {
        if confidence < threshold || self.is_candidate(pos) {
            return;
        }
        let better = self.current.is_none_or(|c| confidence > c.confidence);
        if better {
            self.current = Some(Candidate {
                pos,
                scale,
                confidence,
                streak: 1,
            });
            self.seen_this_frame = true;
        }
    }

    /// Ends a frame: a candidate not confirmed this frame is dropped. Returns the candidate
    /// when it has been confident for `frames` frames in a row.
    pub fn end_frame(&mut self, frames: usize) -> Option<Candidate> {
        if !self.seen_this_frame {
            self.current = None;
        }
        self.current.filter(|c| c.streak >= frames)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> RedetectParams {
        RedetectParams {
            enabled: true,
            windows_per_frame: 4,
            scales: vec![1.0, 0.8],
            tile_stride: 0.5,
            reacquire_threshold: 0.5,
            reacquire_relative: 0.5,
            reacquire_frames: 3,
        }
    }

    #[test]
    fn candidate_threshold_is_the_higher_of_absolute_and_relative() {
        let conf = |s: f32| s / (s + 5.0);
        let p = params();
        // Target scored s = 40 (confidence 0.89) before the loss: half of it is 20, 0.8.
        assert!((candidate_threshold(&p, 40.0, conf) - 0.8).abs() < 1e-6);
        // A weak reference (or none yet): the absolute threshold.
        assert_eq!(candidate_threshold(&p, 4.0, conf), 0.5);
        assert_eq!(candidate_threshold(&p, 0.0, conf), 0.5);
        let off = RedetectParams {
            reacquire_relative: 0.0,
            ..params()
        };
        assert_eq!(candidate_threshold(&off, 40.0, conf), 0.5);
        assert_eq!(candidate_threshold(&p, 40.0, |_| f32::NAN), 0.5);
    }

    #[test]
    fn plan_covers_the_frame_nearest_first_and_cycles() {
        let from = Point2 { x: 300.0, y: 50.0 };
        let mut plan = SearchPlan::new(from, 320, 240, 100.0, &params());
        // Stride 40 px: 8 × 6 tiles + the last position, two scales each.
        assert_eq!(plan.len(), (8 * 6 + 1) * 2);
        let first = plan.next_window().unwrap();
        assert_eq!(first.center, from);
        assert_eq!(first.scale, 1.0);
        let mut last_d = 0.0;
        let mut max_x: f32 = 0.0;
        let mut min_y = f32::INFINITY;
        for _ in 1..plan.len() {
            let w = plan.next_window().unwrap();
            let d = w.center.distance(&from);
            assert!(d >= last_d - 1e-3);
            last_d = d;
            max_x = max_x.max(w.center.x);
            min_y = min_y.min(w.center.y);
        }
        assert!(max_x > 280.0 && min_y < 40.0);
        assert_eq!(plan.next_window().unwrap().center, from);
    }

    #[test]
    fn plan_size_is_bounded_for_huge_frames_and_tiny_windows() {
        let plan = SearchPlan::new(Point2 { x: 0.0, y: 0.0 }, 8192, 8192, 8.0, &params());
        assert!(plan.len() <= (MAX_TILES + 1) * 2, "{}", plan.len());
        assert!(SearchPlan::default().is_empty());
        let off = RedetectParams {
            enabled: false,
            ..params()
        };
        assert_eq!(
            SearchPlan::new(Point2 { x: 5.0, y: 6.0 }, 640, 480, 50.0, &off).len(),
            1
        );
        assert_eq!(SearchPlan::default().next_window(), None);
    }

    #[test]
    fn candidate_needs_consecutive_confident_frames() {
        let p = Point2 { x: 10.0, y: 10.0 };
        let mut c = CandidateTracker::default();
        c.begin_frame(5.0);
        c.offer(p, 1.0, 0.4, 0.5);
        assert_eq!(c.end_frame(3), None);
        assert!(c.current().is_none());
        c.begin_frame(5.0);
        c.offer(p, 1.0, 0.7, 0.5);
        assert!(c.end_frame(3).is_none());
        c.begin_frame(5.0);
        c.followed(p, 1.0, 0.6, 0.5);
        // A less confident window elsewhere does not replace it, nor does a more confident
        // window on the candidate itself reset its streak.
        c.offer(Point2 { x: 90.0, y: 9.0 }, 1.0, 0.55, 0.5);
        c.offer(Point2 { x: 12.0, y: 11.0 }, 1.0, 0.95, 0.5);
        assert!(c.end_frame(3).is_none());
        c.begin_frame(5.0);
        c.followed(p, 1.0, 0.6, 0.5);
        let got = c.end_frame(3).unwrap();
        assert_eq!((got.pos, got.streak), (p, 3));
        // A more confident window elsewhere replaces it.
        c.begin_frame(5.0);
        c.followed(p, 1.0, 0.6, 0.5);
        c.offer(Point2 { x: 90.0, y: 9.0 }, 1.0, 0.9, 0.5);
        assert_eq!(c.end_frame(3), None);
        assert_eq!(c.current().map(|c| (c.pos.x, c.streak)), Some((90.0, 1)));
        // A candidate that fades is dropped.
        c.begin_frame(5.0);
        c.followed(p, 1.0, 0.2, 0.5);
        assert!(c.end_frame(1).is_none() && c.current().is_none());
    }
}
