//! Synthetic perturbations of real sequences: each frame *and its ground truth* are
//! transformed consistently, deterministically from a seed, so a dev-set sequence can stand
//! in for harder footage (tiny targets, camera shake, zoom, aspect change, blur,
//! illumination change) without new annotation.
//!
//! A [`Perturbation`] is parsed from `key=value,...` (`bevt eval --perturb`); keys:
//!
//! | key | value | effect on frame `t` |
//! |---|---|---|
//! | `tiny` | F in 0.1..=1 | whole frame downscaled by F (area average): the target is F× smaller |
//! | `zoom` | Z in 1..=3 | whole frame scaled about its centre by Z^sin(2πt/P) (camera zoom) |
//! | `aspect` | A in 1..=3 | x scaled by A^sin(2πt/1.5P), y by its inverse (aspect change) |
//! | `shake` | D in 0..=64 px | whole frame translated by a random integer (dx, dy) in [−D, D]² |
//! | `blur` | σ in 0..=8 px | Gaussian blur (separable, radius ⌈3σ⌉, edges clamped) |
//! | `light` | G in 1..=4 | gain G^sin(2πt/P) on every channel, clamped at 255 |
//! | `gamma` | Γ in 1..=3 | gamma Γ^sin(2πt/1.5P) |
//! | `lookalike` | K in 1.5..=8 | a copy of the initial target, at the target's current size, pasted K target widths to its right (left when that leaves the frame) on every frame: a same-class neighbour ([`SequencePerturbation::paste_lookalike`]) |
//! | `period` | P in 4..=100000 frames | period of the time-varying terms (default 40) |
//! | `seed` | u64 | seed of the shake (mixed with the sequence name) |
//!
//! Order: tiny, then the geometric warp (zoom, aspect, shake as one bilinear resampling,
//! borders filled with grey 128), then blur, then the photometric terms, then the look-alike
//! (pasted by the caller, who holds the initial frame's patch and the frame's truth). The box follows
//! the geometry exactly (`x' = c + s·(x − c) + d` per axis, `c` the frame centre); a box
//! moved wholly off the frame becomes absent (`None`, as a NaN annotation row). Frame `t =
//! 0` is only changed by `tiny` and `blur` (every time-varying term is 1 or 0 there), so
//! the tracker starts from the same view. Memory: two frame-sized buffers per call.

use crate::geometry::BBox;
use std::f64::consts::PI;
use std::fmt;
use thiserror::Error;

/// Default period of the time-varying terms, frames (4 s at UAV123@10fps).
pub const DEFAULT_PERIOD: u32 = 40;
/// Smallest side of a perturbed frame, pixels (`tiny` must not shrink a frame below it).
pub const MIN_SIDE: usize = 16;
/// Grey level of the border revealed by shake, zoom and aspect.
pub const FILL: u8 = 128;

/// Why a perturbation or a frame cannot be used.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum PerturbError {
    /// The specification is empty.
    #[error("empty perturbation: expected key=value[,key=value...], keys {KEYS}")]
    Empty,
    /// An item is not `key=value`.
    #[error("{0:?}: expected key=value (keys {KEYS})")]
    Syntax(String),
    /// An unknown key.
    #[error("unknown perturbation {0:?} (keys {KEYS})")]
    UnknownKey(String),
    /// A key given twice.
    #[error("perturbation {0:?} is given twice")]
    Duplicate(String),
    /// A value that does not parse or is out of its range.
    #[error("{key}={value}: expected {expected}")]
    Value {
        /// The key.
        key: String,
        /// The value as given.
        value: String,
        /// The accepted range.
        expected: &'static str,
    },
    /// The frame buffer does not match its size.
    #[error("frame buffer of {got} bytes for {width}x{height} RGB")]
    Buffer {
        /// Width.
        width: usize,
        /// Height.
        height: usize,
        /// Bytes given.
        got: usize,
    },
    /// `tiny` would shrink the frame below [`MIN_SIDE`].
    #[error("tiny={factor} shrinks a {width}x{height} frame below {MIN_SIDE} px a side")]
    TooSmall {
        /// The factor.
        factor: f32,
        /// Width.
        width: usize,
        /// Height.
        height: usize,
    },
}

const KEYS: &str = "tiny, zoom, aspect, shake, blur, light, gamma, lookalike, period, seed";

