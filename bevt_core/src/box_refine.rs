//! The learned box on the filter (`box_refine.mode`): NanoTrack v2's head regresses the
//! target's box on a search crop centred where the correlation filter found it, and the
//! regression is fused with the filter's localisation and the scale filter's size.
//!
//! The filter keeps the first frame's aspect ratio, and its scale filter follows a size
//! change late; a Siamese head trained for tracking regresses a box of any aspect every
//! frame. This stage takes from each what it does best (docs/algorithm.md "Box refinement"
//! says from whom):
//! - **where**: the filter's position. The head's box is read *at* that position
//!   (`read: filter`, the score-weighted box of the 3×3 grid points around the crop centre),
//!   as ATOM/DiMP refine the box around the classifier's position; NanoTrack's own arg-max
//!   over the whole crop (`read: peak`) can jump to a look-alike. The centre stays the
//!   filter's unless `center_weight` > 0.
//! - **how large, what aspect**: the head's box, moved towards at NanoTrack's rate
//!   (`size_rate × penalty × score`, the penalty `exp(−k·(r·s − 1))` on scale and aspect
//!   change), from the *prior*: the previous box moved by the scale filter's change this
//!   frame, so the scale filter stays the prior and the fallback; each side changes by at most
//!   `max_change` a frame (SiamRPN++/DSST-style smoothing against one bad regression).
//! - **when**: the head's foreground probability at the filter's position ≥ `min_score`, its
//!   box agrees with the prior (IoU ≥ `min_iou`, centre within `max_offset` target sizes), the
//!   target's shorter side ≥ `min_side`, every `interval` tracked frames. Otherwise the
//!   prior is kept.
//! - **what it changes**: the reported box only (`feed_scale: false`), so the filter, its
//!   window, the scale filter and the lost-state search run as with `mode: none`; or also the
//!   filter's scale (`feed_scale: true`).
//!
//! The networks are [`NanoVerifier`]'s (plans optimised once per process and shared; one
//! backbone and one head pass per run); the refiner has its own template, taken at
//! initialisation and never updated (NanoTrack's choice: a template that does not drift).

use crate::config::{BoxPrior, BoxRead, BoxRefineConfig, BoxRefineMode, TrackerSpec};
use crate::error::TrackError;
use crate::geometry::{BBox, Point2, Size2};
use crate::image::Frame;
use crate::redetect::nano::{NanoVerifier, CENTRE_RADIUS, SEARCH_CELLS, TEMPLATE_SIDE};
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

/// The side of a square map of `len` grid points when it is one the head gives: even
/// (so the crop centre is a grid point), 4 to 16.
fn grid_cells(len: usize) -> Option<usize> {
    let c = (len as f64).sqrt().round() as usize;
    (c * c == len && c.is_multiple_of(2) && (4..=SEARCH_CELLS).contains(&c)).then_some(c)
}

