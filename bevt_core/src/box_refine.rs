//! The learned box on the filter (`box_refine.mode`): NanoTrack v2's head regresses the
//! target's box on a search crop centred where the correlation filter found it, and the
//! regression is fused with the filter's localisation and the scale filter's size.
//!
//! The filter keeps the first frame's aspect ratio, and its scale filter follows a size
//! change late; a Siamese head trained for tracking regresses a box of any aspect every
//! frame. This stage takes from each what it does best:
//! - **where**: the filter's position (its peak is the track); the head's centre only moves
//!   it, by `center_weight`, when the head is confident (`min_score`) and agrees with the
//!   filter (`max_offset`);
//! - **how large, what aspect**: the head's box, post-processed as NanoTrack does it (one
//!   template of the initial frame, 127×127 context crop; a 255×255 search crop of twice
//!   the context side; foreground probability × a penalty on scale and aspect change against
//!   the previous box, `exp(−k·(r·s − 1))`, blended with a cosine window; the size moved
//!   towards the chosen point's box at the rate `size_rate × penalty × score`), where the
//!   rate starts from the scale filter's size instead of the previous box, so the scale
//!   filter stays the prior and the fallback;
//! - **fallback**: a low score, disagreement, a target below `min_side`, or no usable
//!   output keep the scale filter's size and the filter's centre, as with `mode: none`.
//!
//! The networks are [`NanoVerifier`]'s (plans optimised once per process and shared; one
//! backbone and one head pass per tracked frame); the refiner has its own run state and
//! its own template, taken at initialisation and never updated (NanoTrack's choice: a
//! template that does not drift).

use crate::config::{BoxRefineConfig, BoxRefineMode, TrackerSpec};
use crate::error::TrackError;
use crate::geometry::{BBox, Point2, Size2};
use crate::image::Frame;
use crate::redetect::nano::{NanoVerifier, SEARCH_CELLS, SEARCH_SIDE, TEMPLATE_SIDE};
use crate::redetect::{context_side, Verifier};

/// Backbone stride, crop pixels.
const STRIDE: f32 = 16.0;

/// The head's chosen box on one search crop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadBox {
    /// Centre offset from the crop centre, frame pixels (x).
    pub dx: f32,
    /// Centre offset from the crop centre, frame pixels (y).
    pub dy: f32,
    /// Regressed size, frame pixels.
    pub size: Size2,
    /// Foreground probability at the chosen point.
    pub score: f32,
    /// Scale/aspect-change penalty at the chosen point (0–1].
    pub penalty: f32,
}

/// NanoTrack's context size of a `w × h` box (`√((w+p)(h+p))`, `p = (w+h)/2`).
fn sz(w: f32, h: f32) -> f32 {
    context_side(w, h)
}

/// `max(r, 1/r)`.
fn change(r: f32) -> f32 {
    r.max(1.0 / r)
}

/// The 16×16 cosine window NanoTrack adds to its score map (`np.hanning`, outer product).
pub fn cosine_window() -> Vec<f32> {
    let n = SEARCH_CELLS;
    let h: Vec<f32> = (0..n)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f32::consts::PI * i as f32 / (n - 1) as f32).cos())
        .collect();
    h.iter()
        .flat_map(|&a| h.iter().map(move |&b| a * b))
        .collect()
}

/// NanoTrack's post-processing of the head's maps (`margins[256]`: foreground − background
/// logit, `loc[4·256]`: left, top, right, bottom in crop pixels) for a previous box `prev`
/// (frame pixels) on a crop of `scale_z` crop pixels per frame pixel: the point with the
/// largest penalised, windowed score and its box in frame pixels. `None` for maps of the
/// wrong length, a degenerate `prev` or `scale_z`, or no finite positive-size box.
pub fn select(
    margins: &[f32],
    loc: &[f32],
    prev: Size2,
    scale_z: f32,
    cfg: &BoxRefineConfig,
    window: &[f32],
) -> Option<HeadBox> {
    let n = SEARCH_CELLS * SEARCH_CELLS;
    if margins.len() != n || loc.len() != 4 * n || window.len() != n {
        return None;
    }
    if !(prev.w > 0.0 && prev.h > 0.0 && scale_z > 0.0 && scale_z.is_finite()) {
        return None;
    }
    let (pw, ph) = (prev.w * scale_z, prev.h * scale_z);
    let (prev_sz, prev_ratio) = (sz(pw, ph), pw / ph);
    if !(prev_sz.is_finite() && prev_ratio.is_finite()) {
        return None;
    }
    let mut best: Option<(usize, f32, f32, f32)> = None;
    for i in 0..n {
        let (l, t, r, b) = (loc[i], loc[n + i], loc[2 * n + i], loc[3 * n + i]);
        let (w, h) = (l + r, t + b);
        if !(w > 0.0 && h > 0.0 && w.is_finite() && h.is_finite() && margins[i].is_finite()) {
            continue;
        }
        let score = 1.0 / (1.0 + (-margins[i]).exp());
        let s_c = change(sz(w, h) / prev_sz);
        let r_c = change(prev_ratio / (w / h));
        let penalty = (-(r_c * s_c - 1.0) * cfg.penalty_k).exp();
        let p = penalty * score * (1.0 - cfg.window_influence) + window[i] * cfg.window_influence;
        if best.is_none_or(|(_, bp, _, _)| p > bp) {
            best = Some((i, p, score, penalty));
        }
    }
    let (i, _, score, penalty) = best?;
    let (l, t, r, b) = (loc[i], loc[n + i], loc[2 * n + i], loc[3 * n + i]);
    let (j, k) = (i / SEARCH_CELLS, i % SEARCH_CELLS);
    let half = (SEARCH_CELLS / 2) as f32;
    let cx = (k as f32 - half) * STRIDE + 0.5 * (r - l);
    let cy = (j as f32 - half) * STRIDE + 0.5 * (b - t);
    Some(HeadBox {
        dx: cx / scale_z,
        dy: cy / scale_z,
        size: Size2 {
            w: (l + r) / scale_z,
            h: (t + b) / scale_z,
        },
        score,
        penalty,
    })
}

