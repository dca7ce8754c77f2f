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
//! 3. up to `proposals` windows go where a whole-frame template match proposes the target
//!    ([`propose`]: normalised cross-correlation of an [`Appearance`] template — the grey
//!    target box averaged over confident frames — on the frame downsampled to the
//!    template's cells, at the scale of the loss; at most [`MAX_PROPOSAL_PIXELS`] positions,
//!    so its cost is bounded), so a target that re-enters anywhere is looked at on the next
//!    frame instead of when the tile walk reaches it;
//! 4. the rest of the budget walks a [`SearchPlan`]: tiles covering the whole frame, at
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

pub mod dwconv;
pub mod nano;

use crate::config::RedetectionConfig;
use crate::error::TrackError;
use crate::geometry::Point2;
use crate::image::Frame;

/// The best hit of a learned verifier in one search region.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VerifierHit {
    /// Centre of the predicted box, image pixels.
    pub pos: Point2,
    /// Size of the predicted box, image pixels.
    pub w: f32,
    /// Height of the predicted box, image pixels.
    pub h: f32,
    /// The verifier's score (NanoTrack: foreground logit margin).
    pub score: f32,
}

/// What [`Verifier::search_above`] found in a region: the hit, or only the best score when
/// it is below the bar asked for (the box was not regressed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Scored {
    /// The best score reached the bar: the hit with its box.
    Hit(VerifierHit),
    /// The best score, below the bar (or NaN).
    Below(f32),
}

impl Scored {
    /// The best score in the region.
    pub fn score(&self) -> f32 {
        match self {
            Scored::Hit(h) => h.score,
            Scored::Below(s) => *s,
        }
    }
}

/// NanoTrack's template context side for a `w × h` target: `√((w+p)(h+p))`, `p = (w+h)/2`
/// (a verifier's search region is twice this).
pub fn context_side(w: f32, h: f32) -> f32 {
    let p = 0.5 * (w + h);
    ((w + p) * (h + p)).sqrt()
}

/// A learned re-detection verifier (`redetection.verifier`): scores search regions against
/// a template of the target taken on the initial frame.
pub trait Verifier: Send + std::fmt::Debug {
    /// Takes the target (`w × h` pixels at `center` of `frame`) as the template.
    ///
    /// # Errors
    /// [`TrackError::Feature`] when the network fails.
    fn set_template(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        w: f32,
        h: f32,
    ) -> Result<(), TrackError>;

    /// The best hit in the square search region of side `side` pixels at `center`, for a
    /// target whose template context side is `side / 2`; `None` without a template.
    ///
    /// # Errors
    /// [`TrackError::Feature`] when the network fails.
    fn search(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
    ) -> Result<Option<VerifierHit>, TrackError>;

    /// As [`Self::search`], but the hit's box is needed only when its score is at least
    /// `bar` ([`Scored::Hit`]); below it only the score is returned ([`Scored::Below`]), so
    /// a verifier may skip the box regression (`bar = +∞`: the score alone). Scores and
    /// boxes are those of [`Self::search`].
    ///
    /// # Errors
    /// [`TrackError::Feature`] when the network fails.
    fn search_above(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
        bar: f32,
    ) -> Result<Option<Scored>, TrackError> {
        Ok(self.search(frame, center, side)?.map(|h| {
            if h.score >= bar {
                Scored::Hit(h)
            } else {
                Scored::Below(h.score)
            }
        }))
    }

    /// As [`Self::search_above`] on a search crop of `cells × cells` grid points
    /// (`redetection.verifier_tile_cells`): `side` is the square the crop covers, at the
    /// verifier's resolution (`16·cells − 1` pixels for NanoTrack; 16 cells is
    /// [`Self::search_above`]). A verifier without crops of other sizes searches the same
    /// square with its own (this default).
    ///
    /// # Errors
    /// [`TrackError::Feature`] when the network fails or cannot take the size.
    fn search_above_cells(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
        bar: f32,
        cells: usize,
    ) -> Result<Option<Scored>, TrackError> {
        let _ = cells;
        self.search_above(frame, center, side, bar)
    }

