//! Camera motion compensation: where to look for the target in the next frame when the
//! camera moves.
//!
//! The filter searches a window of about five target sizes around the last position. On
//! a drone the camera itself jerks, turns and is re-pointed, and a small target (11 × 8 px:
//! a 47 px search window) leaves that window on the first jerk of 25 px, although nothing
//! about the target changed. Two estimates predict the search centre instead:
//!
//! - **The scene's shift between frames** ([`SceneShift`]): phase correlation of coarse grey
//!   copies of the whole frames (128 cells along the longer side, each the sum of four
//!   pixels; Hann window; the normalised cross-power spectrum's inverse, a peak of 1 for a
//!   pure shift, near 0.04 for noise). A peak below `min_peak` (texture-poor water or sky,
//!   a scene cut) gives no shift.
//! - **The target's own motion in the scene** ([`Motion::own`]), by `motion.own`:
//!   - `camera`: the camera's smooth motion reversed (a running mean of the shifts). A camera
//!     that follows a car moves the background by −v while the car stays put: own motion
//!     +v, shift −v, prediction 0, as without compensation; a jerk of the camera is not in
//!     the mean and moves the search. A static target under a steady pan is searched as
//!     without compensation (the pan is in the mean). Nothing the tracker measured feeds
//!     it, so a tracker error is not carried into the next search.
//!   - `tracker`: a running mean of what the tracker measured on confident frames less
//!     the scene's shift: right for a static target under a pan too, but the tracker's
//!     errors feed the next search.
//!
//! The prediction moves only where the filter looks; the filter still finds the peak.
//! Taken from: global motion compensation in multi-object trackers on moving cameras
//! (BoT-SORT's GMC, ECC or sparse flow; here phase correlation, Kuglin & Hines 1975, which
//! is one FFT a frame on the grid [`crate::fft`] already plans), and the constant-velocity
//! motion model of Kalman-filter trackers, kept in the stabilised frame.

use crate::config::{MotionConfig, OwnMotion};
use crate::fft::{signed_freq, Fft2};
use crate::filter::label::hann2d;
use crate::geometry::{GridSize, Point2};
use crate::image::Frame;
use rustfft::num_complex::Complex32;

/// Cells along the longer side of the coarse copy.
pub const GRID_CELLS: usize = 128;
/// Largest shift searched, as a fraction of the coarse grid's side along each axis.
const MAX_SHIFT_FRACTION: f32 = 0.25;

/// The whole frame's shift between consecutive frames by phase correlation.
#[derive(Debug, Clone)]
pub struct SceneShift {
    /// Frame pixels per coarse cell.
    step: usize,
    /// The frames' size.
    frame: (usize, usize),
    grid: GridSize,
    fft: Fft2,
    /// Hann window over the grid.
    window: Vec<f32>,
    coarse: Vec<f32>,
    prev: Vec<Complex32>,
    cur: Vec<Complex32>,
    cross: Vec<Complex32>,
    corr: Vec<f32>,
    has_prev: bool,
}

/// One frame's shift estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shift {
    /// How far the scene moved since the previous frame, pixels (a point at `p` in the
    /// previous frame is at `p + d` in this one).
    pub d: Point2,
    /// The phase correlation peak, in [−1, 1] (1: a pure shift).
    pub peak: f32,
}

impl SceneShift {
    /// An estimator for `width × height` frames (both ≥ 1).
    pub fn new(width: usize, height: usize) -> Self {
        let long = width.max(height).max(1);
        let step = long.div_ceil(GRID_CELLS).max(1);
        let grid = GridSize {
            h: (height / step).max(2),
            w: (width / step).max(2),
        };
        let window = hann2d(grid);
        let fft = Fft2::new(grid);
        let n = fft.spectrum_len();
        Self {
            step,
            frame: (width, height),
            grid,
            fft,
            window,
            coarse: vec![0.0; grid.len()],
            prev: vec![Complex32::default(); n],
            cur: vec![Complex32::default(); n],
            cross: vec![Complex32::default(); n],
            corr: vec![0.0; grid.len()],
            has_prev: false,
        }
    }

    /// Forgets the previous frame and takes `frame` as the first.
    pub fn reset(&mut self, frame: &Frame<'_>) {
        self.has_prev = false;
        let _ = self.next(frame);
    }

