//! Deterministic synthetic sequences with exact ground truth: a textured target that
//! translates and scales over a textured background that moves with the camera.
//!
//! Used by tests (accuracy with known truth), benches, and the `bevt demo` command, so
//! the tracker can be exercised without any dataset.

use crate::geometry::BBox;

/// Parameters of a synthetic sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthParams {
    /// Frame width, pixels.
    pub width: usize,
    /// Frame height, pixels.
    pub height: usize,
    /// Number of frames.
    pub frames: usize,
    /// Initial target size (w, h), pixels.
    pub target: (f32, f32),
    /// Target scale change per frame (multiplicative, e.g. 1.003).
    pub scale_rate: f32,
    /// Change of the target's aspect ratio `w/h` per frame (multiplicative; 1 = none): the
    /// width grows by its square root and the height shrinks by it, area kept.
    pub aspect_rate: f32,
    /// Amplitude of the target's elliptical path, pixels (x, y).
    pub path_amplitude: (f32, f32),
    /// Camera motion per frame (background shift), pixels (x, y).
    pub camera_velocity: (f32, f32),
    /// Texture seed.
    pub seed: u32,
    /// Frames `[start, end)` in which the target is not drawn (occluded or out of view).
    pub hidden: Option<(usize, usize)>,
    /// Shift of the target's path from the end of `hidden` on, pixels (x, y): it
    /// reappears elsewhere.
    pub reappear_offset: (f32, f32),
    /// A look-alike drawn while the target is hidden.
    pub distractor: Option<Distractor>,
}

/// An object drawn like the target (same size, rim and colours) while it is hidden.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Distractor {
    /// Centre, pixels (x, y).
    pub center: (f32, f32),
    /// Texture seed of its inside (the target's `seed` makes an exact copy).
    pub seed: u32,
}

impl Default for SynthParams {
    fn default() -> Self {
        Self {
            width: 320,
            height: 240,
            frames: 60,
            target: (40.0, 32.0),
            scale_rate: 1.004,
            aspect_rate: 1.0,
            path_amplitude: (60.0, 40.0),
            camera_velocity: (1.5, -0.8),
            seed: 7,
            hidden: None,
            reappear_offset: (0.0, 0.0),
            distractor: None,
        }
    }
}

/// One frame: packed RGB8 pixels and the true box.
#[derive(Debug, Clone)]
pub struct SynthFrame {
    /// `width × height × 3` bytes, row-major RGB.
    pub rgb: Vec<u8>,
    /// Ground-truth box (where the target is, drawn or not).
    pub truth: BBox,
    /// The target is drawn in this frame.
    pub visible: bool,
}

/// Width of the target's dark rim as a fraction of its smaller side.
const RIM_FRACTION: f32 = 0.08;

fn hash(x: i32, y: i32, seed: u32) -> f32 {
    let mut h = (x as u32).wrapping_mul(0x8da6_b343)
        ^ (y as u32).wrapping_mul(0xd816_3841)
        ^ seed.wrapping_mul(0xcb1a_b31f);
    h ^= h >> 13;
    h = h.wrapping_mul(0x5bd1_e995);
    h ^= h >> 15;
    (h & 0xffff) as f32 / 65535.0
}

/// Smooth value noise in [0, 1] with feature size `period` pixels.
fn value_noise(x: f32, y: f32, period: f32, seed: u32) -> f32 {
    let (u, v) = (x / period, y / period);
    let (x0, y0) = (u.floor(), v.floor());
    let (fx, fy) = (u - x0, v - y0);
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let (i, j) = (x0 as i32, y0 as i32);
    let a = hash(i, j, seed) + (hash(i + 1, j, seed) - hash(i, j, seed)) * sx;
    let b = hash(i, j + 1, seed) + (hash(i + 1, j + 1, seed) - hash(i, j + 1, seed)) * sx;
    a + (b - a) * sy
}

fn texture(x: f32, y: f32, seed: u32) -> f32 {
    0.5 * value_noise(x, y, 24.0, seed)
        + 0.3 * value_noise(x, y, 8.0, seed + 1)
        + 0.2 * value_noise(x, y, 3.0, seed + 2)
}

impl SynthParams {
    /// A large frame (960×540) and a small target (28×24) that leaves the view on frame
    /// `hide` and re-enters on frame `show` at the far side (380 px left, 200 px down): the
    /// re-detection scene of the lost-state tests, unit and integration alike.
    pub fn far_reentry(hide: usize, show: usize) -> Self {
        Self {
            width: 960,
            height: 540,
            frames: 90,
            target: (28.0, 24.0),
            scale_rate: 1.0,
            path_amplitude: (30.0, 20.0),
            camera_velocity: (0.5, -0.3),
            hidden: Some((hide, show)),
            reappear_offset: (-380.0, 200.0),
            ..Self::default()
        }
    }