    /// Gets ready for [`Self::search_above_cells`] crops of `cells` grid points now
    /// (planning a network, say), so that the first lost frame does not: called by the
    /// tracker's start-up check. Nothing to do by default.
    ///
    /// # Errors
    /// [`TrackError::Feature`] when the verifier cannot take the size.
    fn prepare_cells(&mut self, cells: usize) -> Result<(), TrackError> {
        let _ = cells;
        Ok(())
    }
}

/// Upper bound on the tiles of one plan (per scale); the stride grows to respect it.
pub const MAX_TILES: usize = 1024;

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
        p: &RedetectionConfig,
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
    p: &RedetectionConfig,
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

/// Cells per side of the [`Appearance`] template.
pub const TEMPLATE_CELLS: usize = 8;
/// Fewest cells per side a proposal template is matched with.
const MIN_MATCH_CELLS: usize = 3;
/// Largest downsampled frame [`propose`] searches, pixels: bounds its cost to this many
/// positions × at most `TEMPLATE_CELLS²` multiply-adds.
pub const MAX_PROPOSAL_PIXELS: usize = 1 << 16;
/// Pixels sampled per cell side when downsampling for [`propose`].
const CELL_SAMPLES: usize = 4;
/// Smallest local standard deviation (grey levels) a position needs to be matched.
const MIN_MATCH_STD: f32 = 1.0;

/// Grey level of pixel `(x, y)` of `frame` (mean of the colour bytes), clamped to the frame.
fn grey(frame: &Frame<'_>, x: isize, y: isize) -> f32 {
    let xi = x.clamp(0, frame.width() as isize - 1) as usize;
    let yi = y.clamp(0, frame.height() as isize - 1) as usize;
    let bpp = frame.format().bytes_per_pixel();
    let i = yi * frame.stride() + xi * bpp;
    let d = frame.data();
    if bpp == 1 {
        f32::from(d.get(i).copied().unwrap_or(0))
    } else {
        let px = d.get(i..i + 3).unwrap_or(&[0, 0, 0]);
        (f32::from(px[0]) + f32::from(px[1]) + f32::from(px[2])) / 3.0
    }
}

/// The re-detection appearance model: the grey target square (side `√(w·h)`) averaged
/// into `TEMPLATE_CELLS²` cells, a running mean over the confident frames. Independent of
/// the correlation filter's features and of its learning gate.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Appearance {
    cells: Vec<f32>,
}

impl Appearance {
    /// True once a frame has been observed.
    pub fn is_ready(&self) -> bool {
        !self.cells.is_empty()
    }

    /// Blends the target square of side `side` pixels at `center` of `frame` in with
    /// weight `rate` (the first observation is taken as it is).
    pub fn observe(&mut self, frame: &Frame<'_>, center: Point2, side: f32, rate: f32) {
        let n = TEMPLATE_CELLS;
        let cell = side / n as f32;
        if !(cell.is_finite() && cell > 0.0 && center.x.is_finite() && center.y.is_finite()) {
            return;
        }
        let (x0, y0) = (center.x - side / 2.0, center.y - side / 2.0);
        let fresh = self.cells.is_empty();
        if fresh {
            self.cells = vec![0.0; n * n];
        }
        for r in 0..n {
            let ya = (y0 + r as f32 * cell).floor() as isize;
            let yb = ((y0 + (r + 1) as f32 * cell).floor() as isize).max(ya + 1);
            for c in 0..n {
                let xa = (x0 + c as f32 * cell).floor() as isize;
                let xb = ((x0 + (c + 1) as f32 * cell).floor() as isize).max(xa + 1);
                let mut sum = 0.0;
                for y in ya..yb {
                    for x in xa..xb {
                        sum += grey(frame, x, y);
                    }
                }
                let v = sum / ((yb - ya) * (xb - xa)) as f32;
                let m = &mut self.cells[r * n + c];
                *m = if fresh { v } else { *m + rate * (v - *m) };
            }
        }
    }

    /// The template resampled to `k × k` cells (area averaging), zero-mean and unit-norm;
    /// `None` for a flat template.
    fn matched(&self, k: usize) -> Option<Vec<f32>> {
        let n = TEMPLATE_CELLS;
        if self.cells.len() != n * n || k == 0 {
            return None;
        }
        let mut t = vec![0.0f32; k * k];
        for (i, v) in self.cells.iter().enumerate() {
            let (r, c) = ((i / n) * k / n, (i % n) * k / n);
            t[r * k + c] += v;
        }
        let mean = t.iter().sum::<f32>() / t.len() as f32;
        t.iter_mut().for_each(|v| *v -= mean);
        let norm = t.iter().map(|v| v * v).sum::<f32>().sqrt();
        if !norm.is_finite() || norm <= f32::EPSILON {
            return None;
        }
        t.iter_mut().for_each(|v| *v /= norm);
        Some(t)
    }
}