/// A perturbation (see the module documentation). The default changes nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Perturbation {
    /// Static downscale factor, 0.1..=1 (1 = none).
    pub tiny: f32,
    /// Zoom amplitude, 1..=3 (1 = none).
    pub zoom: f32,
    /// Aspect amplitude, 1..=3 (1 = none).
    pub aspect: f32,
    /// Shake amplitude, pixels, 0..=64.
    pub shake: u32,
    /// Gaussian blur σ, pixels, 0..=8.
    pub blur: f32,
    /// Gain amplitude, 1..=4 (1 = none).
    pub light: f32,
    /// Gamma amplitude, 1..=3 (1 = none).
    pub gamma: f32,
    /// Look-alike distance in target widths, 1.5..=8 (0 = none).
    pub lookalike: f32,
    /// Period of the time-varying terms, frames.
    pub period: u32,
    /// Seed of the shake.
    pub seed: u64,
}

impl Default for Perturbation {
    fn default() -> Self {
        Self {
            tiny: 1.0,
            zoom: 1.0,
            aspect: 1.0,
            shake: 0,
            blur: 0.0,
            light: 1.0,
            gamma: 1.0,
            lookalike: 0.0,
            period: DEFAULT_PERIOD,
            seed: 0,
        }
    }
}

fn parse_f32(
    key: &str,
    value: &str,
    lo: f32,
    hi: f32,
    lo_open: bool,
    expected: &'static str,
) -> Result<f32, PerturbError> {
    let bad = || PerturbError::Value {
        key: key.into(),
        value: value.into(),
        expected,
    };
    let v: f32 = value.trim().parse().map_err(|_| bad())?;
    let above = if lo_open { v > lo } else { v >= lo };
    if v.is_finite() && above && v <= hi {
        Ok(v)
    } else {
        Err(bad())
    }
}

fn parse_u32(
    key: &str,
    value: &str,
    lo: u32,
    hi: u32,
    expected: &'static str,
) -> Result<u32, PerturbError> {
    match value.trim().parse::<u32>() {
        Ok(v) if (lo..=hi).contains(&v) => Ok(v),
        _ => Err(PerturbError::Value {
            key: key.into(),
            value: value.into(),
            expected,
        }),
    }
}

impl Perturbation {
    /// Parses `key=value,...` (see the module documentation for keys and ranges).
    ///
    /// # Errors
    /// An empty specification, an item that is not `key=value`, an unknown or repeated key,
    /// or a value out of its range.
    pub fn parse(spec: &str) -> Result<Self, PerturbError> {
        if spec.trim().is_empty() {
            return Err(PerturbError::Empty);
        }
        let mut p = Self::default();
        let mut seen: Vec<String> = Vec::new();
        for item in spec.split(',') {
            let (k, v) = item
                .split_once('=')
                .ok_or_else(|| PerturbError::Syntax(item.to_string()))?;
            let k = k.trim();
            if seen.iter().any(|s| s == k) {
                return Err(PerturbError::Duplicate(k.into()));
            }
            match k {
                "tiny" => p.tiny = parse_f32(k, v, 0.1, 1.0, false, "a factor in 0.1..=1")?,
                "zoom" => p.zoom = parse_f32(k, v, 1.0, 3.0, false, "an amplitude in 1..=3")?,
                "aspect" => p.aspect = parse_f32(k, v, 1.0, 3.0, false, "an amplitude in 1..=3")?,
                "shake" => p.shake = parse_u32(k, v, 0, 64, "whole pixels in 0..=64")?,
                "blur" => p.blur = parse_f32(k, v, 0.0, 8.0, false, "a sigma in 0..=8 px")?,
                "light" => p.light = parse_f32(k, v, 1.0, 4.0, false, "a gain amplitude in 1..=4")?,
                "gamma" => p.gamma = parse_f32(k, v, 1.0, 3.0, false, "an amplitude in 1..=3")?,
                "lookalike" => {
                    p.lookalike =
                        parse_f32(k, v, 1.5, 8.0, false, "a distance in 1.5..=8 target widths")?
                }
                "period" => p.period = parse_u32(k, v, 4, 100_000, "frames in 4..=100000")?,
                "seed" => {
                    p.seed = v.trim().parse().map_err(|_| PerturbError::Value {
                        key: k.into(),
                        value: v.into(),
                        expected: "an unsigned 64-bit integer",
                    })?
                }
                _ => return Err(PerturbError::UnknownKey(k.into())),
            }
            seen.push(k.to_string());
        }
        Ok(p)
    }