    /// The true box of frame `t`.
    pub fn truth(&self, t: usize) -> BBox {
        let tf = t as f32;
        let s = self.scale_rate.powf(tf);
        let a = self.aspect_rate.powf(tf).sqrt();
        let (w, h) = (self.target.0 * s * a, self.target.1 * s / a);
        let phase = tf * 0.06;
        let (ox, oy) = match self.hidden {
            Some((_, end)) if t >= end => self.reappear_offset,
            _ => (0.0, 0.0),
        };
        let cx = self.width as f32 / 2.0 + self.path_amplitude.0 * phase.sin() + ox;
        let cy = self.height as f32 / 2.0 + self.path_amplitude.1 * (1.0 - phase.cos()) + oy;
        BBox::new(
            cx - w / 2.0,
            cy - h / 2.0 - self.path_amplitude.1 / 2.0,
            w,
            h,
        )
    }

    /// True when the target is drawn in frame `t`.
    pub fn visible(&self, t: usize) -> bool {
        !matches!(self.hidden, Some((a, b)) if (a..b).contains(&t))
    }

    /// Renders frame `t`.
    pub fn frame(&self, t: usize) -> SynthFrame {
        let truth = self.truth(t);
        let visible = self.visible(t);
        // What is drawn as "the target" this frame: the target, a distractor, or nothing.
        let drawn = if visible {
            Some((truth, self.seed))
        } else {
            self.distractor.map(|d| {
                (
                    BBox::new(
                        d.center.0 - truth.w / 2.0,
                        d.center.1 - truth.h / 2.0,
                        truth.w,
                        truth.h,
                    ),
                    d.seed,
                )
            })
        };
        let (cam_x, cam_y) = (
            self.camera_velocity.0 * t as f32,
            self.camera_velocity.1 * t as f32,
        );
        let s = truth.w / self.target.0;
        // Texture scale per axis (one scale without aspect change, as it always was).
        let (sx, sy) = if self.aspect_rate == 1.0 {
            (s, s)
        } else {
            (s, truth.h / self.target.1)
        };
        let mut rgb = vec![0u8; self.width * self.height * 3];
        for y in 0..self.height {
            for x in 0..self.width {
                let (xf, yf) = (x as f32 + 0.5, y as f32 + 0.5);
                let inside = drawn
                    .filter(|(b, _)| xf >= b.x && xf < b.x + b.w && yf >= b.y && yf < b.y + b.h);
                let px = &mut rgb[(y * self.width + x) * 3..][..3];
                if let Some((truth, seed)) = inside {
                    // Target texture in its own (scaled) coordinates: moves and scales with it.
                    let (u, v) = ((xf - truth.x) / sx, (yf - truth.y) / sy);
                    // A dark rim (like a vehicle's outline) plus internal texture.
                    let rim = u.min(v).min(self.target.0 - u).min(self.target.1 - v)
                        < RIM_FRACTION * self.target.0.min(self.target.1);
                    let t0 = if rim {
                        0.0
                    } else {
                        texture(u * 0.7, v * 0.7, seed + 100)
                    };
                    px[0] = (60.0 + 190.0 * t0) as u8;
                    px[1] = (30.0 + 120.0 * (1.0 - t0)) as u8;
                    px[2] = (20.0 + 60.0 * t0) as u8;
                } else {
                    let b = texture(xf + cam_x, yf + cam_y, self.seed);
                    let g = (40.0 + 150.0 * b) as u8;
                    px[0] = g;
                    px[1] = (g as f32 * 1.05).min(255.0) as u8;
                    px[2] = (g as f32 * 0.9) as u8;
                }
            }
        }
        SynthFrame {
            rgb,
            truth,
            visible,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_deterministic_and_textured() {
        let p = SynthParams::default();
        let a = p.frame(3);
        let b = p.frame(3);
        assert_eq!(a.rgb, b.rgb);
        let mean = a.rgb.iter().map(|&v| v as f64).sum::<f64>() / a.rgb.len() as f64;
        let var = a
            .rgb
            .iter()
            .map(|&v| (v as f64 - mean).powi(2))
            .sum::<f64>()
            / a.rgb.len() as f64;
        assert!(var > 100.0, "{var}");
    }

    #[test]
    fn hidden_target_is_not_drawn_and_reappears_shifted() {
        let p = SynthParams {
            hidden: Some((5, 8)),
            reappear_offset: (50.0, 0.0),
            ..SynthParams::default()
        };
        let plain = SynthParams::default();
        assert!(p.visible(4) && !p.visible(5) && !p.visible(7) && p.visible(8));
        assert_eq!(p.frame(4).rgb, plain.frame(4).rgb);
        assert_ne!(p.frame(6).rgb, plain.frame(6).rgb);
        assert!(!p.frame(6).visible);
        assert_eq!(p.truth(6), plain.truth(6));
        assert!((p.truth(8).x - plain.truth(8).x - 50.0).abs() < 1e-3);
        let d = SynthParams {
            distractor: Some(Distractor {
                center: (60.0, 60.0),
                seed: 99,
            }),
            ..p.clone()
        };
        assert_ne!(d.frame(6).rgb, p.frame(6).rgb);
        assert_eq!(d.frame(8).rgb, p.frame(8).rgb);
    }

    #[test]
    fn truth_grows_with_the_scale_rate() {
        let p = SynthParams::default();
        assert!(p.truth(50).w > p.truth(0).w * 1.2);
    }
}