/// A whole-frame template-match proposal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Proposal {
    /// Centre of the matched square, image pixels.
    pub center: Point2,
    /// Normalised cross-correlation, -1..1.
    pub score: f32,
}

/// Buffers of [`propose`], reused across frames.
#[derive(Debug, Clone, Default)]
pub struct ProposalScratch {
    small: Vec<f32>,
    sum: Vec<f64>,
    sq: Vec<f64>,
    map: Vec<f32>,
    /// Sampled frame columns of every downsampled column, flattened, and where each starts.
    cols: Vec<usize>,
    col_start: Vec<usize>,
    /// Grey levels of one frame row.
    grey_row: Vec<f32>,
    /// Per-cell sums and sample counts of one downsampled row.
    acc: Vec<f32>,
    /// Per-position template dot products of one map row, and one template row's share.
    dots: Vec<f32>,
    row_dots: Vec<f32>,
}

/// Grey levels (mean of the colour bytes, as [`grey`]) of frame row `y` into `out`.
fn grey_row(frame: &Frame<'_>, y: usize, out: &mut Vec<f32>) {
    let fw = frame.width();
    let bpp = frame.format().bytes_per_pixel();
    out.clear();
    out.resize(fw, 0.0);
    let start = y * frame.stride();
    let Some(row) = frame.data().get(start..start + fw * bpp) else {
        return;
    };
    match bpp {
        1 => {
            for (o, &v) in out.iter_mut().zip(row) {
                *o = f32::from(v);
            }
        }
        3 => grey_px::<3>(row, out),
        4 => grey_px::<4>(row, out),
        _ => {
            for (o, px) in out.iter_mut().zip(row.chunks_exact(bpp)) {
                *o = (f32::from(px[0]) + f32::from(px[1]) + f32::from(px[2])) / 3.0;
            }
        }
    }
}

/// [`grey_row`] for `B` bytes per pixel. The three bytes are summed as integers: their
/// `f32` sum is exact either way.
fn grey_px<const B: usize>(row: &[u8], out: &mut [f32]) {
    for (o, px) in out.iter_mut().zip(row.chunks_exact(B)) {
        let s = u16::from(px[0]) + u16::from(px[1]) + u16::from(px[2]);
        *o = f32::from(s) / 3.0;
    }
}

/// Key of `f32::total_cmp` as a signed integer (same order).
fn total_key(x: f32) -> i32 {
    let b = x.to_bits() as i32;
    b ^ (((b >> 31) as u32) >> 1) as i32
}