/// What the stage decided for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refined {
    /// Box centre, frame pixels.
    pub pos: Point2,
    /// Box size, frame pixels.
    pub size: Size2,
    /// The head's box was taken (false: the filter's centre and the fallback size).
    pub taken: bool,
    /// The head's foreground probability at its chosen point (0 when it did not run).
    pub score: f32,
}

/// Fuses the head's box with the filter's (`fallback` size, `filter_pos` centre) under the
/// gates of `cfg`; `prev` is the previous frame's box size (the search crop's scale and
/// NanoTrack's penalty reference).
pub fn fuse(
    hb: Option<HeadBox>,
    filter_pos: Point2,
    prev: Size2,
    fallback: Size2,
    cfg: &BoxRefineConfig,
) -> Refined {
    let keep = Refined {
        pos: filter_pos,
        size: fallback,
        taken: false,
        score: hb.map_or(0.0, |h| h.score),
    };
    let Some(h) = hb else {
        return keep;
    };
    let target = (prev.w * prev.h).sqrt();
    let offset = (h.dx * h.dx + h.dy * h.dy).sqrt() / target;
    if !(h.score >= cfg.min_score && offset <= cfg.max_offset && target > 0.0) {
        return keep;
    }
    let lr = (h.penalty * h.score * cfg.size_rate).clamp(0.0, 1.0);
    let size = Size2 {
        w: fallback.w * (1.0 - lr) + h.size.w * lr,
        h: fallback.h * (1.0 - lr) + h.size.h * lr,
    };
    let pos = Point2 {
        x: filter_pos.x + cfg.center_weight * h.dx,
        y: filter_pos.y + cfg.center_weight * h.dy,
    };
    let finite = size.w.is_finite() && size.h.is_finite() && pos.x.is_finite() && pos.y.is_finite();
    if !(finite && size.w > 0.0 && size.h > 0.0) {
        return keep;
    }
    Refined {
        pos,
        size,
        taken: true,
        score: h.score,
    }
}

/// The box refinement stage: NanoTrack v2's networks and the stage's settings.
#[derive(Debug)]
pub struct BoxRefiner {
    net: NanoVerifier,
    cfg: BoxRefineConfig,
    window: Vec<f32>,
}

impl BoxRefiner {
    /// The stage `spec` names (`None` for `box_refine.mode: none`), its networks loaded
    /// (plans shared per process with the verifier's).
    ///
    /// # Errors
    /// [`TrackError::Feature`] when a network cannot be loaded, or `nanotrack_ort` without
    /// the `cnn` cargo feature.
    pub fn new(spec: &TrackerSpec) -> Result<Option<Self>, TrackError> {
        let c = &spec.config;
        let (bb, hd) = (
            &c.redetection.verifier_backbone,
            &c.redetection.verifier_head,
        );
        let net = match c.box_refine.mode {
            BoxRefineMode::None => return Ok(None),
            BoxRefineMode::Nanotrack => NanoVerifier::new(bb, hd)?,
            #[cfg(feature = "cnn")]
            BoxRefineMode::NanotrackOrt => {
                let runtime = c.features.cnn.as_ref().map_or("", |x| x.runtime.as_str());
                NanoVerifier::new_ort(runtime, bb, hd)?
            }
            #[cfg(not(feature = "cnn"))]
            BoxRefineMode::NanotrackOrt => {
                return Err(TrackError::Feature(
                    "box_refine.mode is nanotrack_ort but bevt_core was built without the \
                     `cnn` cargo feature (build with --features cnn, or use nanotrack)"
                        .into(),
                ))
            }
        };
        Ok(Some(Self {
            net,
            cfg: c.box_refine.clone(),
            window: cosine_window(),
        }))
    }