    /// The shift from the previous frame to `frame` (which becomes the previous one);
    /// `None` on the first frame or for a frame of another size than the estimator's.
    pub fn next(&mut self, frame: &Frame<'_>) -> Option<Shift> {
        if (frame.width(), frame.height()) != self.frame {
            return None;
        }
        self.spectrum(frame);
        let out = self.has_prev.then(|| self.correlate());

        std::mem::swap(&mut self.prev, &mut self.cur);
        self.has_prev = true;
        out
    }

    /// The coarse, windowed grey copy of `frame` and its spectrum into `cur`.
    fn spectrum(&mut self, frame: &Frame<'_>) {
        let (gw, gh, step) = (self.grid.w, self.grid.h, self.step);
        let bpp = frame.format().bytes_per_pixel();
        let offs = frame.format().rgb_offsets();
        let (data, stride) = (frame.data(), frame.stride());
        let (fw, fh) = (frame.width(), frame.height());
        // Four pixels a cell, at a quarter and three quarters of its side each way.
        let (q, q3) = (step / 4, (3 * step) / 4);
        let grey = |x: usize, y: usize| -> f32 {
            let at = y.min(fh - 1) * stride + x.min(fw - 1) * bpp;
            if bpp == 1 {
                4.0 * f32::from(data[at])
            } else {
                f32::from(data[at + offs[0]])
                    + 2.0 * f32::from(data[at + offs[1]])
                    + f32::from(data[at + offs[2]])
            }
        };
        let mut sum = 0.0f64;
        for cy in 0..gh {
            let (y0, y1) = (cy * step + q, cy * step + q3);
            for cx in 0..gw {
                let (x0, x1) = (cx * step + q, cx * step + q3);
                let v = grey(x0, y0) + grey(x1, y0) + grey(x0, y1) + grey(x1, y1);
                self.coarse[cy * gw + cx] = v;
                sum += f64::from(v);
            }
        }
        let mean = (sum / self.grid.len() as f64) as f32;
        for (c, w) in self.coarse.iter_mut().zip(&self.window) {
            *c = (*c - mean) * w;
        }
        self.fft.forward(&self.coarse, &mut self.cur);
    }

    /// Phase correlation of `prev` and `cur`: the peak of the normalised cross-power
    /// spectrum's inverse, refined to a fraction of a cell.
    fn correlate(&mut self) -> Shift {
        for ((x, c), p) in self.cross.iter_mut().zip(&self.cur).zip(&self.prev) {
            let r = c * p.conj();
            let m = r.norm();
            *x = if m > 1e-12 {
                r / m
            } else {
                Complex32::default()
            };
        }
        // The DC bin carries no shift (the means were removed).
        self.cross[0] = Complex32::default();
        self.fft.inverse(&self.cross, &mut self.corr);
        let (h, w) = (self.grid.h, self.grid.w);
        let (my, mx) = (
            (h as f32 * MAX_SHIFT_FRACTION) as isize,
            (w as f32 * MAX_SHIFT_FRACTION) as isize,
        );
        let mut best = (0usize, 0usize, f32::NEG_INFINITY);
        for r in 0..h {
            let dy = signed_freq(r, h) as isize;
            if dy.abs() > my {
                continue;
            }
            for c in 0..w {
                let dx = signed_freq(c, w) as isize;
                if dx.abs() > mx {
                    continue;
                }
                let v = self.corr[r * w + c];
                if v > best.2 {
                    best = (r, c, v);
                }
            }
        }
        let (r, c, peak) = best;
        let at = |r: usize, c: usize| self.corr[(r % h) * w + (c % w)];
        let sub = |m: f32, z: f32, p: f32| {
            let den = m - 2.0 * z + p;
            if den < 0.0 {
                (0.5 * (m - p) / den).clamp(-0.5, 0.5)
            } else {
                0.0
            }
        };
        let fy = sub(at(r + h - 1, c), peak, at(r + 1, c));
        let fx = sub(at(r, c + w - 1), peak, at(r, c + 1));
        let step = self.step as f32;
        Shift {
            d: Point2 {
                x: (signed_freq(c, w) + fx) * step,
                y: (signed_freq(r, h) + fy) * step,
            },
            peak,
        }
    }
}

/// The search centre's prediction: the scene's shift plus the target's own motion.
#[derive(Debug, Clone)]
pub struct Motion {
    scene: SceneShift,
    min_peak: f32,
    rate: f32,
    mode: OwnMotion,
    /// The target's own motion in the scene, pixels a frame (a running mean).
    own: Point2,
    /// This frame's scene shift (zero when not trusted).
    shift: Point2,
    /// This frame's scene shift was trusted.
    trusted: bool,
}