/// Up to `count` proposals for a target square of side `side` pixels: the template's
/// normalised cross-correlation over the whole frame, downsampled so a template cell is
/// one pixel (coarser when needed to stay within [`MAX_PROPOSAL_PIXELS`]), best first, at
/// least one template side apart. Cost: at most `MAX_PROPOSAL_PIXELS` × 16 pixel reads and
/// `MAX_PROPOSAL_PIXELS` × `TEMPLATE_CELLS²` multiply-adds, whatever the frame size.
///
/// Computed a row at a time (grey levels of a frame row once, template dot products of all
/// positions of a map row together) so the loops vectorise; every value is summed in the
/// order of the per-position definition, so the result is that of the direct computation.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
pub fn propose(
    frame: &Frame<'_>,
    appearance: &Appearance,
    side: f32,
    count: usize,
    scratch: &mut ProposalScratch,
) -> Vec<Proposal> {
    let (fw, fh) = (frame.width(), frame.height());
    if count == 0 || !side.is_finite() || side <= 0.0 {
        return Vec::new();
    }
    let area_floor = ((fw * fh) as f32 / MAX_PROPOSAL_PIXELS as f32).sqrt();
    let cell = (side / TEMPLATE_CELLS as f32).max(area_floor).max(1.0);
    let k = ((side / cell).round() as usize).clamp(MIN_MATCH_CELLS, TEMPLATE_CELLS);
    let Some(t) = appearance.matched(k) else {
        return Vec::new();
    };
    let (w, h) = ((fw as f32 / cell) as usize, (fh as f32 / cell) as usize);
    if w < k || h < k || fw == 0 || fh == 0 {
        return Vec::new();
    }
    let ProposalScratch {
        small,
        sum,
        sq,
        map,
        cols,
        col_start,
        grey_row: grow,
        acc,
        dots,
        row_dots,
    } = scratch;
    // Box-averaged downsampling: per cell, the mean of at most CELL_SAMPLES² sampled
    // pixels (clamped to the frame), summed row by row, left to right.
    let span = |i: usize| {
        let a = (i as f32 * cell) as isize;
        let b = (((i + 1) as f32 * cell) as isize).max(a + 1);
        (a, b, ((b - a) as usize).div_ceil(CELL_SAMPLES))
    };
    cols.clear();
    col_start.clear();
    for u in 0..w {
        col_start.push(cols.len());
        let (xa, xb, sx) = span(u);
        cols.extend(
            (xa..xb)
                .step_by(sx)
                .map(|x| x.clamp(0, fw as isize - 1) as usize),
        );
    }
    col_start.push(cols.len());
    small.clear();
    small.resize(w * h, 0.0);
    acc.clear();
    acc.resize(w, 0.0);
    for v in 0..h {
        let (ya, yb, sy) = span(v);
        acc.iter_mut().for_each(|a| *a = 0.0);
        let mut rows = 0usize;
        for y in (ya..yb).step_by(sy) {
            grey_row(frame, y.clamp(0, fh as isize - 1) as usize, grow);
            for (a, se) in acc.iter_mut().zip(col_start.windows(2)) {
                for &x in &cols[se[0]..se[1]] {
                    *a += grow[x];
                }
            }
            rows += 1;
        }
        for ((o, a), se) in small[v * w..(v + 1) * w]
            .iter_mut()
            .zip(acc.iter())
            .zip(col_start.windows(2))
        {
            *o = a / (rows * (se[1] - se[0])).max(1) as f32;
        }
    }
    // Integral images of the values and their squares, (w+1) × (h+1).
    let iw = w + 1;
    sum.clear();
    sum.resize(iw * (h + 1), 0.0);
    sq.clear();
    sq.resize(iw * (h + 1), 0.0);
    for v in 0..h {
        let (mut rs, mut rq) = (0.0f64, 0.0f64);
        for u in 0..w {
            let x = f64::from(small[v * w + u]);
            rs += x;
            rq += x * x;
            sum[(v + 1) * iw + u + 1] = sum[v * iw + u + 1] + rs;
            sq[(v + 1) * iw + u + 1] = sq[v * iw + u + 1] + rq;
        }
    }
    let (mw, mh) = (w - k + 1, h - k + 1);
    map.clear();
    map.resize(mw * mh, f32::NEG_INFINITY);
    let nk = (k * k) as f64;
    // The neutral element `Iterator::sum` starts from (the sign of its zero matters for
    // bit-equality with the per-position sums).
    let zero: f32 = std::iter::empty::<f32>().sum();
    dots.clear();
    dots.resize(mw, 0.0);
    row_dots.clear();
    row_dots.resize(mw, 0.0);
    for v in 0..mh {
        dots.iter_mut().for_each(|d| *d = 0.0);
        for r in 0..k {
            row_dots.iter_mut().for_each(|d| *d = zero);
            let src = &small[(v + r) * w..(v + r + 1) * w];
            for (c, &tc) in t[r * k..(r + 1) * k].iter().enumerate() {
                for (d, &a) in row_dots.iter_mut().zip(&src[c..c + mw]) {
                    *d += a * tc;
                }
            }
            for (d, &rd) in dots.iter_mut().zip(row_dots.iter()) {
                *d += rd;
            }
        }
        for u in 0..mw {
            let rect = |a: &[f64]| {
                a[(v + k) * iw + u + k] - a[v * iw + u + k] - a[(v + k) * iw + u] + a[v * iw + u]
            };
            let (s, q) = (rect(sum), rect(sq));
            let var = (q - s * s / nk).max(0.0);
            if var < f64::from(MIN_MATCH_STD * MIN_MATCH_STD) * nk {
                continue;
            }
            map[v * mw + u] = dots[u] / var.sqrt() as f32;
        }
    }
    // Best first, suppressing everything within one template side of a pick.
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        // The last of the largest values under `total_cmp`, as `Iterator::max_by` picks.
        let Some(best) = map.iter().map(|&m| total_key(m)).max() else {
            break;
        };
        let Some(i) = map.iter().rposition(|&m| total_key(m) == best) else {
            break;
        };
        let score = map[i];
        if !score.is_finite() {
            break;
        }
        let (pv, pu) = (i / mw, i % mw);
        out.push(Proposal {
            center: Point2 {
                x: (pu as f32 + k as f32 / 2.0) * cell,
                y: (pv as f32 + k as f32 / 2.0) * cell,
            },
            score,
        });
        for v in pv.saturating_sub(k - 1)..(pv + k).min(mh) {
            for u in pu.saturating_sub(k - 1)..(pu + k).min(mw) {
                map[v * mw + u] = f32::NEG_INFINITY;
            }
        }
    }
    out
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

    /// Moves the current candidate's position by `f` (the scene moved under the camera).
    pub fn move_by(&mut self, f: impl Fn(Point2) -> Point2) {
        if let Some(c) = self.current.as_mut() {
            c.pos = f(c.pos);
        }
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

    fn params() -> RedetectionConfig {
        RedetectionConfig {
            enabled: true,
            windows_per_frame: 4,
            scales: vec![1.0, 0.8],
            tile_stride: 0.5,
            reacquire_threshold: 0.5,
            reacquire_relative: 0.5,
            reacquire_frames: 3,
            proposals: 4,
            ..RedetectionConfig::default()
        }
    }

    /// A 400 × 300 grey frame of smooth noise with a 40-px textured square at `at`.
    fn scene(at: (usize, usize), seed: u32) -> Vec<u8> {
        let (w, h) = (400, 300);
        let noise = |x: usize, y: usize, s: u32| {
            let v = (x as u32 / 3)
                .wrapping_mul(0x9e37_79b9)
                .wrapping_add((y as u32 / 3).wrapping_mul(0x85eb_ca6b))
                ^ s.wrapping_mul(0xc2b2_ae35);
            (v.wrapping_mul(0x27d4_eb2f) >> 24) as u8
        };
        let mut img = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                img[y * w + x] = 60 + noise(x, y, seed) / 4;
                let (dx, dy) = (x.wrapping_sub(at.0), y.wrapping_sub(at.1));
                if dx < 40 && dy < 40 {
                    img[y * w + x] = if (dx / 10 + dy / 8) % 2 == 0 { 230 } else { 20 };
                }
            }
        }
        img
    }

    /// The direct per-position form of [`propose`] (before it was computed row-wise).
    #[derive(Default)]
    struct RefScratch {
        small: Vec<f32>,
        sum: Vec<f64>,
        sq: Vec<f64>,
        map: Vec<f32>,
    }

    /// Up to `count` proposals for a target square of side `side` pixels: the template's
    /// normalised cross-correlation over the whole frame, downsampled so a template cell is
    /// one pixel (coarser when needed to stay within [`MAX_PROPOSAL_PIXELS`]), best first, at
    /// least one template side apart. Cost: at most `MAX_PROPOSAL_PIXELS` × 16 pixel reads and
    /// `MAX_PROPOSAL_PIXELS` × `TEMPLATE_CELLS²` multiply-adds, whatever the frame size.
    fn propose_reference(
        frame: &Frame<'_>,
        appearance: &Appearance,
        side: f32,
        count: usize,
        scratch: &mut RefScratch,
    ) -> Vec<Proposal> {
        let (fw, fh) = (frame.width(), frame.height());
        if count == 0 || !side.is_finite() || side <= 0.0 {
            return Vec::new();
        }
        let area_floor = ((fw * fh) as f32 / MAX_PROPOSAL_PIXELS as f32).sqrt();
        let cell = (side / TEMPLATE_CELLS as f32).max(area_floor).max(1.0);
        let k = ((side / cell).round() as usize).clamp(MIN_MATCH_CELLS, TEMPLATE_CELLS);
        let Some(t) = appearance.matched(k) else {
            return Vec::new();
        };
        let (w, h) = ((fw as f32 / cell) as usize, (fh as f32 / cell) as usize);
        if w < k || h < k {
            return Vec::new();
        }
        // Box-averaged downsampling.
        let RefScratch {
            small,
            sum,
            sq,
            map,
        } = scratch;
        small.clear();
        small.resize(w * h, 0.0);
        for v in 0..h {
            let ya = (v as f32 * cell) as isize;
            let yb = (((v + 1) as f32 * cell) as isize).max(ya + 1);
            for u in 0..w {
                let xa = (u as f32 * cell) as isize;
                let xb = (((u + 1) as f32 * cell) as isize).max(xa + 1);
                // At most CELL_SAMPLES² pixels per cell: the cost stays bounded on huge frames.
                let (sy, sx) = (
                    ((yb - ya) as usize).div_ceil(CELL_SAMPLES),
                    ((xb - xa) as usize).div_ceil(CELL_SAMPLES),
                );
                let (mut acc, mut n) = (0.0, 0usize);
                for y in (ya..yb).step_by(sy) {
                    for x in (xa..xb).step_by(sx) {
                        acc += grey(frame, x, y);
                        n += 1;
                    }
                }
                small[v * w + u] = acc / n.max(1) as f32;
            }
        }
        // Integral images of the values and their squares, (w+1) × (h+1).
        let iw = w + 1;
        sum.clear();
        sum.resize(iw * (h + 1), 0.0);
        sq.clear();
        sq.resize(iw * (h + 1), 0.0);
        for v in 0..h {
            let (mut rs, mut rq) = (0.0f64, 0.0f64);
            for u in 0..w {
                let x = f64::from(small[v * w + u]);
                rs += x;
                rq += x * x;
                sum[(v + 1) * iw + u + 1] = sum[v * iw + u + 1] + rs;
                sq[(v + 1) * iw + u + 1] = sq[v * iw + u + 1] + rq;
            }
        }
        let (mw, mh) = (w - k + 1, h - k + 1);
        map.clear();
        map.resize(mw * mh, f32::NEG_INFINITY);
        let nk = (k * k) as f64;
        for v in 0..mh {
            for u in 0..mw {
                let rect = |a: &[f64]| {
                    a[(v + k) * iw + u + k] - a[v * iw + u + k] - a[(v + k) * iw + u]
                        + a[v * iw + u]
                };
                let (s, q) = (rect(sum), rect(sq));
                let var = (q - s * s / nk).max(0.0);
                if var < f64::from(MIN_MATCH_STD * MIN_MATCH_STD) * nk {
                    continue;
                }
                let mut dot = 0.0f32;
                for r in 0..k {
                    let row = &small[(v + r) * w + u..(v + r) * w + u + k];
                    dot += row
                        .iter()
                        .zip(&t[r * k..(r + 1) * k])
                        .map(|(a, b)| a * b)
                        .sum::<f32>();
                }
                map[v * mw + u] = dot / var.sqrt() as f32;
            }
        }
        // Best first, suppressing everything within one template side of a pick.
        let mut out = Vec::with_capacity(count);
        for _ in 0..count {
            let Some((i, &score)) = map.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) else {
                break;
            };
            if !score.is_finite() {
                break;
            }
            let (pv, pu) = (i / mw, i % mw);
            out.push(Proposal {
                center: Point2 {
                    x: (pu as f32 + k as f32 / 2.0) * cell,
                    y: (pv as f32 + k as f32 / 2.0) * cell,
                },
                score,
            });
            for v in pv.saturating_sub(k - 1)..(pv + k).min(mh) {
                for u in pu.saturating_sub(k - 1)..(pu + k).min(mw) {
                    map[v * mw + u] = f32::NEG_INFINITY;
                }
            }
        }
        out
    }

    #[test]
    fn row_wise_proposals_equal_the_per_position_definition_bit_for_bit() {
        // Colour and grey frames, cells below and above 4 px (all or sampled pixels), frame
        // sizes that are not multiples of the cell.
        for (fw, fh, side, fmt) in [
            (203usize, 151usize, 40.0f32, crate::image::PixelFormat::Rgb8),
            (400, 300, 24.0, crate::image::PixelFormat::Mono8),
            (333, 97, 90.0, crate::image::PixelFormat::Bgra8),
            (640, 480, 20.0, crate::image::PixelFormat::Bgr8),
        ] {
            let bpp = fmt.bytes_per_pixel();
            let mut seed = 0x1234_5678u32 ^ fw as u32;
            let img: Vec<u8> = (0..fw * fh * bpp)
                .map(|i| {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    // Smooth structure plus noise, so normalised scores spread out.
                    ((i / bpp % fw) as u32 / 9 * 13 + (i / bpp / fw) as u32 / 7 * 5 + (seed >> 28))
                        as u8
                })
                .collect();
            let f = Frame::packed(&img, fw, fh, fmt).unwrap();
            let mut a = Appearance::default();
            a.observe(
                &f,
                Point2 {
                    x: fw as f32 / 3.0,
                    y: fh as f32 / 2.0,
                },
                side,
                1.0,
            );
            let got = propose(&f, &a, side, 4, &mut ProposalScratch::default());
            let want = propose_reference(&f, &a, side, 4, &mut RefScratch::default());
            assert!(!want.is_empty());
            assert_eq!(got.len(), want.len());
            for (g, w) in got.iter().zip(&want) {
                assert_eq!(
                    g.score.to_bits(),
                    w.score.to_bits(),
                    "{fw}x{fh} {g:?} {w:?}"
                );
                assert_eq!(g.center, w.center);
            }
        }
    }

    #[test]
    fn proposals_find_the_template_anywhere_in_the_frame() {
        let first = scene((40, 40), 1);
        let f = Frame::packed(&first, 400, 300, crate::image::PixelFormat::Mono8).unwrap();
        let mut a = Appearance::default();
        assert!(!a.is_ready());
        let mut scratch = ProposalScratch::default();
        assert!(propose(&f, &a, 40.0, 3, &mut scratch).is_empty());
        a.observe(&f, Point2 { x: 60.0, y: 60.0 }, 40.0, 1.0);
        assert!(a.is_ready());
        // The square moved to the far corner over new background.
        let later = scene((330, 230), 2);
        let f = Frame::packed(&later, 400, 300, crate::image::PixelFormat::Mono8).unwrap();
        let got = propose(&f, &a, 40.0, 3, &mut scratch);
        assert_eq!(got.len(), 3);
        let best = got[0];
        assert!(
            best.center.distance(&Point2 { x: 350.0, y: 250.0 }) < 6.0,
            "{best:?}"
        );
        assert!(best.score > 0.9 && got[1].score < best.score, "{got:?}");
        // Picks are at least a template side apart.
        assert!(got[1].center.distance(&best.center) >= 30.0);
        // A template of a flat patch proposes nothing; no proposals asked, none given.
        let mut flat = Appearance::default();
        flat.observe(&f, Point2 { x: 350.0, y: 250.0 }, 4.0, 1.0);
        let flat_frame = vec![90u8; 400 * 300];
        let ff = Frame::packed(&flat_frame, 400, 300, crate::image::PixelFormat::Mono8).unwrap();
        flat.observe(&ff, Point2 { x: 50.0, y: 50.0 }, 40.0, 1.0);
        assert!(propose(&f, &flat, 40.0, 3, &mut scratch).is_empty());
        assert!(propose(&f, &a, 40.0, 0, &mut scratch).is_empty());
    }

    #[test]
    fn proposal_cost_is_bounded_on_huge_frames() {
        // 8000 × 4000 with a 16-px target: the downsampled map stays within the bound.
        let (w, h) = (8000, 4000);
        let img = vec![128u8; w * h];
        let f = Frame::packed(&img, w, h, crate::image::PixelFormat::Mono8).unwrap();
        let mut a = Appearance::default();
        let tex = scene((40, 40), 3);
        let t = Frame::packed(&tex, 400, 300, crate::image::PixelFormat::Mono8).unwrap();
        a.observe(&t, Point2 { x: 60.0, y: 60.0 }, 40.0, 1.0);
        let mut scratch = ProposalScratch::default();
        let _ = propose(&f, &a, 16.0, 2, &mut scratch);
        assert!(
            scratch.small.len() <= MAX_PROPOSAL_PIXELS,
            "{}",
            scratch.small.len()
        );
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
        let off = RedetectionConfig {
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
        let off = RedetectionConfig {
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