/// The `n × n` cosine window NanoTrack adds to its score map (`np.hanning`, outer product;
/// NanoTrack's is 16×16).
pub fn cosine_window(n: usize) -> Vec<f32> {
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
    let cells = grid_cells(margins.len())?;
    let n = cells * cells;
    if loc.len() != 4 * n || window.len() != n {
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
    let (j, k) = (i / cells, i % cells);
    let half = (cells / 2) as f32;
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

/// Largest per-side calibration factor (and smallest, inverted) the initial frame may set:
/// beyond ×1.5 the head and the given box do not describe the same object's extent.
const MAX_CALIBRATION: f32 = 1.5;

/// Grid points on each side of the crop centre that [`read_at`] averages (1: 3×3).
const READ_RADIUS: usize = CENTRE_RADIUS;

/// The head's box read at the crop centre (the filter's position): the foreground-probability
/// weighted mean of the boxes (left/top/right/bottom corners) regressed at the
/// `(2·READ_RADIUS+1)²` grid points around it, in frame pixels on a crop of `scale_z` crop
/// pixels per frame pixel; its score is the mean probability there and its penalty
/// NanoTrack's against `prior`. Unlike [`select`], a look-alike elsewhere in the crop cannot
/// take the box: every point read lies within a quarter of the target's context of the
/// filter's position. `None` for maps of the wrong length, a degenerate `prior` or
/// `scale_z`, or no finite positive-size box there.
pub fn read_at(
    margins: &[f32],
    loc: &[f32],
    prior: Size2,
    scale_z: f32,
    cfg: &BoxRefineConfig,
) -> Option<HeadBox> {
    let cells = grid_cells(margins.len())?;
    let n = cells * cells;
    if loc.len() != 4 * n {
        return None;
    }
    if !(prior.w > 0.0 && prior.h > 0.0 && scale_z > 0.0 && scale_z.is_finite()) {
        return None;
    }
    let c = cells / 2;
    let (mut wsum, mut psum, mut count) = (0.0f32, 0.0f32, 0usize);
    let mut acc = [0.0f32; 4];
    for j in c - READ_RADIUS..=c + READ_RADIUS {
        for k in c - READ_RADIUS..=c + READ_RADIUS {
            let i = j * cells + k;
            let (l, t, r, b) = (loc[i], loc[n + i], loc[2 * n + i], loc[3 * n + i]);
            let ok = [l, t, r, b, margins[i]].iter().all(|v| v.is_finite());
            if !(ok && l + r > 0.0 && t + b > 0.0) {
                continue;
            }
            let p = 1.0 / (1.0 + (-margins[i]).exp());
            let (px, py) = (
                (k as f32 - c as f32) * STRIDE,
                (j as f32 - c as f32) * STRIDE,
            );
            acc[0] += p * (px - l);
            acc[1] += p * (py - t);
            acc[2] += p * (px + r);
            acc[3] += p * (py + b);
            wsum += p;
            psum += p;
            count += 1;
        }
    }
    if count == 0 || wsum <= 0.0 {
        return None;
    }
    let [x1, y1, x2, y2] = acc.map(|v| v / wsum);
    let (w, h) = (x2 - x1, y2 - y1);
    let (pw, ph) = (prior.w * scale_z, prior.h * scale_z);
    let (s_c, r_c) = (change(sz(w, h) / sz(pw, ph)), change((pw / ph) / (w / h)));
    let penalty = (-(r_c * s_c - 1.0) * cfg.penalty_k).exp();
    let hb = HeadBox {
        dx: 0.5 * (x1 + x2) / scale_z,
        dy: 0.5 * (y1 + y2) / scale_z,
        size: Size2 {
            w: w / scale_z,
            h: h / scale_z,
        },
        score: psum / count as f32,
        penalty,
    };
    let finite = [hb.dx, hb.dy, hb.size.w, hb.size.h, hb.penalty]
        .iter()
        .all(|v| v.is_finite());
    (finite && hb.size.w > 0.0 && hb.size.h > 0.0).then_some(hb)
}

/// The largest finite foreground logit margin among the grid points [`read_at`] reads (the
/// `(2·READ_RADIUS+1)²` around the crop centre); `None` for maps of the wrong length or no
/// finite margin there.
pub fn centre_margin(margins: &[f32]) -> Option<f32> {
    let cells = grid_cells(margins.len())?;
    let c = cells / 2;
    (c - READ_RADIUS..=c + READ_RADIUS)
        .flat_map(|j| (c - READ_RADIUS..=c + READ_RADIUS).map(move |k| j * cells + k))
        .map(|i| margins[i])
        .filter(|m| m.is_finite())
        .reduce(f32::max)
}

/// What the stage decided for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refined {
    /// Box centre, frame pixels.
    pub pos: Point2,
    /// Box size, frame pixels.
    pub size: Size2,
    /// The head's box was taken (false: the filter's centre and the prior size).
    pub taken: bool,
    /// The head's foreground probability where its box was read (0 when it did not run).
    pub score: f32,
    /// The head ran on this frame (false: not due, target too small or no template).
    pub ran: bool,
    /// The head's box centre, frame pixels, when its box was taken (`report_center`).
    pub head_pos: Option<Point2>,
    /// The head's largest foreground logit margin at the filter's position (the grid points
    /// [`read_at`] reads, around the crop centre) when it ran and gave finite maps: what
    /// the verifier's score means, read at the box (`track_state.drift_head`).
    pub witness: Option<f32>,
}

/// IoU of two boxes given by centre and size.
fn iou(a: Point2, sa: Size2, b: Point2, sb: Size2) -> f32 {
    let ix = ((a.x + 0.5 * sa.w).min(b.x + 0.5 * sb.w) - (a.x - 0.5 * sa.w).max(b.x - 0.5 * sb.w))
        .max(0.0);
    let iy = ((a.y + 0.5 * sa.h).min(b.y + 0.5 * sb.h) - (a.y - 0.5 * sa.h).max(b.y - 0.5 * sb.h))
        .max(0.0);
    let inter = ix * iy;
    let union = sa.w * sa.h + sb.w * sb.h - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

/// Fuses the head's box with the filter's (`filter_pos` centre, `prior` size: the previous
/// box moved by the scale filter's change) under the gates of `cfg`: the head must be
/// confident (`min_score`), near (`max_offset` target sizes) and overlapping (`min_iou`);
/// then the size moves towards the head's at `size_rate × penalty × score`, each side by at
/// most `max_change`, and the centre by `center_weight`.
pub fn fuse(
    hb: Option<HeadBox>,
    filter_pos: Point2,
    prior: Size2,
    cfg: &BoxRefineConfig,
) -> Refined {
    let keep = Refined {
        pos: filter_pos,
        size: prior,
        taken: false,
        score: hb.map_or(0.0, |h| h.score),
        ran: hb.is_some(),
        head_pos: None,
        witness: None,
    };
    let Some(h) = hb else {
        return keep;
    };
    let target = (prior.w * prior.h).sqrt();
    let offset = (h.dx * h.dx + h.dy * h.dy).sqrt() / target;
    let head_pos = Point2 {
        x: filter_pos.x + h.dx,
        y: filter_pos.y + h.dy,
    };
    let overlap = iou(head_pos, h.size, filter_pos, prior);
    if !(h.score >= cfg.min_score
        && offset <= cfg.max_offset
        && overlap >= cfg.min_iou
        && target > 0.0)
    {
        return keep;
    }
    let lr = (h.penalty * h.score * cfg.size_rate).clamp(0.0, 1.0);
    let step = 1.0 + cfg.max_change;
    let side = |p: f32, t: f32| (p * (1.0 - lr) + t * lr).clamp(p / step, p * step);
    let size = Size2 {
        w: side(prior.w, h.size.w),
        h: side(prior.h, h.size.h),
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
        ran: true,
        head_pos: Some(head_pos),
        witness: None,
    }
}

/// The box refinement stage: NanoTrack v2's networks and the stage's settings.
#[derive(Debug)]
pub struct BoxRefiner {
    net: NanoVerifier,
    cfg: BoxRefineConfig,
    window: Vec<f32>,
    /// Tracked frames seen since the template was set (the `interval` counter).
    frames: usize,
    /// Per-side factors (w, h) from the head's box to the initial box's extent
    /// (`calibrate`; 1 without).
    calib: (f32, f32),
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
            BoxRefineMode::Nanotrack => {
                let mut v = NanoVerifier::new(bb, hd)?;
                // Its crop's plans now (cached per process), not at the first box.
                v.plan_cells(c.box_refine.search_cells)?;
                v
            }
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
            window: cosine_window(c.box_refine.search_cells),
            frames: 0,
            calib: (1.0, 1.0),
        }))
    }

    /// Whether the head's size also sets the filter's scale (`feed_scale`).
    pub fn feeds_scale(&self) -> bool {
        self.cfg.feed_scale
    }

    /// Whether the head's box is blended into the filter's own box (`prior: filter`)
    /// rather than the previous box.
    pub fn from_filter(&self) -> bool {
        self.cfg.prior == BoxPrior::Filter
    }

    /// Takes the template from `bbox` on the initial frame.
    ///
    /// # Errors
    /// A network error.
    pub fn set_template(&mut self, frame: &Frame<'_>, bbox: BBox) -> Result<(), TrackError> {
        self.frames = 0;
        self.calib = (1.0, 1.0);
        self.net
            .set_template(frame, bbox.center(), bbox.w, bbox.h)?;
        // Calibration: the given box defines the target's extent; the head's own idea of it
        // (a building with its surroundings, a rider with the board) is a per-object bias
        // that the per-side ratio on the initial frame removes from every later box.
        let size = Size2 {
            w: bbox.w,
            h: bbox.h,
        };
        if self.cfg.calibrate && size.w.min(size.h) >= self.cfg.min_side {
            if let (Some(hb), _) = self.head_box(frame, bbox.center(), size, BoxRead::Filter)? {
                let (cw, ch) = (size.w / hb.size.w, size.h / hb.size.h);
                let lim = |c: f32| c.clamp(1.0 / MAX_CALIBRATION, MAX_CALIBRATION);
                if cw.is_finite() && ch.is_finite() && cw > 0.0 && ch > 0.0 {
                    self.calib = (lim(cw), lim(ch));
                }
            }
        }
        Ok(())
    }

    /// The head's box on a search crop at `pos` sized from `prior` (frame pixels), read as
    /// `read` says, uncalibrated (`None` when the maps give no usable box), and the maps'
    /// [`centre_margin`]. `(None, None)` when there is no crop or no maps.
    fn head_box(
        &mut self,
        frame: &Frame<'_>,
        pos: Point2,
        prior: Size2,
        read: BoxRead,
    ) -> Result<(Option<HeadBox>, Option<f32>), TrackError> {
        let s_z = sz(prior.w, prior.h);
        if !(s_z.is_finite() && s_z > 0.0) {
            return Ok((None, None));
        }
        // The crop keeps NanoTrack's pixels per target pixel (`TEMPLATE_SIDE / s_z`) at
        // any `search_cells`: a smaller one is a tighter context around the position.
        let cells = self.cfg.search_cells;
        let side = 16 * cells - 1;
        let s_x = s_z * side as f32 / TEMPLATE_SIDE as f32;
        // `read: filter` and the witness read only the points around the centre: the head
        // computes only those (the same values), `peak` needs the whole maps.
        let maps = match read {
            BoxRead::Filter => self.net.centre_maps_sized(frame, pos, s_x, cells)?,
            BoxRead::Peak => self.net.score_maps_sized(frame, pos, s_x, cells)?,
        };
        let Some((margins, loc)) = maps else {
            return Ok((None, None));
        };
        let scale_z = TEMPLATE_SIDE as f32 / s_z;
        let hb = match read {
            BoxRead::Filter => read_at(&margins, &loc, prior, scale_z, &self.cfg),
            BoxRead::Peak => select(&margins, &loc, prior, scale_z, &self.cfg, &self.window),
        };
        Ok((hb, centre_margin(&margins)))
    }

    /// This frame's box: the head runs (every `interval` calls) on a search crop at
    /// `filter_pos` sized from `prior` (the previous box moved by the scale filter's
    /// change), and [`fuse`] decides between its box and the prior.
    ///
    /// # Errors
    /// A network error.
    pub fn refine(
        &mut self,
        frame: &Frame<'_>,
        filter_pos: Point2,
        prior: Size2,
    ) -> Result<Refined, TrackError> {
        let skip = fuse(None, filter_pos, prior, &self.cfg);
        let due = self.frames.is_multiple_of(self.cfg.interval.max(1));
        self.frames = self.frames.wrapping_add(1);
        if !due || prior.w.min(prior.h) < self.cfg.min_side || !self.net.has_template() {
            return Ok(skip);
        }
        // The prior in the head's units, so that NanoTrack's penalty compares like with like;
        // the head's box back in the initial box's units.
        let (cw, ch) = self.calib;
        let head_prior = Size2 {
            w: prior.w / cw,
            h: prior.h / ch,
        };
        let (hb, witness) = self.head_box(frame, filter_pos, head_prior, self.cfg.read)?;
        let hb = hb.map(|h| HeadBox {
            dx: h.dx,
            dy: h.dy,
            size: Size2 {
                w: h.size.w * cw,
                h: h.size.h * ch,
            },
            ..h
        });
        let out = fuse(hb, filter_pos, prior, &self.cfg);
        // The head ran even when it found no readable box.
        Ok(Refined {
            ran: true,
            witness,
            ..out
        })
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

    /// The witness margin is the largest finite margin of the 3×3 points around the centre
    /// (what `read_at` reads), never one beside them, on any even grid.
    #[test]
    fn centre_margin_reads_only_the_points_around_the_centre() {
        for cells in [SEARCH_CELLS, 12] {
            let n = cells * cells;
            let c = cells / 2;
            let mut m = vec![-3.0; n];
            // A confident point two cells off the centre does not count.
            m[c * cells + c + 2] = 9.0;
            assert_eq!(centre_margin(&m), Some(-3.0), "{cells}");
            m[(c - 1) * cells + c + 1] = 6.5;
            m[c * cells + c] = f32::NAN;
            assert_eq!(centre_margin(&m), Some(6.5), "{cells}");
        }
        assert_eq!(centre_margin(&[1.0; 15]), None);
        assert_eq!(centre_margin(&[f32::NAN; 144]), None);
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
            &cosine_window(SEARCH_CELLS),
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
        let w = cosine_window(SEARCH_CELLS);
        let s = Size2 { w: 20.0, h: 20.0 };
        assert!(select(&m[1..], &loc, s, 2.0, &cfg(), &w).is_none());
        assert!(select(&m, &loc, Size2 { w: 0.0, h: 20.0 }, 2.0, &cfg(), &w).is_none());
        assert!(select(&m, &loc, s, f32::NAN, &cfg(), &w).is_none());
        let nan = vec![f32::NAN; 4 * N];
        assert!(select(&m, &nan, s, 2.0, &cfg(), &w).is_none());
    }

    #[test]
    fn fuse_takes_a_confident_agreeing_box_and_falls_back_otherwise() {
        let c = BoxRefineConfig {
            center_weight: 0.5,
            ..cfg()
        };
        let p = Point2 { x: 100.0, y: 100.0 };
        let prior = Size2 { w: 20.0, h: 20.0 };
        let hb = HeadBox {
            dx: 4.0,
            dy: 0.0,
            size: Size2 { w: 24.0, h: 20.0 },
            score: 0.9,
            penalty: 1.0,
        };
        let r = fuse(Some(hb), p, prior, &c);
        assert!(r.taken);
        assert!(r.size.w > 20.0 && r.size.h == 20.0, "{r:?}");
        assert!((r.pos.x - 102.0).abs() < 1e-4);
        // Unconfident, far away, not overlapping: the prior.
        let tiny = HeadBox {
            size: Size2 { w: 6.0, h: 6.0 },
            dx: 0.0,
            ..hb
        };
        for bad in [
            HeadBox { score: 0.3, ..hb },
            HeadBox { dx: 15.0, ..hb },
            tiny,
        ] {
            let r = fuse(Some(bad), p, prior, &c);
            assert!(!r.taken && r.pos == p && r.size == prior, "{bad:?} {r:?}");
        }
        assert!(!fuse(None, p, prior, &c).taken);
    }

    #[test]
    fn fuse_keeps_the_filter_centre_by_default_and_limits_the_change_per_frame() {
        let c = cfg();
        let p = Point2 { x: 100.0, y: 100.0 };
        let prior = Size2 { w: 40.0, h: 40.0 };
        // A confident head box twice as wide (IoU 0.5 with the prior: just accepted).
        let hb = HeadBox {
            dx: 1.0,
            dy: 0.0,
            size: Size2 { w: 80.0, h: 40.0 },
            score: 1.0,
            penalty: 1.0,
        };
        let r = fuse(Some(hb), p, prior, &c);
        assert!(r.taken, "{r:?}");
        assert_eq!(r.pos, p, "center_weight 0: the filter's centre");
        // Rate 0.39 would give 55.6 px; max_change 0.1 caps it at 44.
        assert!((r.size.w - 44.0).abs() < 1e-3 && r.size.h == 40.0, "{r:?}");
        let loose = BoxRefineConfig {
            max_change: 1.0,
            ..c.clone()
        };
        let r = fuse(Some(hb), p, prior, &loose);
        assert!((r.size.w - 55.6).abs() < 1e-3, "{r:?}");
    }

    #[test]
    fn read_at_takes_the_box_at_the_filter_position_not_a_brighter_look_alike() {
        // The target (a 40×20 crop-pixel box) at the centre with a moderate score, a
        // look-alike (the same box) two cells right with a higher one.
        let (mut m, loc) = maps(8, 8, 40.0, 20.0);
        m[8 * SEARCH_CELLS + 8] = 0.5;
        m[8 * SEARCH_CELLS + 10] = 8.0;
        let prior = Size2 { w: 20.0, h: 10.0 };
        let w = cosine_window(SEARCH_CELLS);
        let peak = select(&m, &loc, prior, 2.0, &cfg(), &w).unwrap();
        assert!(peak.dx > 10.0, "the arg-max takes the look-alike: {peak:?}");
        let at = read_at(&m, &loc, prior, 2.0, &cfg()).unwrap();
        assert!(at.dx.abs() < 1e-3 && at.dy.abs() < 1e-3, "{at:?}");
        assert!(
            (at.size.w - 20.0).abs() < 1e-3 && (at.size.h - 10.0).abs() < 1e-3,
            "{at:?}"
        );
        // Mean probability over the 3×3 points: one at sigmoid(0.5), eight at sigmoid(−6).
        let expect = (1.0 / (1.0 + (-0.5f32).exp()) + 8.0 / (1.0 + 6.0f32.exp())) / 9.0;
        assert!((at.score - expect).abs() < 1e-4, "{}", at.score);
        assert!(
            (at.penalty - 1.0).abs() < 1e-4,
            "same size and aspect as the prior"
        );
    }

    #[test]
    fn read_at_weights_the_points_by_their_probability_and_refuses_bad_maps() {
        // Two confident points around the centre regress different boxes: the mean of
        // their corners, the background points' (probability ~0.0025) nearly nothing.
        let (mut m, mut loc) = maps(8, 8, 40.0, 40.0);
        m[7 * SEARCH_CELLS + 8] = 6.0;
        let i = 7 * SEARCH_CELLS + 8;
        // The point one cell up (16 px) regresses a box 8 px taller at the bottom.
        loc[N + i] = 20.0 - 16.0;
        loc[3 * N + i] = 20.0 + 16.0 + 8.0;
        let hb = read_at(&m, &loc, Size2 { w: 20.0, h: 20.0 }, 1.0, &cfg()).unwrap();
        assert!((hb.size.w - 40.0).abs() < 0.1, "{hb:?}");
        assert!(hb.size.h > 43.5 && hb.size.h < 44.5, "{hb:?}");
        let s = Size2 { w: 20.0, h: 20.0 };
        assert!(read_at(&m[1..], &loc, s, 1.0, &cfg()).is_none());
        assert!(read_at(&m, &loc, Size2 { w: 0.0, h: 1.0 }, 1.0, &cfg()).is_none());
        assert!(read_at(&m, &loc, s, f32::INFINITY, &cfg()).is_none());
        assert!(read_at(&m, &vec![f32::NAN; 4 * N], s, 1.0, &cfg()).is_none());
    }
}