    /// The perturbation of one sequence: the shake's random stream depends on the seed and
    /// the sequence's name, so sequences are shaken differently and every run alike.
    pub fn for_sequence(&self, name: &str) -> SequencePerturbation {
        // FNV-1a of the name.
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in name.bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
        SequencePerturbation {
            p: *self,
            stream: splitmix64(self.seed ^ h),
        }
    }
}

impl fmt::Display for Perturbation {
    /// The canonical `key=value,...` form (only the keys that differ from the default).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let d = Self::default();
        let mut items: Vec<String> = Vec::new();
        if self.tiny != d.tiny {
            items.push(format!("tiny={}", self.tiny));
        }
        if self.zoom != d.zoom {
            items.push(format!("zoom={}", self.zoom));
        }
        if self.aspect != d.aspect {
            items.push(format!("aspect={}", self.aspect));
        }
        if self.shake != d.shake {
            items.push(format!("shake={}", self.shake));
        }
        if self.blur != d.blur {
            items.push(format!("blur={}", self.blur));
        }
        if self.light != d.light {
            items.push(format!("light={}", self.light));
        }
        if self.gamma != d.gamma {
            items.push(format!("gamma={}", self.gamma));
        }
        if self.lookalike != d.lookalike {
            items.push(format!("lookalike={}", self.lookalike));
        }
        if self.period != d.period {
            items.push(format!("period={}", self.period));
        }
        if self.seed != d.seed {
            items.push(format!("seed={}", self.seed));
        }
        if items.is_empty() {
            write!(f, "none")
        } else {
            write!(f, "{}", items.join(","))
        }
    }
}

fn splitmix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = x;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The geometric part of one frame's perturbation, in the coordinates after `tiny`:
/// `x' = cx + sx·(x − cx) + dx`, `y' = cy + sy·(y − cy) + dy`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Warp {
    /// Centre, x (half the width after `tiny`).
    pub cx: f64,
    /// Centre, y.
    pub cy: f64,
    /// Scale along x.
    pub sx: f64,
    /// Scale along y.
    pub sy: f64,
    /// Shift along x, pixels.
    pub dx: f64,
    /// Shift along y, pixels.
    pub dy: f64,
}

impl Warp {
    fn is_identity(&self) -> bool {
        self.sx == 1.0 && self.sy == 1.0 && self.dx == 0.0 && self.dy == 0.0
    }
}

/// A [`Perturbation`] bound to one sequence (see [`Perturbation::for_sequence`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SequencePerturbation {
    p: Perturbation,
    stream: u64,
}

impl SequencePerturbation {
    /// The size of a `width × height` frame after the perturbation.
    ///
    /// # Errors
    /// [`PerturbError::TooSmall`] when `tiny` would leave less than [`MIN_SIDE`] px a side.
    pub fn output_size(&self, width: usize, height: usize) -> Result<(usize, usize), PerturbError> {
        if self.p.tiny >= 1.0 {
            return Ok((width, height));
        }
        let ow = (width as f64 * f64::from(self.p.tiny)).round() as usize;
        let oh = (height as f64 * f64::from(self.p.tiny)).round() as usize;
        if ow < MIN_SIDE || oh < MIN_SIDE {
            return Err(PerturbError::TooSmall {
                factor: self.p.tiny,
                width,
                height,
            });
        }
        Ok((ow, oh))
    }

    fn phase(&self, t: usize, stretch: f64) -> f64 {
        (2.0 * PI * t as f64 / (f64::from(self.p.period) * stretch)).sin()
    }

    /// The shake of frame `t`: integers in `[-shake, shake]`, (0, 0) on frame 0.
    pub fn shake(&self, t: usize) -> (i32, i32) {
        let d = self.p.shake;
        if d == 0 || t == 0 {
            return (0, 0);
        }
        let r = splitmix64(self.stream ^ splitmix64(t as u64));
        let span = u64::from(2 * d + 1);
        let pick = |x: u64| (x % span) as i32 - d as i32;
        (pick(r & 0xffff_ffff), pick(r >> 32))
    }

    /// The warp of frame `t` on a frame of `width × height` after `tiny`.
    pub fn warp(&self, t: usize, width: usize, height: usize) -> Warp {
        let s = f64::from(self.p.zoom).powf(self.phase(t, 1.0));
        let a = f64::from(self.p.aspect).powf(self.phase(t, 1.5));
        let (dx, dy) = self.shake(t);
        Warp {
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
            sx: s * a,
            sy: s / a,
            dx: f64::from(dx),
            dy: f64::from(dy),
        }
    }