impl Motion {
    /// A model for `width × height` frames with `cfg`'s settings (`camera` is the caller's
    /// business).
    pub fn new(width: usize, height: usize, cfg: &MotionConfig) -> Self {
        Self {
            scene: SceneShift::new(width, height),
            min_peak: cfg.min_peak,
            rate: cfg.own_rate,
            mode: cfg.own,
            own: Point2::default(),
            shift: Point2::default(),
            trusted: false,
        }
    }

    /// Starts on `frame` (the initial frame or a re-initialisation): no motion known.
    pub fn start(&mut self, frame: &Frame<'_>) {
        self.scene.reset(frame);
        self.own = Point2::default();
        self.shift = Point2::default();
        self.trusted = false;
    }

    /// Reads `frame`'s scene shift; returns it when trusted.
    pub fn observe(&mut self, frame: &Frame<'_>) -> Option<Shift> {
        // The previous frame's shift joins the camera's smooth motion now, after it was
        // used: a jerk is not in the mean that cancels the steady part of this frame's.
        if let (OwnMotion::Camera, true) = (self.mode, self.trusted) {
            self.own.x += self.rate * (-self.shift.x - self.own.x);
            self.own.y += self.rate * (-self.shift.y - self.own.y);
        }
        let s = self
            .scene
            .next(frame)
            .filter(|s| s.peak >= self.min_peak && s.d.x.is_finite() && s.d.y.is_finite());
        self.shift = s.map_or(Point2::default(), |s| s.d);
        self.trusted = s.is_some();
        s
    }

    /// Where to search for a target last at `pos`: moved by the scene's shift and the own
    /// motion; with `own: camera`, not moved when this frame's shift is not trusted (the
    /// own motion is the camera's, reversed: it means nothing without the shift).
    pub fn predict(&self, pos: Point2) -> Point2 {
        if self.mode == OwnMotion::Camera && !self.trusted {
            return pos;
        }
        Point2 {
            x: pos.x + self.shift.x + self.own.x,
            y: pos.y + self.shift.y + self.own.y,
        }
    }

    /// Learns the target's own motion from a confident frame: it moved by `moved` pixels
    /// since the previous frame.
    pub fn learn(&mut self, moved: Point2) {
        if self.mode != OwnMotion::Tracker {
            return;
        }
        if !(moved.x.is_finite() && moved.y.is_finite()) || self.rate <= 0.0 {
            return;
        }
        let (ox, oy) = (moved.x - self.shift.x, moved.y - self.shift.y);
        self.own.x += self.rate * (ox - self.own.x);
        self.own.y += self.rate * (oy - self.own.y);
    }

    /// Forgets the target's own motion (after a loss: it is stale).
    pub fn forget_own(&mut self) {
        self.own = Point2::default();
    }

    /// The target's own motion estimate, pixels a frame.
    pub fn own(&self) -> Point2 {
        self.own
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::PixelFormat;

    const W: usize = 640;
    const H: usize = 360;

    /// Smooth random texture (value noise on a 12 px lattice), grey in all three planes,
    /// the scene seen from a camera at `(cx, cy)`: pixel `(x, y)` shows scene point
    /// `(x + cx, y + cy)`, so moving the camera by `+c` moves the scene by `−c`.
    fn scene(cx: i64, cy: i64) -> Vec<u8> {
        let hash = |i: i64, j: i64| -> f32 {
            let mut h = (i.wrapping_mul(73_856_093) ^ j.wrapping_mul(19_349_663)) as u64;
            h ^= h >> 13;
            h = h.wrapping_mul(0x5bd1_e995);
            h ^= h >> 15;
            (h % 256) as f32
        };
        let mut out = Vec::with_capacity(W * H * 3);
        for y in 0..H as i64 {
            for x in 0..W as i64 {
                let (sx, sy) = ((x + cx) as f32 / 12.0, (y + cy) as f32 / 12.0);
                let (i, j) = (sx.floor() as i64, sy.floor() as i64);
                let (fx, fy) = (sx - sx.floor(), sy - sy.floor());
                let v = (hash(i, j) * (1.0 - fx) + hash(i + 1, j) * fx) * (1.0 - fy)
                    + (hash(i, j + 1) * (1.0 - fx) + hash(i + 1, j + 1) * fx) * fy;
                out.extend([v as u8; 3]);
            }
        }
        out
    }

    fn frame(data: &[u8]) -> Frame<'_> {
        Frame::packed(data, W, H, PixelFormat::Rgb8).unwrap()
    }