    /// Takes the template from `bbox` on the initial frame.
    ///
    /// # Errors
    /// A network error.
    pub fn set_template(&mut self, frame: &Frame<'_>, bbox: BBox) -> Result<(), TrackError> {
        self.net.set_template(frame, bbox.center(), bbox.w, bbox.h)
    }

    /// This frame's box: the head runs on a search crop at `filter_pos` sized from `prev`
    /// (the previous box), and [`fuse`] decides between its box and the filter's
    /// (`filter_pos`, `fallback`).
    ///
    /// # Errors
    /// A network error.
    pub fn refine(
        &mut self,
        frame: &Frame<'_>,
        filter_pos: Point2,
        prev: Size2,
        fallback: Size2,
    ) -> Result<Refined, TrackError> {
        let skip = fuse(None, filter_pos, prev, fallback, &self.cfg);
        if prev.w.min(prev.h) < self.cfg.min_side || !self.net.has_template() {
            return Ok(skip);
        }
        let s_z = sz(prev.w, prev.h);
        if !(s_z.is_finite() && s_z > 0.0) {
            return Ok(skip);
        }
        let s_x = s_z * SEARCH_SIDE as f32 / TEMPLATE_SIDE as f32;
        let Some((margins, loc)) = self.net.score_maps(frame, filter_pos, s_x)? else {
            return Ok(skip);
        };
        let scale_z = TEMPLATE_SIDE as f32 / s_z;
        let hb = select(&margins, &loc, prev, scale_z, &self.cfg, &self.window);
        Ok(fuse(hb, filter_pos, prev, fallback, &self.cfg))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const N: usize = SEARCH_CELLS * SEARCH_CELLS;

    /// Maps with one confident point at grid (j, k) whose box is `w × h` crop pixels
    /// centred on the point; every other point background with a same-size box.
    fn maps(j: usize, k: usize, w: f32, h: f32) -> (Vec<f32>, Vec<f32>) {
        let mut m = vec![-6.0; N];
        let mut loc = vec![0.0; 4 * N];
        for i in 0..N {
            loc[i] = 0.5 * w;
            loc[N + i] = 0.5 * h;
            loc[2 * N + i] = 0.5 * w;
            loc[3 * N + i] = 0.5 * h;
        }
        m[j * SEARCH_CELLS + k] = 6.0;
        (m, loc)
    }

    fn cfg() -> BoxRefineConfig {
        BoxRefineConfig::default()
    }

    #[test]
    fn select_reads_the_confident_point_and_its_box_in_frame_pixels() {
        let (m, loc) = maps(8, 9, 40.0, 20.0);
        let hb = select(
            &m,
            &loc,
            Size2 { w: 20.0, h: 20.0 },
            2.0,
            &cfg(),
            &cosine_window(),
        )
        .unwrap();
        assert!((hb.dx - 8.0).abs() < 1e-4 && hb.dy.abs() < 1e-4, "{hb:?}");
        assert!((hb.size.w - 20.0).abs() < 1e-4 && (hb.size.h - 10.0).abs() < 1e-4);
        assert!(hb.score > 0.99);
        // Aspect 2 against 1 and a smaller context size: penalised, not zeroed.
        assert!(hb.penalty < 1.0 && hb.penalty > 0.5, "{}", hb.penalty);
    }

    #[test]
    fn select_refuses_bad_maps() {
        let (m, loc) = maps(8, 8, 40.0, 40.0);
        let w = cosine_window();
        let s = Size2 { w: 20.0, h: 20.0 };
        assert!(select(&m[1..], &loc, s, 2.0, &cfg(), &w).is_none());
        assert!(select(&m, &loc, Size2 { w: 0.0, h: 20.0 }, 2.0, &cfg(), &w).is_none());
        assert!(select(&m, &loc, s, f32::NAN, &cfg(), &w).is_none());
        let nan = vec![f32::NAN; 4 * N];
        assert!(select(&m, &nan, s, 2.0, &cfg(), &w).is_none());
    }

    #[test]
    fn fuse_takes_a_confident_agreeing_box_and_falls_back_otherwise() {
        let c = cfg();
        let p = Point2 { x: 100.0, y: 100.0 };
        let prev = Size2 { w: 20.0, h: 20.0 };
        let hb = HeadBox {
            dx: 4.0,
            dy: 0.0,
            size: Size2 { w: 40.0, h: 20.0 },
            score: 0.9,
            penalty: 1.0,
        };
        let r = fuse(Some(hb), p, prev, prev, &c);
        assert!(r.taken);
        assert!(r.size.w > 20.0 && r.size.h == 20.0, "{r:?}");
        assert!((r.pos.x - 102.0).abs() < 1e-4);
        // Unconfident, far away: the filter's box.
        for bad in [HeadBox { score: 0.3, ..hb }, HeadBox { dx: 15.0, ..hb }] {
            let r = fuse(Some(bad), p, prev, prev, &c);
            assert!(!r.taken && r.pos == p && r.size == prev, "{r:?}");
        }
        assert!(!fuse(None, p, prev, prev, &c).taken);
    }
}