    /// The ground truth of frame `t` (a `width × height` frame before the perturbation)
    /// moved with the frame; `None` when it leaves the frame entirely.
    ///
    /// # Errors
    /// As [`Self::output_size`].
    pub fn apply_box(
        &self,
        t: usize,
        width: usize,
        height: usize,
        b: BBox,
    ) -> Result<Option<BBox>, PerturbError> {
        let (ow, oh) = self.output_size(width, height)?;
        let (kx, ky) = (ow as f64 / width as f64, oh as f64 / height as f64);
        let w = self.warp(t, ow, oh);
        let x = w.cx + w.sx * (f64::from(b.x) * kx - w.cx) + w.dx;
        let y = w.cy + w.sy * (f64::from(b.y) * ky - w.cy) + w.dy;
        let bw = f64::from(b.w) * kx * w.sx;
        let bh = f64::from(b.h) * ky * w.sy;
        let off = x + bw <= 0.0 || y + bh <= 0.0 || x >= ow as f64 || y >= oh as f64;
        Ok((!off).then(|| BBox::new(x as f32, y as f32, bw as f32, bh as f32)))
    }

    /// Frame `t`, packed RGB8 `width × height`, perturbed: returns the new buffer and size.
    ///
    /// # Errors
    /// A buffer of the wrong length, or `tiny` shrinking the frame below [`MIN_SIDE`].
    pub fn apply_frame(
        &self,
        t: usize,
        rgb: Vec<u8>,
        width: usize,
        height: usize,
    ) -> Result<(Vec<u8>, usize, usize), PerturbError> {
        if width.checked_mul(height).and_then(|n| n.checked_mul(3)) != Some(rgb.len()) {
            return Err(PerturbError::Buffer {
                width,
                height,
                got: rgb.len(),
            });
        }
        let (ow, oh) = self.output_size(width, height)?;
        let mut img = if (ow, oh) == (width, height) {
            rgb
        } else {
            area_resize(&rgb, width, height, ow, oh)
        };
        let w = self.warp(t, ow, oh);
        if !w.is_identity() {
            img = warp_image(&img, ow, oh, &w);
        }
        if self.p.blur > 0.0 {
            gaussian_blur(&mut img, ow, oh, self.p.blur);
        }
        let gain = f64::from(self.p.light).powf(self.phase(t, 1.0));
        let gamma = f64::from(self.p.gamma).powf(self.phase(t, 1.5));
        if gain != 1.0 || gamma != 1.0 {
            let lut: Vec<u8> = (0..256)
                .map(|v| {
                    let x = (v as f64 / 255.0).powf(gamma) * gain * 255.0;
                    x.round().clamp(0.0, 255.0) as u8
                })
                .collect();
            for v in &mut img {
                *v = lut[usize::from(*v)];
            }
        }
        Ok((img, ow, oh))
    }
}

/// A patch of a frame: the look-alike's appearance.
#[derive(Debug, Clone, PartialEq)]
pub struct Patch {
    rgb: Vec<u8>,
    width: usize,
    height: usize,
}

impl SequencePerturbation {
    /// Whether a look-alike is pasted ([`Self::cut_patch`], [`Self::paste_lookalike`]).
    pub fn has_lookalike(&self) -> bool {
        self.p.lookalike > 0.0
    }

    /// The pixels of `b` in a packed RGB `width × height` frame (clipped to the frame;
    /// `None` when nothing of it is inside).
    pub fn cut_patch(&self, rgb: &[u8], width: usize, height: usize, b: BBox) -> Option<Patch> {
        let x0 = f64::from(b.x).round().max(0.0) as usize;
        let y0 = f64::from(b.y).round().max(0.0) as usize;
        let x1 = (f64::from(b.x + b.w).round().max(0.0) as usize).min(width);
        let y1 = (f64::from(b.y + b.h).round().max(0.0) as usize).min(height);
        if x1 <= x0 || y1 <= y0 || rgb.len() != width * height * 3 {
            return None;
        }
        let mut out = Vec::with_capacity((x1 - x0) * (y1 - y0) * 3);
        for y in y0..y1 {
            out.extend_from_slice(&rgb[(y * width + x0) * 3..(y * width + x1) * 3]);
        }
        Some(Patch {
            rgb: out,
            width: x1 - x0,
            height: y1 - y0,
        })
    }