    fn cfg(own: OwnMotion) -> MotionConfig {
        MotionConfig {
            camera: true,
            min_peak: 0.1,
            own,
            own_rate: 0.3,
            min_move: 0.0,
        }
    }

    #[test]
    fn the_scene_shift_is_found_with_its_sign_to_half_a_cell() {
        // 640 px wide: 5 px cells; the sub-cell fit is good to about a quarter of a cell.
        let mut s = SceneShift::new(W, H);
        s.reset(&frame(&scene(0, 0)));
        let got = s.next(&frame(&scene(23, -11))).unwrap();
        assert!(got.peak > 0.3, "peak {}", got.peak);
        assert!((got.d.x + 23.0).abs() <= 2.5, "dx {}", got.d.x);
        assert!((got.d.y - 11.0).abs() <= 2.5, "dy {}", got.d.y);
        let got = s.next(&frame(&scene(23 - 7, -11 + 30))).unwrap();
        assert!((got.d.x - 7.0).abs() <= 2.5, "dx {}", got.d.x);
        assert!((got.d.y + 30.0).abs() <= 2.5, "dy {}", got.d.y);
    }

    #[test]
    fn no_shift_is_trusted_on_a_featureless_or_resized_frame() {
        let flat = vec![128u8; W * H * 3];
        let mut m = Motion::new(W, H, &cfg(OwnMotion::Camera));
        m.start(&frame(&flat));
        assert_eq!(m.observe(&frame(&flat)), None);
        let p = Point2 { x: 100.0, y: 50.0 };
        assert_eq!(m.predict(p), p);
        // A textured frame after the flat one: no common content, no trusted shift.
        let t = scene(0, 0);
        let s = m.observe(&frame(&t));
        assert!(s.is_none(), "{s:?}");
        // Another frame size: no shift, no panic.
        let small = vec![0u8; 32 * 16 * 3];
        let f = Frame::packed(&small, 32, 16, PixelFormat::Rgb8).unwrap();
        assert!(m.observe(&f).is_none());
        assert_eq!(m.predict(p), p);
    }

    #[test]
    fn own_camera_follows_a_steady_pan_and_moves_the_search_on_a_jerk() {
        let mut m = Motion::new(W, H, &cfg(OwnMotion::Camera));
        m.start(&frame(&scene(0, 0)));
        let p = Point2 { x: 300.0, y: 200.0 };
        // The camera follows a target moving right at 9 px a frame: the scene moves left,
        // the target stays where it is in the image.
        let mut cx = 0;
        for _ in 0..12 {
            cx += 9;
            m.observe(&frame(&scene(cx, 0))).expect("trusted");
        }
        let q = m.predict(p);
        assert!((q.x - p.x).abs() < 1.5 && (q.y - p.y).abs() < 1.0, "{q:?}");
        // A jerk: the camera moves 25 px further down at once; the target's image moves up.
        cx += 9;
        m.observe(&frame(&scene(cx, 25))).expect("trusted");
        let q = m.predict(p);
        assert!((q.x - p.x).abs() < 2.0, "{q:?}");
        assert!((q.y - (p.y - 25.0)).abs() < 1.5, "{q:?}");
    }

    #[test]
    fn own_tracker_learns_the_targets_motion_in_the_scene() {
        let mut m = Motion::new(W, H, &cfg(OwnMotion::Tracker));
        m.start(&frame(&scene(0, 0)));
        let p = Point2 { x: 300.0, y: 200.0 };
        // A static camera; the target moves 6 px right a frame, measured on confident frames.
        for _ in 0..15 {
            m.observe(&frame(&scene(0, 0)));
            m.learn(Point2 { x: 6.0, y: 0.0 });
        }
        let q = m.predict(p);
        assert!(
            (q.x - 306.0).abs() < 0.5 && (q.y - 200.0).abs() < 0.5,
            "{q:?}"
        );
        // Not finite: ignored; a loss forgets the motion.
        m.learn(Point2 {
            x: f32::NAN,
            y: 0.0,
        });
        assert!(m.own().x.is_finite());
        m.forget_own();
        m.observe(&frame(&scene(0, 0)));
        let q = m.predict(p);
        assert!((q.x - 300.0).abs() < 0.5, "{q:?}");
    }
}