    /// Where the look-alike of a target at `b` goes: `lookalike` target widths to its right,
    /// or to its left when the right would leave the frame; `None` when neither fits.
    pub fn lookalike_box(&self, width: usize, b: BBox) -> Option<BBox> {
        let d = self.p.lookalike * b.w;
        [b.x + d, b.x - d]
            .into_iter()
            .find(|&x| x >= 0.0 && x + b.w <= width as f32)
            .map(|x| BBox::new(x, b.y, b.w, b.h))
    }

    /// Pastes `patch`, resized (nearest) to the target's current box `b`, at
    /// [`Self::lookalike_box`] in the packed RGB frame; returns where (the truth is unchanged:
    /// the look-alike is not the target).
    pub fn paste_lookalike(
        &self,
        rgb: &mut [u8],
        width: usize,
        height: usize,
        b: BBox,
        patch: &Patch,
    ) -> Option<BBox> {
        if !self.has_lookalike() || rgb.len() != width * height * 3 {
            return None;
        }
        let at = self.lookalike_box(width, b)?;
        let x0 = f64::from(at.x).round() as usize;
        let y0 = f64::from(at.y).round().max(0.0) as usize;
        let pw = (f64::from(at.w).round() as usize).max(1);
        let ph = (f64::from(at.h).round() as usize).max(1);
        for y in 0..ph {
            let fy = y0 + y;
            if fy >= height {
                break;
            }
            let sy = (y * patch.height / ph).min(patch.height - 1);
            for x in 0..pw {
                let fx = x0 + x;
                if fx >= width {
                    break;
                }
                let sx = (x * patch.width / pw).min(patch.width - 1);
                let (d, o) = ((fy * width + fx) * 3, (sy * patch.width + sx) * 3);
                rgb[d..d + 3].copy_from_slice(&patch.rgb[o..o + 3]);
            }
        }
        Some(at)
    }
}

/// Box-filter downscale: every source pixel is averaged into the output pixel its centre
/// falls in, so output pixel `i` covers source `[i·w/ow, (i+1)·w/ow)`.
fn area_resize(src: &[u8], w: usize, h: usize, ow: usize, oh: usize) -> Vec<u8> {
    let mut sum = vec![0u32; ow * oh * 3];
    let mut count = vec![0u32; ow * oh];
    let col: Vec<usize> = (0..w)
        .map(|x| ((x * 2 + 1) * ow / (2 * w)).min(ow - 1))
        .collect();
    for y in 0..h {
        let oy = ((y * 2 + 1) * oh / (2 * h)).min(oh - 1);
        for (x, &ox) in col.iter().enumerate() {
            let o = oy * ow + ox;
            count[o] += 1;
            for c in 0..3 {
                sum[o * 3 + c] += u32::from(src[(y * w + x) * 3 + c]);
            }
        }
    }
    sum.iter()
        .enumerate()
        .map(|(i, &s)| {
            let n = count[i / 3].max(1);
            ((s + n / 2) / n) as u8
        })
        .collect()
}

/// Bilinear resampling by the inverse of `warp`; outside the source: [`FILL`].
fn warp_image(src: &[u8], w: usize, h: usize, warp: &Warp) -> Vec<u8> {
    let mut out = vec![FILL; w * h * 3];
    for y in 0..h {
        // Continuous source coordinate of the output pixel centre, then pixel-index space.
        let v = warp.cy + (y as f64 + 0.5 - warp.cy - warp.dy) / warp.sy - 0.5;
        if v < -0.5 || v > h as f64 - 0.5 {
            continue;
        }
        let v = v.clamp(0.0, (h - 1) as f64);
        let y0 = v.floor() as usize;
        let y1 = (y0 + 1).min(h - 1);
        let fy = v - y0 as f64;
        for x in 0..w {
            let u = warp.cx + (x as f64 + 0.5 - warp.cx - warp.dx) / warp.sx - 0.5;
            if u < -0.5 || u > w as f64 - 0.5 {
                continue;
            }
            let u = u.clamp(0.0, (w - 1) as f64);
            let x0 = u.floor() as usize;
            let x1 = (x0 + 1).min(w - 1);
            let fx = u - x0 as f64;
            for c in 0..3 {
                let p = |xx: usize, yy: usize| f64::from(src[(yy * w + xx) * 3 + c]);
                let top = p(x0, y0) * (1.0 - fx) + p(x1, y0) * fx;
                let bottom = p(x0, y1) * (1.0 - fx) + p(x1, y1) * fx;
                out[(y * w + x) * 3 + c] = (top * (1.0 - fy) + bottom * fy).round() as u8;
            }
        }
    }
    out
}

/// Separable Gaussian blur in place, radius ⌈3σ⌉, edges clamped.
fn gaussian_blur(img: &mut [u8], w: usize, h: usize, sigma: f32) {
    let r = (3.0 * sigma).ceil() as isize;
    let k: Vec<f32> = (-r..=r)
        .map(|i| (-((i * i) as f32) / (2.0 * sigma * sigma)).exp())
        .collect();
    let norm: f32 = k.iter().sum();
    let k: Vec<f32> = k.iter().map(|v| v / norm).collect();
    let mut tmp = vec![0f32; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let mut acc = 0.0;
                for (j, kv) in k.iter().enumerate() {
                    let xx = (x as isize + j as isize - r).clamp(0, w as isize - 1) as usize;
                    acc += kv * f32::from(img[(y * w + xx) * 3 + c]);
                }
                tmp[(y * w + x) * 3 + c] = acc;
            }
        }
    }
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let mut acc = 0.0;
                for (j, kv) in k.iter().enumerate() {
                    let yy = (y as isize + j as isize - r).clamp(0, h as isize - 1) as usize;
                    acc += kv * tmp[(yy * w + x) * 3 + c];
                }
                img[(y * w + x) * 3 + c] = acc.round().clamp(0.0, 255.0) as u8;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grey frame with a white box at `b` (pixel-aligned).
    fn frame_with_box(w: usize, h: usize, b: (usize, usize, usize, usize)) -> Vec<u8> {
        let mut f = vec![40u8; w * h * 3];
        for y in b.1..b.1 + b.3 {
            for x in b.0..b.0 + b.2 {
                for c in 0..3 {
                    f[(y * w + x) * 3 + c] = 250;
                }
            }
        }
        f
    }

    /// Bounding box of the pixels brighter than 190 (red channel), as x, y, w, h.
    fn bright_box(f: &[u8], w: usize, h: usize) -> Option<(f64, f64, f64, f64)> {
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for y in 0..h {
            for x in 0..w {
                if f[(y * w + x) * 3] > 190 {
                    x0 = x0.min(x);
                    y0 = y0.min(y);
                    x1 = x1.max(x);
                    y1 = y1.max(y);
                }
            }
        }
        (x0 != usize::MAX).then(|| {
            (
                x0 as f64,
                y0 as f64,
                (x1 + 1 - x0) as f64,
                (y1 + 1 - y0) as f64,
            )
        })
    }

    fn close(b: BBox, m: (f64, f64, f64, f64), tol: f64) -> bool {
        (f64::from(b.x) - m.0).abs() <= tol
            && (f64::from(b.y) - m.1).abs() <= tol
            && (f64::from(b.w) - m.2).abs() <= tol
            && (f64::from(b.h) - m.3).abs() <= tol
    }

    #[test]
    fn shake_moves_the_box_by_the_frame_shift_exactly() {
        let (w, h) = (160, 120);
        let b = (60, 40, 20, 16);
        let truth = BBox::new(60.0, 40.0, 20.0, 16.0);
        let sp = Perturbation::parse("shake=12,seed=7")
            .unwrap()
            .for_sequence("seq");
        let mut moved = 0;
        for t in 0..20 {
            let (dx, dy) = sp.shake(t);
            assert!(dx.abs() <= 12 && dy.abs() <= 12);
            moved += usize::from((dx, dy) != (0, 0));
            let (f, ow, oh) = sp.apply_frame(t, frame_with_box(w, h, b), w, h).unwrap();
            assert_eq!((ow, oh), (w, h));
            let tb = sp.apply_box(t, w, h, truth).unwrap().unwrap();
            assert_eq!(tb.x, 60.0 + dx as f32, "frame {t}");
            assert_eq!(tb.y, 40.0 + dy as f32, "frame {t}");
            assert_eq!((tb.w, tb.h), (20.0, 16.0));
            let m = bright_box(&f, ow, oh).unwrap();
            assert!(close(tb, m, 0.0), "frame {t}: {tb:?} vs {m:?}");
            // The revealed border is filled.
            if dx > 0 {
                assert_eq!(f[(h / 2 * w) * 3], FILL);
            }
        }
        assert!(moved >= 15, "the shake moved only {moved} of 20 frames");
        assert_eq!(sp.shake(0), (0, 0));
    }

    #[test]
    fn shake_is_repeatable_and_depends_on_seed_and_sequence() {
        let p = Perturbation::parse("shake=8,seed=1").unwrap();
        let a: Vec<_> = (0..30).map(|t| p.for_sequence("a").shake(t)).collect();
        let a2: Vec<_> = (0..30).map(|t| p.for_sequence("a").shake(t)).collect();
        let b: Vec<_> = (0..30).map(|t| p.for_sequence("b").shake(t)).collect();
        let q = Perturbation::parse("shake=8,seed=2").unwrap();
        let a3: Vec<_> = (0..30).map(|t| q.for_sequence("a").shake(t)).collect();
        assert_eq!(a, a2);
        assert_ne!(a, b);
        assert_ne!(a, a3);
    }

    #[test]
    fn zoom_and_aspect_move_the_box_with_the_content() {
        let (w, h) = (200, 160);
        let b = (70, 50, 40, 30);
        let truth = BBox::new(70.0, 50.0, 40.0, 30.0);
        let sp = Perturbation::parse("zoom=1.5,aspect=1.3,period=8")
            .unwrap()
            .for_sequence("z");
        for t in [0, 1, 2, 3, 5, 6, 9] {
            let wp = sp.warp(t, w, h);
            let (f, _, _) = sp.apply_frame(t, frame_with_box(w, h, b), w, h).unwrap();
            let tb = sp.apply_box(t, w, h, truth).unwrap().unwrap();
            let m = bright_box(&f, w, h).unwrap();
            // Bilinear edges: within a pixel of the transformed box.
            assert!(close(tb, m, 1.5), "frame {t} ({wp:?}): {tb:?} vs {m:?}");
        }
        // Frame 2 of period 8: zoom at its peak, 1.5x about the centre.
        let wp = sp.warp(2, w, h);
        assert!((wp.sx * wp.sy - 1.5 * 1.5).abs() < 1e-9, "{wp:?}");
        // The aspect changes: sx/sy is not 1 on frame 2.
        assert!((wp.sx / wp.sy - 1.0).abs() > 0.1, "{wp:?}");
        assert_eq!(sp.warp(0, w, h).sx, 1.0);
    }

    #[test]
    fn tiny_shrinks_frame_and_box_by_the_same_factor() {
        let (w, h) = (200, 100);
        let sp = Perturbation::parse("tiny=0.25").unwrap().for_sequence("t");
        let (f, ow, oh) = sp
            .apply_frame(0, frame_with_box(w, h, (80, 40, 40, 20)), w, h)
            .unwrap();
        assert_eq!((ow, oh), (50, 25));
        let tb = sp
            .apply_box(0, w, h, BBox::new(80.0, 40.0, 40.0, 20.0))
            .unwrap()
            .unwrap();
        assert_eq!((tb.x, tb.y, tb.w, tb.h), (20.0, 10.0, 10.0, 5.0));
        let m = bright_box(&f, ow, oh).unwrap();
        assert!(close(tb, m, 0.0), "{tb:?} vs {m:?}");
        let e = Perturbation::parse("tiny=0.1")
            .unwrap()
            .for_sequence("t")
            .apply_frame(0, vec![0; 100 * 100 * 3], 100, 100)
            .unwrap_err();
        assert!(matches!(e, PerturbError::TooSmall { .. }), "{e}");
    }

    #[test]
    fn a_box_moved_off_the_frame_is_absent() {
        let sp = Perturbation::parse("shake=30,seed=3")
            .unwrap()
            .for_sequence("s");
        // A box hugging the left edge leaves the frame on some shaken frame.
        let b = BBox::new(0.0, 50.0, 5.0, 5.0);
        let gone = (1..200)
            .filter(|&t| sp.apply_box(t, 100, 100, b).unwrap().is_none())
            .count();
        let left = (1..200).filter(|&t| sp.shake(t).0 <= -5).count();
        assert_eq!(gone, left);
        assert!(gone > 0);
    }

    #[test]
    fn blur_and_light_keep_the_box_and_change_the_pixels() {
        let (w, h) = (64, 48);
        let f0 = frame_with_box(w, h, (20, 10, 10, 10));
        let b = BBox::new(20.0, 10.0, 10.0, 10.0);
        let sp = Perturbation::parse("blur=2").unwrap().for_sequence("b");
        let (f, _, _) = sp.apply_frame(3, f0.clone(), w, h).unwrap();
        assert_eq!(sp.apply_box(3, w, h, b).unwrap(), Some(b));
        // The edge is softened; the box's centre keeps its level, the far background too.
        let at = |f: &[u8], x: usize, y: usize| f[(y * w + x) * 3];
        assert!(
            at(&f, 19, 15) > 60 && at(&f, 19, 15) < 230,
            "{}",
            at(&f, 19, 15)
        );
        assert!(at(&f, 25, 15) > 230, "{}", at(&f, 25, 15));
        assert_eq!(at(&f, 60, 40), 40);
        let sp = Perturbation::parse("light=2,period=4")
            .unwrap()
            .for_sequence("l");
        // Frame 1 of period 4: gain 2; frame 3: gain 1/2.
        let (f1, _, _) = sp.apply_frame(1, f0.clone(), w, h).unwrap();
        let (f3, _, _) = sp.apply_frame(3, f0.clone(), w, h).unwrap();
        assert_eq!(at(&f1, 60, 40), 80);
        assert_eq!(at(&f1, 25, 15), 255);
        assert_eq!(at(&f3, 60, 40), 20);
        assert_eq!(at(&f3, 25, 15), 125);
        assert_eq!(sp.apply_frame(0, f0.clone(), w, h).unwrap().0, f0);
    }

    #[test]
    fn the_lookalike_is_the_initial_target_beside_the_current_one() {
        let (w, h) = (200, 100);
        let sp = Perturbation::parse("lookalike=2")
            .unwrap()
            .for_sequence("l");
        assert!(sp.has_lookalike());
        let f0 = frame_with_box(w, h, (20, 30, 10, 20));
        let patch = sp
            .cut_patch(&f0, w, h, BBox::new(20.0, 30.0, 10.0, 20.0))
            .unwrap();
        // Later the target is at (100, 40), 20x40: the copy goes 2 widths (40 px) right, at
        // that size; the truth stays on the target.
        let mut f = vec![40u8; w * h * 3];
        let b = BBox::new(100.0, 40.0, 20.0, 40.0);
        let at = sp.paste_lookalike(&mut f, w, h, b, &patch).unwrap();
        assert_eq!(at, BBox::new(140.0, 40.0, 20.0, 40.0));
        assert_eq!(bright_box(&f, w, h), Some((140.0, 40.0, 20.0, 40.0)));
        // Near the right edge it goes to the left.
        let b = BBox::new(170.0, 10.0, 20.0, 20.0);
        assert_eq!(
            sp.lookalike_box(w, b),
            Some(BBox::new(130.0, 10.0, 20.0, 20.0))
        );
        // No look-alike asked for: nothing pasted.
        let none = Perturbation::parse("blur=1").unwrap().for_sequence("l");
        let mut g = vec![40u8; w * h * 3];
        assert_eq!(none.paste_lookalike(&mut g, w, h, b, &patch), None);
        assert!(g.iter().all(|&v| v == 40));
        assert_eq!(
            sp.cut_patch(&f0, w, h, BBox::new(-50.0, 0.0, 10.0, 10.0)),
            None
        );
    }

    #[test]
    fn specifications_parse_print_and_fail_clearly() {
        let p = Perturbation::parse("blur=2, shake=8 ,seed=5,tiny=0.5").unwrap();
        assert_eq!(p.to_string(), "tiny=0.5,shake=8,blur=2,seed=5");
        assert_eq!(Perturbation::parse(&p.to_string()).unwrap(), p);
        assert_eq!(Perturbation::default().to_string(), "none");
        for (bad, want) in [
            ("", "empty"),
            ("blur", "expected key=value"),
            ("wobble=1", "unknown perturbation \"wobble\""),
            ("blur=1,blur=2", "given twice"),
            ("blur=-1", "sigma in 0..=8"),
            ("blur=nan", "sigma in 0..=8"),
            ("tiny=0", "0.1..=1"),
            ("tiny=1.5", "0.1..=1"),
            ("shake=2.5", "whole pixels"),
            ("shake=100", "whole pixels"),
            ("zoom=0.5", "1..=3"),
            ("period=1", "4..=100000"),
            ("seed=-1", "unsigned"),
            ("lookalike=1", "1.5..=8"),
        ] {
            let e = Perturbation::parse(bad).unwrap_err().to_string();
            assert!(e.contains(want), "{bad:?}: {e}");
        }
        let e = Perturbation::default()
            .for_sequence("x")
            .apply_frame(0, vec![0; 10], 4, 4)
            .unwrap_err();
        assert!(e.to_string().contains("10 bytes for 4x4"), "{e}");
    }
}
