//! Borrowed frames and the anti-aliased, border-replicating patch sampler.
//!
//! [`Frame`] is a zero-copy view of a camera buffer (so the ROS node can hand over
//! message data directly). [`Sampler`] crops a square region around a point, at any
//! scale, into a fixed-size planar `f32` [`Patch`]: large downscales are first
//! box-averaged by an integer factor (anti-aliasing), then resampled bilinearly.
//! Pixels outside the frame replicate the nearest border pixel.

use crate::error::TrackError;
use crate::geometry::Point2;
use serde::{Deserialize, Serialize};

/// Pixel layout of a [`Frame`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PixelFormat {
    /// 8-bit red, green, blue, interleaved.
    Rgb8,
    /// 8-bit blue, green, red, interleaved.
    Bgr8,
    /// 8-bit red, green, blue, alpha.
    Rgba8,
    /// 8-bit blue, green, red, alpha.
    Bgra8,
    /// 8-bit grey.
    Mono8,
}

impl PixelFormat {
    /// Bytes per pixel.
    pub const fn bytes_per_pixel(self) -> usize {
        match self {
            PixelFormat::Rgb8 | PixelFormat::Bgr8 => 3,
            PixelFormat::Rgba8 | PixelFormat::Bgra8 => 4,
            PixelFormat::Mono8 => 1,
        }
    }

    /// Byte offsets of red, green and blue within a pixel (all 0 for grey).
    pub(crate) const fn rgb_offsets(self) -> [usize; 3] {
        match self {
            PixelFormat::Rgb8 | PixelFormat::Rgba8 => [0, 1, 2],
            PixelFormat::Bgr8 | PixelFormat::Bgra8 => [2, 1, 0],
            PixelFormat::Mono8 => [0, 0, 0],
        }
    }

    /// Number of colour planes a patch sampled from this format has (3 or 1).
    pub const fn planes(self) -> usize {
        match self {
            PixelFormat::Mono8 => 1,
            _ => 3,
        }
    }

    /// The ROS `sensor_msgs/Image` encoding name.
    pub const fn name(self) -> &'static str {
        match self {
            PixelFormat::Rgb8 => "rgb8",
            PixelFormat::Bgr8 => "bgr8",
            PixelFormat::Rgba8 => "rgba8",
            PixelFormat::Bgra8 => "bgra8",
            PixelFormat::Mono8 => "mono8",
        }
    }
}

/// Largest accepted frame side, pixels (guards against absurd sizes from untrusted headers).
pub const MAX_FRAME_SIDE: usize = 1 << 15;

/// A borrowed 8-bit image: `height` rows of `stride` bytes, `width` pixels each.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    data: &'a [u8],
    width: usize,
    height: usize,
    stride: usize,
    format: PixelFormat,
}

impl<'a> Frame<'a> {
    /// Wraps a buffer.
    ///
    /// # Errors
    /// [`TrackError::InvalidFrame`] when a side is zero or above [`MAX_FRAME_SIDE`], the
    /// stride is shorter than a row, or the buffer is shorter than `stride × (height − 1) + row`.
    pub fn new(
        data: &'a [u8],
        width: usize,
        height: usize,
        stride: usize,
        format: PixelFormat,
    ) -> Result<Self, TrackError> {
        if width == 0 || height == 0 {
            return Err(TrackError::InvalidFrame(format!(
                "empty frame {width}x{height}"
            )));
        }
        if width > MAX_FRAME_SIDE || height > MAX_FRAME_SIDE {
            return Err(TrackError::InvalidFrame(format!(
                "frame {width}x{height} exceeds the maximum side {MAX_FRAME_SIDE}"
            )));
        }
        let row = width * format.bytes_per_pixel();
        if stride < row {
            return Err(TrackError::InvalidFrame(format!(
                "stride {stride} is shorter than a row of {row} bytes"
            )));
        }
        let need = stride * (height - 1) + row;
        if data.len() < need {
            return Err(TrackError::InvalidFrame(format!(
                "buffer has {} bytes, {width}x{height} {} with stride {stride} needs {need}",
                data.len(),
                format.name()
            )));
        }
        Ok(Self {
            data,
            width,
            height,
            stride,
            format,
        })
    }

    /// A tightly packed frame (`stride = width × bytes per pixel`).
    ///
    /// # Errors
    /// As [`Frame::new`].
    pub fn packed(
        data: &'a [u8],
        width: usize,
        height: usize,
        format: PixelFormat,
    ) -> Result<Self, TrackError> {
        Self::new(
            data,
            width,
            height,
            width * format.bytes_per_pixel(),
            format,
        )
    }

    /// Width, pixels.
    pub fn width(&self) -> usize {
        self.width
    }
    /// Height, pixels.
    pub fn height(&self) -> usize {
        self.height
    }
    /// Pixel format.
    pub fn format(&self) -> PixelFormat {
        self.format
    }
    /// Row stride, bytes.
    pub fn stride(&self) -> usize {
        self.stride
    }
    /// The raw bytes.
    pub fn data(&self) -> &'a [u8] {
        self.data
    }
    /// `WxH format`, for messages.
    pub fn describe(&self) -> String {
        format!("{}x{} {}", self.width, self.height, self.format.name())
    }
}

/// A planar `f32` image (values 0..255), `planes × side × side`.
#[derive(Debug, Clone, Default)]
pub struct Patch {
    /// Side length, pixels.
    pub side: usize,
    /// Number of colour planes (3 = RGB, 1 = grey).
    pub planes: usize,
    /// Plane-major data: `data[(p * side + r) * side + c]`.
    pub data: Vec<f32>,
    /// Sampling scratch: per output column and row, the resampling taps.
    cols: Vec<Taps>,
    rows: Vec<Taps>,
    tmp: Vec<f32>,
    /// [`sample_bilinear`]'s per output column: the byte offsets of its two taps in a row.
    col_bytes: Vec<[usize; 2]>,
    /// [`sample_bilinear`]'s per output column: its two taps' weights (0 for a missing second).
    col_w: Vec<[f32; 2]>,
}

impl Patch {
    /// A zeroed patch.
    pub fn new(side: usize, planes: usize) -> Self {
        Self {
            side,
            planes,
            data: vec![0.0; side * side * planes],
            cols: Vec::with_capacity(side),
            rows: Vec::with_capacity(side),
            tmp: Vec::new(),
            col_bytes: Vec::new(),
            col_w: Vec::new(),
        }
    }

    /// One colour plane.
    pub fn plane(&self, p: usize) -> &[f32] {
        let n = self.side * self.side;
        &self.data[p * n..(p + 1) * n]
    }
}

/// Crops and resizes square regions of a frame; owns its scratch buffers.
///
/// Use [`Sampler::prepare`] once per frame and region of interest, then [`Sampler::sample`]
/// for each scale inside it.
#[derive(Debug, Default, Clone)]
pub struct Sampler {
    /// Box-averaged copy of the region, plane-major.
    inter: Vec<f32>,
    inter_w: usize,
    inter_h: usize,
    planes: usize,
    /// Integer box-averaging factor of `inter`.
    factor: usize,
    /// Frame coordinate (pixel edge) of `inter`'s top-left corner.
    ox: f32,
    oy: f32,
    /// Integer row sums of one output row, interleaved as the frame's bytes.
    acc16: Vec<u16>,
    acc32: Vec<u32>,
    /// Per region column, the byte offset of its pixel in the row sums.
    col_src: Vec<usize>,
    /// Integer box sums of one output row, plane-major.
    col_sum: Vec<u32>,
    /// Sums of `factor` consecutive pixels' row sums at every byte of the span
    /// ([`column_sums_boxed`]).
    boxed: Vec<u16>,
}

impl Sampler {
    /// Prepares a region: a square of side `max_region` pixels around `center`, to be sampled
    /// into patches of side about `out_side` (so regions down to `min_region` are anti-aliased
    /// correctly).
    pub fn prepare(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        min_region: f32,
        max_region: f32,
        out_side: usize,
    ) {
        prepare_into(self, frame, center, min_region, max_region, out_side);
    }

    /// Samples a square of side `region` frame pixels centred on `center` (which must lie in
    /// the prepared region) into `out` (side `out.side`).
    ///
    /// Downscaling averages each output pixel's footprint (area resampling, so every scale
    /// is low-pass filtered alike and none aliases more than another); upscaling is
    /// bilinear.
    pub fn sample(&self, center: Point2, region: f32, out: &mut Patch) {
        self.sample_rect(center, region, region, out);
    }

    /// As [`Self::sample`] for a `region_w × region_h` rectangle, stretched onto the square
    /// patch (prepare with the shorter side as `min_region`; aspect ratios up to
    /// [`MAX_SAMPLE_ASPECT`] are resampled exactly, longer footprints lose their far taps).
    pub fn sample_rect(&self, center: Point2, region_w: f32, region_h: f32, out: &mut Patch) {
        sample_rect_into(self, center, region_w, region_h, out);
    }
}

/// [`Sampler::prepare`]'s work (compiled for the baseline and with AVX2 + FMA).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
fn prepare_into(
    sampler: &mut Sampler,
    frame: &Frame<'_>,
    center: Point2,
    min_region: f32,
    max_region: f32,
    out_side: usize,
) {
    let ratio = min_region / out_side.max(1) as f32;
    let factor = if ratio >= 2.0 {
        ratio.floor() as usize
    } else {
        1
    };
    let f = factor as f32;
    let half = max_region / 2.0 + 2.0 * f;
    let x0 = ((center.x - half) / f).floor() * f;
    let y0 = ((center.y - half) / f).floor() * f;
    let w = (((center.x + half) - x0) / f).ceil().max(1.0) as usize;
    let h = (((center.y + half) - y0) / f).ceil().max(1.0) as usize;
    let planes = frame.format().planes();
    sampler.factor = factor;
    sampler.ox = x0;
    sampler.oy = y0;
    sampler.inter_w = w;
    sampler.inter_h = h;
    sampler.planes = planes;
    sampler.inter.resize(w * h * planes, 0.0);

    let bpp = frame.format().bytes_per_pixel();
    let offs = frame.format().rgb_offsets();
    let fw = frame.width() as isize;
    let fh = frame.height() as isize;
    let data = frame.data();
    let stride = frame.stride();
    let sx0 = x0 as isize;
    let sy0 = y0 as isize;
    let inv = 1.0 / (f * f);
    // Region columns `0..wide`: those left of the frame replicate column 0, those right
    // of it column `fw − 1`, the span `left..right` is read in place, sequentially.
    // When the span is empty, `first_x` is the replicated column its.
    let wide = w * factor;
    let left = (-sx0).clamp(0, wide as isize) as usize;
    let right = (fw - sx0).clamp(left as isize, wide as isize) as usize;
    let first_x = (sx0 + left as isize).clamp(0, fw - 1) as usize;
    let nspan = (right - left).max(1);
    let bytes = nspan * bpp;
    // Byte offset in the span of each region column's pixel.
    sampler.col_src.clear();
    sampler.col_src.extend((0..wide).map(|x| {
        let i = if x < left {
            0
        } else if x >= right {
            nspan - 1
        } else {
            x - left
        };
        i * bpp
    }));
    // The `factor` rows of one output row are summed as exact integers, interleaved as
    // in the frame (one widening add per byte), in u16 batches of at most
    // `U16_ROWS` rows; integer sums below 2^24 are what the f32 sums were.
    const U16_ROWS: usize = 256;
    let batched = factor > U16_ROWS;
    sampler.acc16.resize(bytes, 0);
    sampler.acc32.resize(if batched { bytes } else { 0 }, 0);
    sampler.col_sum.resize(w * planes, 0);
    // An output row whose `factor` source rows all clamp to the same frame row (above or
    // below the frame) equals the previous such row: copied instead of summed again.
    let mut prev_clamped: Option<usize> = None;
    let small_sums = (factor as u64 * factor as u64 * 255) < (1u64 << 31);
    for r in 0..h {
        let first = sy0 + (r * factor) as isize;
        let last = first + factor as isize - 1;
        let clamped = if last <= 0 {
            Some(0)
        } else if first >= fh - 1 {
            Some((fh - 1) as usize)
        } else {
            None
        };
        if clamped.is_some() && clamped == prev_clamped {
            for p in 0..planes {
                let start = (p * h + r - 1) * w;
                sampler.inter.copy_within(start..start + w, start + w);
            }
            continue;
        }
        prev_clamped = clamped;
        if factor == 1 {
            // Single pixels, read from the frame row itself (no row sums to build).
            let sy = first.clamp(0, fh - 1) as usize;
            let start = sy * stride + first_x * bpp;
            pixels_row(
                &data[start..start + bytes],
                &sampler.col_src,
                bpp,
                offs,
                (left, right),
                &mut sampler.inter,
                (r, w, h, planes),
            );
            continue;
        }
        sampler.acc32.iter_mut().for_each(|v| *v = 0);
        for k in 0..factor {
            if batched && k > 0 && k % U16_ROWS == 0 {
                flush(&mut sampler.acc16, &mut sampler.acc32);
            }
            let sy = (sy0 + (r * factor + k) as isize).clamp(0, fh - 1) as usize;
            let start = sy * stride + first_x * bpp;
            let src = &data[start..start + bytes];
            if k == 0 {
                // The first row initialises the sums (no separate clearing pass).
                for (a, &b) in sampler.acc16.iter_mut().zip(src) {
                    *a = u16::from(b);
                }
            } else {
                for (a, &b) in sampler.acc16.iter_mut().zip(src) {
                    *a += u16::from(b);
                }
            }
        }
        if batched {
            flush(&mut sampler.acc16, &mut sampler.acc32);
            column_sums(
                &sampler.acc32,
                &sampler.col_src,
                bpp,
                offs,
                factor,
                &mut sampler.col_sum,
            );
        } else if factor <= BOXED_MAX_FACTOR {
            column_sums_boxed(
                &sampler.acc16,
                &mut sampler.boxed,
                &sampler.col_src,
                bpp,
                offs,
                factor,
                (left, right),
                &mut sampler.col_sum,
            );
        } else {
            column_sums(
                &sampler.acc16,
                &sampler.col_src,
                bpp,
                offs,
                factor,
                &mut sampler.col_sum,
            );
        }
        for p in 0..planes {
            let out = &mut sampler.inter[(p * h + r) * w..(p * h + r + 1) * w];
            let sums = &sampler.col_sum[p * w..(p + 1) * w];
            if small_sums {
                // Sums below 2^31 convert through i32 alike, and that conversion
                // vectorises (u32 → f32 has no baseline x86-64 instruction).
                for (o, &s) in out.iter_mut().zip(sums) {
                    *o = s as i32 as f32 * inv;
                }
            } else {
                for (o, &s) in out.iter_mut().zip(sums) {
                    *o = s as f32 * inv;
                }
            }
        }
    }
}

/// [`Sampler::sample_rect`]'s work (compiled for the baseline and with AVX2 + FMA).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
fn sample_rect_into(
    sampler: &Sampler,
    center: Point2,
    region_w: f32,
    region_h: f32,
    out: &mut Patch,
) {
    let side = out.side;
    out.planes = sampler.planes;
    out.data.resize(side * side * sampler.planes, 0.0);
    let f = sampler.factor as f32;
    let (kx, ky) = (region_w / side as f32, region_h / side as f32);
    let (w, h) = (sampler.inter_w, sampler.inter_h);
    // Output pixel j's centre in frame edge coordinates: center + (j + 0.5 − side/2)·k;
    // in intermediate pixel-centre coordinates: (X − origin)/f − 0.5. Footprint width k/f.
    let map = |c: f32, o: f32, j: usize, k: f32| {
        (c + (j as f32 + 0.5 - side as f32 / 2.0) * k - o) / f - 0.5
    };
    out.cols.clear();
    for j in 0..side {
        out.cols
            .push(Taps::new(map(center.x, sampler.ox, j, kx), kx / f, w));
    }
    out.rows.clear();
    for r in 0..side {
        out.rows
            .push(Taps::new(map(center.y, sampler.oy, r, ky), ky / f, h));
    }
    let cmin = out.cols.iter().map(|t| t.start).min().unwrap_or(0);
    let cmax = out
        .cols
        .iter()
        .map(|t| t.start + t.len)
        .max()
        .unwrap_or(0)
        .min(w);
    // The horizontal pass reads every column's taps as `taps` of them (the widest
    // footprint's count), those past a column's own with weight 0 on values of `tmp`'s slack
    // or of other columns: `x + 0·y` is `x`'s bits, as every value and weight here is finite
    // and at least +0 (pixel bytes, area and bilinear weights). A fixed count lets the
    // compiler unroll the sum instead of looping per output pixel.
    // `tmp` starts as zeros: a padded tap past the current row's range reads +0.
    let taps = out.cols.iter().map(|t| t.len).max().unwrap_or(1);
    // One blended row per plane, each with `MAX_TAPS` values of slack.
    let planes = sampler.planes;
    let stride = w + MAX_TAPS;
    out.tmp.clear();
    out.tmp.resize(planes * stride, 0.0);
    let n = side * side;
    for (r, rt) in out.rows.iter().enumerate() {
        // Vertical pass into each plane's row, then the horizontal pass.
        for p in 0..planes {
            let src = &sampler.inter[p * w * h..(p + 1) * w * h];
            let tmp = &mut out.tmp[p * stride + cmin..p * stride + cmax];
            let src = &src[rt.start * w + cmin..];
            match rt.len {
                0 => tmp.iter_mut().for_each(|v| *v = 0.0),
                1 => rows::<1>(tmp, src, w, &rt.w),
                2 => rows::<2>(tmp, src, w, &rt.w),
                3 => rows::<3>(tmp, src, w, &rt.w),
                4 => rows::<4>(tmp, src, w, &rt.w),
                5 => rows::<5>(tmp, src, w, &rt.w),
                6 => rows::<6>(tmp, src, w, &rt.w),
                7 => rows::<7>(tmp, src, w, &rt.w),
                _ => rows::<MAX_TAPS>(tmp, src, w, &rt.w),
            }
        }
        if planes == 3 {
            // The three planes in one pass over the columns (each column's taps read once).
            let (d0, rest) = out.data.split_at_mut(n);
            let (d1, d2) = rest.split_at_mut(n);
            let row = r * side..(r + 1) * side;
            let o = [&mut d0[row.clone()], &mut d1[row.clone()], &mut d2[row]];
            let (t0, rest) = out.tmp.split_at(stride);
            let (t1, t2) = rest.split_at(stride);
            let t = [t0, t1, t2];
            match taps {
                0 => columns3::<0>(o, &out.cols, t),
                1 => columns3::<1>(o, &out.cols, t),
                2 => columns3::<2>(o, &out.cols, t),
                3 => columns3::<3>(o, &out.cols, t),
                4 => columns3::<4>(o, &out.cols, t),
                _ => columns3::<MAX_TAPS>(o, &out.cols, t),
            }
            continue;
        }
        for p in 0..planes {
            let o = &mut out.data[(p * side + r) * side..(p * side + r + 1) * side];
            let tmp = &out.tmp[p * stride..(p + 1) * stride];
            match taps {
                0 => columns::<0>(o, &out.cols, tmp),
                1 => columns::<1>(o, &out.cols, tmp),
                2 => columns::<2>(o, &out.cols, tmp),
                3 => columns::<3>(o, &out.cols, tmp),
                4 => columns::<4>(o, &out.cols, tmp),
                _ => columns::<MAX_TAPS>(o, &out.cols, tmp),
            }
        }
    }
}

/// `sample_rect`'s vertical pass over one plane's row: `tmp[c] = ((0 + w₀·row₀[c]) +
/// w₁·row₁[c]) …` over the `L` source rows starting at `src` (`w` values apart), summed in
/// tap order from +0 as one pass per tap into a zeroed row did, in a single pass over the
/// row (the same operations per value, so the same bits, without storing and reloading the
/// row per tap).
#[inline(always)] // into each clone of `sample_rect_into`
fn rows<const L: usize>(tmp: &mut [f32], src: &[f32], w: usize, wt: &[f32; MAX_TAPS]) {
    let n = tmp.len();
    let rows: [&[f32]; L] = std::array::from_fn(|t| &src[t * w..t * w + n]);
    for (c, a) in tmp.iter_mut().enumerate() {
        let mut s = 0.0f32;
        for t in 0..L {
            s += wt[t] * rows[t][c];
        }
        *a = s;
    }
}

/// [`columns`] for three planes at once: each column's taps are read once for the three
/// rows (the same sums, so the same bits).
#[inline(always)] // into each clone of `sample_rect_into`
fn columns3<const L: usize>(out: [&mut [f32]; 3], cols: &[Taps], tmp: [&[f32]; 3]) {
    let [o0, o1, o2] = out;
    let dst = o0.iter_mut().zip(o1.iter_mut()).zip(o2.iter_mut());
    for (((o0, o1), o2), ct) in dst.zip(cols) {
        let w = &ct.w[..L];
        let dot = |t: &[f32]| -> f32 {
            let src = &t[ct.start..ct.start + L];
            src.iter().zip(w).map(|(a, b)| a * b).sum()
        };
        *o0 = dot(tmp[0]);
        *o1 = dot(tmp[1]);
        *o2 = dot(tmp[2]);
    }
}

/// `sample_rect`'s horizontal pass over one row: output `j` is column `j`'s taps applied to
/// `tmp`, each column read as `L` taps (its own, then weight-0 ones; `tmp` has `MAX_TAPS`
/// values of slack past the region).
#[inline(always)] // into each clone of `sample_rect_into`
fn columns<const L: usize>(out: &mut [f32], cols: &[Taps], tmp: &[f32]) {
    for (o, ct) in out.iter_mut().zip(cols) {
        let src = &tmp[ct.start..ct.start + L];
        *o = src.iter().zip(&ct.w[..L]).map(|(a, b)| a * b).sum();
    }
}

/// Samples the square of side `region` frame pixels centred on `center` into `out` (side
/// `out.side`, the frame's planes) by bilinear interpolation of the four nearest pixels,
/// without low-pass filtering when downscaling, pixels outside the frame replicating the
/// border: OpenCV's `resize(INTER_LINEAR)` of the region, the resampling NanoTrack's networks
/// were trained on (pysot's `get_subwindow`) and OpenCV's TrackerNano feeds them. Reads four
/// pixels per output pixel whatever the region's size, where [`Sampler`] box-averages the
/// whole region first. Upscaling (`region ≤ out.side`) gives [`Sampler::sample`]'s bits (the
/// same coordinates, weights and order of operations).
pub fn sample_bilinear(frame: &Frame<'_>, center: Point2, region: f32, out: &mut Patch) {
    sample_bilinear_into(frame, center, region, out);
}

/// [`sample_bilinear`]'s work (compiled for the baseline and with AVX2 + FMA). Allocates
/// nothing once `out`'s scratch has grown: the column taps go to `out.cols` and their byte
/// offsets to `out.col_bytes`, the blended rows to `out.tmp`.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
fn sample_bilinear_into(frame: &Frame<'_>, center: Point2, region: f32, out: &mut Patch) {
    let side = out.side;
    let planes = frame.format().planes();
    out.planes = planes;
    out.data.resize(side * side * planes, 0.0);
    let k = region / side as f32;
    let bpp = frame.format().bytes_per_pixel();
    let offs = frame.format().rgb_offsets();
    // `prepare`'s region at box factor 1 (corner `o`, `n` pixels, those outside the frame
    // replicating its border) and `sample_rect`'s interpolating taps in it ([`Taps::new`]
    // with a footprint of one pixel), so enlarging crops get the sampler's bits.
    let half = region / 2.0 + 2.0;
    let corner = |c: f32| {
        let o = (c - half).floor();
        let n = ((c + half) - o).ceil().max(1.0);
        // A region far beyond any frame is clamped to it anyway.
        let n = if n.is_finite() {
            n.min(MAX_REGION_PX)
        } else {
            1.0
        };
        (o, n as usize)
    };
    let tap = |c: f32, (o, n): (f32, usize), j: usize| {
        let u = (c + (j as f32 + 0.5 - side as f32 / 2.0) * k - o) / 1.0 - 0.5;
        Taps::new(if u.is_finite() { u } else { 0.0 }, 1.0, n)
    };
    // Frame pixel of tap `t` (clamped: the region's replicated border).
    let pixel = |t: &Taps, i: usize, o: f32, len: usize| {
        let x = (t.start + i.min(t.len.saturating_sub(1))) as f32 + o;
        if x.is_finite() {
            x.clamp(0.0, (len - 1) as f32) as usize
        } else {
            0
        }
    };
    let (fw, fh) = (frame.width(), frame.height());
    let (cx, cy) = (corner(center.x), corner(center.y));
    out.cols.clear();
    out.cols.extend((0..side).map(|j| tap(center.x, cx, j)));
    // The columns grow with j: one output row reads the frame bytes of `first..=last`.
    let first = out.cols.first().map_or(0, |t| pixel(t, 0, cx.0, fw));
    let last = out.cols.last().map_or(0, |t| pixel(t, 1, cx.0, fw));
    let span = first * bpp..(last + 1) * bpp;
    out.col_bytes.clear();
    out.col_bytes.extend(
        out.cols
            .iter()
            .map(|t| [0, 1].map(|i| (pixel(t, i, cx.0, fw) - first) * bpp)),
    );
    // A column with one tap gets a second of weight 0: `w₀·a + 0·b` is `w₀·a`'s bits, as
    // every blended value is finite and at least +0 (bytes, non-negative weights), so the
    // row loop has no branch per pixel.
    out.col_w.clear();
    out.col_w.extend(
        out.cols
            .iter()
            .map(|t| [t.w[0], if t.len > 1 { t.w[1] } else { 0.0 }]),
    );
    out.tmp.clear();
    out.tmp.resize(span.len(), 0.0);
    let data = frame.data();
    let stride = frame.stride();
    let n = side * side;
    for r in 0..side {
        // Vertical pass over the span's bytes (all planes interleaved), then the horizontal,
        // each as `sample_rect` sums its taps: `w₀·a` or `w₀·a + w₁·b`.
        let rt = tap(center.y, cy, r);
        let row = |i: usize| {
            let y = pixel(&rt, i, cy.0, fh);
            &data[y * stride + span.start..y * stride + span.end]
        };
        let (row0, row1, w0, w1) = (row(0), row(1), rt.w[0], rt.w[1]);
        if rt.len > 1 {
            for ((v, &a), &b) in out.tmp.iter_mut().zip(row0).zip(row1) {
                *v = w0 * f32::from(a) + w1 * f32::from(b);
            }
        } else {
            for (v, &a) in out.tmp.iter_mut().zip(row0) {
                *v = w0 * f32::from(a);
            }
        }
        let taps = out.col_w.iter().zip(&out.col_bytes);
        if planes == 3 && bpp >= 3 {
            // The three planes in one pass over the columns: each column's taps read once,
            // its two pixels' bytes as two short runs of the blended row.
            let [o0, o1, o2] = offs.map(|o| o.min(2));
            let (d0, rest) = out.data.split_at_mut(n);
            let (d1, d2) = rest.split_at_mut(n);
            let row = r * side..(r + 1) * side;
            let (d0, d1, d2) = (&mut d0[row.clone()], &mut d1[row.clone()], &mut d2[row]);
            let dst = d0.iter_mut().zip(d1.iter_mut()).zip(d2.iter_mut());
            for (((d0, d1), d2), (&[w0, w1], &[b0, b1])) in dst.zip(taps) {
                let (a, b) = (&out.tmp[b0..b0 + 3], &out.tmp[b1..b1 + 3]);
                *d0 = w0 * a[o0] + w1 * b[o0];
                *d1 = w0 * a[o1] + w1 * b[o1];
                *d2 = w0 * a[o2] + w1 * b[o2];
            }
            continue;
        }
        for p in 0..planes {
            let o = offs[p];
            let dst = &mut out.data[p * n + r * side..p * n + (r + 1) * side];
            let tmp = &out.tmp[o..];
            for (d, (&[w0, w1], &[b0, b1])) in dst.iter_mut().zip(taps.clone()) {
                *d = w0 * tmp[b0] + w1 * tmp[b1];
            }
        }
    }
}

/// Largest region side [`sample_bilinear`] lays out, pixels: four times the largest frame
/// side, so a hostile region is clamped to the frame, never sized by itself.
const MAX_REGION_PX: f32 = (4 * MAX_FRAME_SIDE) as f32;

/// Adds a u16 row-sum batch into the u32 sums and clears it.
#[inline(always)] // into each clone of `prepare_into`
fn flush(acc16: &mut [u16], acc32: &mut [u32]) {
    for (a, b) in acc32.iter_mut().zip(acc16.iter_mut()) {
        *a += u32::from(*b);
        *b = 0;
    }
}

/// The box sums of one output row for every plane, plane-major into `sums` (`planes × w`):
/// output column `j` of plane `p` sums the row sums of region columns
/// `j·factor..(j+1)·factor` (byte offsets `col_src`, plus the plane's offset `offs[p]`).
/// Exact integer sums, so the order of the additions does not matter.
#[inline(always)]
fn column_sums<T: Copy + Into<u32>>(
    acc: &[T],
    col_src: &[usize],
    bpp: usize,
    offs: [usize; 3],
    factor: usize,
    sums: &mut [u32],
) {
    let planes = if bpp == 1 { 1 } else { 3 };
    let w = sums.len() / planes;
    match bpp {
        3 => column_sums_px::<T, 3>(acc, col_src, offs, factor, w, sums),
        4 => column_sums_px::<T, 4>(acc, col_src, offs, factor, w, sums),
        _ => {
            for (p, &off) in offs.iter().enumerate().take(planes) {
                for (o, cols) in sums[p * w..(p + 1) * w]
                    .iter_mut()
                    .zip(col_src.chunks_exact(factor))
                {
                    *o = cols.iter().map(|&c| acc[c + off].into()).sum();
                }
            }
        }
    }
}

/// Row `r` of a region prepared at factor 1 (`inter` plane-major, `w × h` per plane) from
/// the frame row's span `src`: the region columns inside the frame (`left..right`, span
/// pixels `0..right − left`) converted in one pass over the span's pixels, three planes at
/// a time for 3-byte pixels; the columns replicating the frame's border through `col_src`.
/// Each value is its byte as `f32`, as the per-column gather gave.
#[inline(always)]
fn pixels_row(
    src: &[u8],
    col_src: &[usize],
    bpp: usize,
    offs: [usize; 3],
    (left, right): (usize, usize),
    inter: &mut [f32],
    (r, w, h, planes): (usize, usize, usize, usize),
) {
    let offs = offs.map(|o| o.min(bpp - 1));
    for (p, &off) in offs.iter().enumerate().take(planes) {
        let out = &mut inter[(p * h + r) * w..(p * h + r + 1) * w];
        for x in (0..left).chain(right..w) {
            out[x] = f32::from(src[col_src[x] + off]);
        }
    }
    if right <= left {
        return;
    }
    let span = &src[..(right - left) * bpp];
    if planes == 3 && bpp == 3 {
        let (a, rest) = inter.split_at_mut(h * w);
        let (b, c) = rest.split_at_mut(h * w);
        let row = r * w + left..r * w + right;
        let (a, b, c) = (&mut a[row.clone()], &mut b[row.clone()], &mut c[row]);
        let [o0, o1, o2] = offs;
        let dst = a.iter_mut().zip(b.iter_mut()).zip(c.iter_mut());
        for (((a, b), c), px) in dst.zip(span.chunks_exact(3)) {
            *a = f32::from(px[o0]);
            *b = f32::from(px[o1]);
            *c = f32::from(px[o2]);
        }
        return;
    }
    for (p, &off) in offs.iter().enumerate().take(planes) {
        let out = &mut inter[(p * h + r) * w + left..(p * h + r) * w + right];
        for (o, px) in out.iter_mut().zip(span.chunks_exact(bpp)) {
            *o = f32::from(px[off]);
        }
    }
}

/// Largest box factor [`column_sums_boxed`] takes: its sums of `factor` row sums of
/// `factor` bytes each stay below 2^16 (`16² · 255 = 65,280`).
const BOXED_MAX_FACTOR: usize = 16;

/// [`column_sums`] of `u16` row sums for `factor ≤ BOXED_MAX_FACTOR`, the same values.
/// Output columns whose pixels all lie in the frame (`j·factor ≥ left`, `(j+1)·factor ≤
/// right`: consecutive pixels of the span) read one value each of `boxed`, the sums of
/// `factor` consecutive pixels' row sums at every byte of the span, built in `factor` passes
/// over the row that vectorise (where each output column took `factor · bpp` scalar adds,
/// most of the region's preparation for large targets); the columns that replicate the
/// frame's border are summed one by one. Exact integer sums, so the order of the additions
/// does not matter.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn column_sums_boxed(
    acc: &[u16],
    boxed: &mut Vec<u16>,
    col_src: &[usize],
    bpp: usize,
    offs: [usize; 3],
    factor: usize,
    (left, right): (usize, usize),
    sums: &mut [u32],
) {
    debug_assert!((2..=BOXED_MAX_FACTOR).contains(&factor));
    let planes = if bpp == 1 { 1 } else { 3 };
    let w = sums.len() / planes;
    let offs = offs.map(|o| o.min(bpp - 1));
    let j0 = left.div_ceil(factor).min(w);
    let j1 = (right / factor).clamp(j0, w);
    for j in (0..j0).chain(j1..w) {
        let cols = &col_src[j * factor..(j + 1) * factor];
        for (p, &off) in offs.iter().enumerate().take(planes) {
            sums[p * w + j] = cols.iter().map(|&c| u32::from(acc[c + off])).sum();
        }
    }
    if j1 == j0 {
        return;
    }
    // Output column j's first pixel is span pixel `j·factor − left`.
    let start = (j0 * factor - left) * bpp;
    let step = factor * bpp;
    let n = (j1 - j0) * step - (factor - 1) * bpp;
    boxed.clear();
    boxed.extend_from_slice(&acc[start..start + n]);
    for t in 1..factor {
        let src = &acc[start + t * bpp..start + t * bpp + n];
        for (b, &a) in boxed.iter_mut().zip(src) {
            *b += a;
        }
    }
    for (p, &off) in offs.iter().enumerate().take(planes) {
        let dst = &mut sums[p * w + j0..p * w + j1];
        for (d, &v) in dst.iter_mut().zip(boxed[off..].iter().step_by(step)) {
            *d = u32::from(v);
        }
    }
}

/// [`column_sums`] for `B` interleaved bytes per pixel: each output column's pixels are read
/// once for all planes, contiguously when they lie inside the frame.
#[inline(always)]
fn column_sums_px<T: Copy + Into<u32>, const B: usize>(
    acc: &[T],
    col_src: &[usize],
    offs: [usize; 3],
    factor: usize,
    w: usize,
    sums: &mut [u32],
) {
    let (s0, rest) = sums.split_at_mut(w);
    let (s1, s2) = rest.split_at_mut(w);
    // Each plane's byte within a pixel (`rgb_offsets` are below 3): in range by
    // construction, so neither the reads below nor the zipped stores check bounds.
    let [o0, o1, o2] = offs.map(|o| o.min(B - 1));
    let dst = s0.iter_mut().zip(s1.iter_mut()).zip(s2.iter_mut());
    for (cols, ((d0, d1), d2)) in col_src.chunks_exact(factor).zip(dst) {
        let mut s = [0u32; B];
        let (a, b) = (cols[0], cols[factor - 1]);
        if b == a + (factor - 1) * B {
            // Consecutive pixels of the frame row (offsets grow by B inside the span).
            for px in acc[a..b + B].chunks_exact(B) {
                for (si, &v) in s.iter_mut().zip(px) {
                    *si += v.into();
                }
            }
        } else {
            for &c in cols {
                for (si, &v) in s.iter_mut().zip(&acc[c..c + B]) {
                    *si += v.into();
                }
            }
        }
        (*d0, *d1, *d2) = (s[o0], s[o1], s[o2]);
    }
}

/// Most source pixels one output pixel reads along one axis.
const MAX_TAPS: usize = 8;
/// Largest aspect ratio [`Sampler::sample_rect`] resamples exactly (footprints of up to
/// `2·MAX_SAMPLE_ASPECT` source pixels plus one partial tap fit in the 8 taps per axis).
pub const MAX_SAMPLE_ASPECT: f32 = 3.0;

/// Resampling weights of one output pixel along one axis.
#[derive(Debug, Clone, Copy)]
struct Taps {
    start: usize,
    len: usize,
    w: [f32; MAX_TAPS],
}

impl Taps {
    /// Weights for an output pixel centred at source coordinate `u` (pixel centres at
    /// integers) with footprint `width` source pixels, over `n` source pixels; indices
    /// outside `0..n` replicate the border.
    #[inline(always)] // into the samplers' clones (their `floor`s compile to one instruction there)
    fn new(u: f32, width: f32, n: usize) -> Self {
        let mut t = Taps {
            start: 0,
            len: 0,
            w: [0.0; MAX_TAPS],
        };
        let last = n.saturating_sub(1) as isize;
        // Indices arrive in increasing order, so clamped ones fold onto the first/last tap.
        let push = |i: isize, wt: f32, t: &mut Taps| {
            let i = i.clamp(0, last) as usize;
            if t.len == 0 {
                t.start = i;
            }
            let slot = i - t.start;
            if slot < MAX_TAPS {
                t.w[slot] += wt;
                t.len = t.len.max(slot + 1);
            }
        };
        if width <= 1.0 {
            let u = u.clamp(0.0, last as f32);
            let i0 = u.floor();
            let a = u - i0;
            push(i0 as isize, 1.0 - a, &mut t);
            push(i0 as isize + 1, a, &mut t);
        } else {
            let (lo, hi) = (u - width / 2.0, u + width / 2.0);
            let inv = 1.0 / width;
            let first = (lo + 0.5).floor() as isize;
            let last_i = (hi + 0.5).ceil() as isize - 1;
            for i in first..=last_i {
                let a = (i as f32 - 0.5).max(lo);
                let b = (i as f32 + 0.5).min(hi);
                if b > a {
                    push(i, (b - a) * inv, &mut t);
                }
            }
        }
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize) -> Vec<u8> {
        (0..h)
            .flat_map(|r| (0..w).map(move |c| ((r * 3 + c) % 256) as u8))
            .collect()
    }

    #[test]
    fn frame_rejects_short_buffers_and_bad_strides() {
        let d = vec![0u8; 10];
        assert!(Frame::new(&d, 4, 4, 4, PixelFormat::Mono8).is_err());
        assert!(Frame::new(&d, 4, 2, 3, PixelFormat::Mono8).is_err());
        assert!(Frame::new(&d, 0, 2, 3, PixelFormat::Mono8).is_err());
        assert!(Frame::new(&d, 4, 2, 5, PixelFormat::Mono8).is_ok());
    }

    #[test]
    fn identity_sampling_reproduces_pixels() {
        let (w, h) = (32, 24);
        let d = ramp(w, h);
        let f = Frame::packed(&d, w, h, PixelFormat::Mono8).unwrap();
        let mut s = Sampler::default();
        let c = Point2 { x: 16.0, y: 12.0 };
        s.prepare(&f, c, 16.0, 16.0, 16);
        let mut p = Patch::new(16, 1);
        s.sample(c, 16.0, &mut p);
        for r in 0..16 {
            for col in 0..16 {
                let want = d[(r + 4) * w + col + 8] as f32;
                assert!((p.data[r * 16 + col] - want).abs() < 1e-3, "{r} {col}");
            }
        }
    }

    #[test]
    fn bilinear_sampling_is_opencv_inter_linear_of_the_region() {
        let (w, h) = (40, 30);
        let d = ramp(w, h);
        let f = Frame::packed(&d, w, h, PixelFormat::Mono8).unwrap();
        let px = |x: usize, y: usize| f32::from(d[y * w + x]);
        // The identity: a region of the output's side on pixel edges gives the pixels.
        let mut p = Patch::new(16, 1);
        let c = Point2 { x: 16.0, y: 12.0 };
        sample_bilinear(&f, c, 16.0, &mut p);
        for r in 0..16 {
            for col in 0..16 {
                assert_eq!(p.data[r * 16 + col], px(col + 8, r + 4), "{r} {col}");
            }
        }
        // Halving: output pixel j sits on source coordinate 2j + 0.5 (OpenCV's
        // (j + 0.5)·2 − 0.5), the mean of two neighbours per axis, no wider footprint.
        let mut p = Patch::new(8, 1);
        sample_bilinear(&f, c, 16.0, &mut p);
        for r in 0..8 {
            for col in 0..8 {
                let (x, y) = (8 + 2 * col, 4 + 2 * r);
                let want = (px(x, y) + px(x + 1, y) + px(x, y + 1) + px(x + 1, y + 1)) / 4.0;
                assert!((p.data[r * 8 + col] - want).abs() < 1e-4, "{r} {col}");
            }
        }
    }

    #[test]
    fn bilinear_upscaling_gives_the_samplers_bits() {
        // Where the sampler interpolates too (a region at most the patch's side), the two give
        // the same values, bit for bit, inside the frame and across its borders.
        let (w, h) = (64, 48);
        let rgb: Vec<u8> = (0..w * h * 3).map(|i| ((i * 7919) % 251) as u8).collect();
        let f = Frame::packed(&rgb, w, h, PixelFormat::Rgb8).unwrap();
        let mut seed = 11u32;
        let mut next = |lo: f32, hi: f32| {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            lo + (hi - lo) * (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        for _ in 0..200 {
            let side = 31 + (next(0.0, 40.0) as usize);
            let region = next(2.0, side as f32);
            let c = Point2 {
                x: next(-20.0, 84.0),
                y: next(-20.0, 68.0),
            };
            let mut s = Sampler::default();
            s.prepare(&f, c, region, region, side);
            let (mut a, mut b) = (Patch::new(side, 3), Patch::new(side, 3));
            s.sample(c, region, &mut a);
            sample_bilinear(&f, c, region, &mut b);
            let bits = |p: &Patch| p.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a), bits(&b), "{c:?} region {region} side {side}");
        }
    }

    #[test]
    fn bilinear_sampling_replicates_the_border_orders_planes_and_survives_hostile_input() {
        let (w, h) = (8, 6);
        let mut bgr = vec![0u8; w * h * 3];
        for (i, px) in bgr.chunks_exact_mut(3).enumerate() {
            px.copy_from_slice(&[10, (i % 200) as u8, 250]);
        }
        let f = Frame::packed(&bgr, w, h, PixelFormat::Bgr8).unwrap();
        let mut p = Patch::new(4, 3);
        // Far outside the top-left corner: every sample is pixel (0, 0), as RGB planes.
        sample_bilinear(&f, Point2 { x: -50.0, y: -50.0 }, 4.0, &mut p);
        assert!(p.plane(0).iter().all(|&v| v == 250.0));
        assert!(p.plane(1).iter().all(|&v| v == 0.0));
        assert!(p.plane(2).iter().all(|&v| v == 10.0));
        // Non-finite centres and absurd regions sample inside the frame, without a panic.
        for (c, region) in [
            (
                Point2 {
                    x: f32::NAN,
                    y: 3.0,
                },
                4.0,
            ),
            (
                Point2 {
                    x: 4.0,
                    y: f32::INFINITY,
                },
                4.0,
            ),
            (Point2 { x: 4.0, y: 3.0 }, 1e30),
            (Point2 { x: 4.0, y: 3.0 }, 0.0),
        ] {
            sample_bilinear(&f, c, region, &mut p);
            assert!(
                p.data.iter().all(|v| (0.0..=255.0).contains(v)),
                "{c:?} {region}"
            );
        }
    }

    #[test]
    fn outside_pixels_replicate_the_border() {
        let (w, h) = (8, 8);
        let d = ramp(w, h);
        let f = Frame::packed(&d, w, h, PixelFormat::Mono8).unwrap();
        let mut s = Sampler::default();
        let c = Point2 { x: -20.0, y: -20.0 };
        s.prepare(&f, c, 4.0, 4.0, 4);
        let mut p = Patch::new(4, 1);
        s.sample(c, 4.0, &mut p);
        assert!(p.data.iter().all(|&v| (v - d[0] as f32).abs() < 1e-4));
    }

    #[test]
    fn downscaling_averages_instead_of_aliasing() {
        // A 1-pixel checkerboard downscaled 4x must come out as flat mid-grey.
        let (w, h) = (64, 64);
        let d: Vec<u8> = (0..h * w)
            .map(|i| if (i / w + i % w) % 2 == 0 { 0 } else { 200 })
            .collect();
        let f = Frame::packed(&d, w, h, PixelFormat::Mono8).unwrap();
        let mut s = Sampler::default();
        let c = Point2 { x: 32.0, y: 32.0 };
        s.prepare(&f, c, 32.0, 32.0, 8);
        let mut p = Patch::new(8, 1);
        s.sample(c, 32.0, &mut p);
        for v in &p.data {
            assert!((v - 100.0).abs() < 30.0, "{v}");
        }
    }

    #[test]
    fn area_taps_sum_to_one_and_replicate_borders() {
        for (u, width) in [
            (5.3f32, 1.37f32),
            (0.2, 1.9),
            (-3.0, 1.5),
            (9.8, 2.08),
            (4.0, 0.7),
        ] {
            let t = Taps::new(u, width, 10);
            let s: f32 = t.w[..t.len].iter().sum();
            assert!((s - 1.0).abs() < 1e-5, "{u} {width}: {t:?}");
            assert!(t.start + t.len <= 10, "{t:?}");
        }
    }

    #[test]
    fn downscaling_by_a_fraction_preserves_the_mean() {
        let (w, h) = (64, 64);
        let d: Vec<u8> = (0..h * w).map(|i| ((i * 37) % 251) as u8).collect();
        let mean_in = d.iter().map(|&v| v as f32).sum::<f32>() / d.len() as f32;
        let f = Frame::packed(&d, w, h, PixelFormat::Mono8).unwrap();
        let mut s = Sampler::default();
        let c = Point2 { x: 32.0, y: 32.0 };
        s.prepare(&f, c, 64.0, 64.0, 47);
        let mut p = Patch::new(47, 1);
        s.sample(c, 64.0, &mut p);
        let mean_out = p.data.iter().sum::<f32>() / p.data.len() as f32;
        assert!((mean_in - mean_out).abs() < 2.0, "{mean_in} {mean_out}");
    }

    #[test]
    fn prepared_region_is_the_clamped_box_average_across_the_border() {
        // A region hanging over the top-left and right edges, factor 3, colour with alpha.
        let (w, h) = (20, 12);
        let d: Vec<u8> = (0..w * h * 4).map(|i| ((i * 29) % 253) as u8).collect();
        let f = Frame::packed(&d, w, h, PixelFormat::Bgra8).unwrap();
        let mut s = Sampler::default();
        let c = Point2 { x: 6.0, y: 2.0 };
        s.prepare(&f, c, 30.0, 36.0, 10);
        assert_eq!(s.factor, 3);
        let px = |x: isize, y: isize, p: usize| {
            let (x, y) = (x.clamp(0, w as isize - 1), y.clamp(0, h as isize - 1));
            d[(y as usize * w + x as usize) * 4 + [2, 1, 0][p]] as f32
        };
        for p in 0..3 {
            for r in 0..s.inter_h {
                for col in 0..s.inter_w {
                    let mut sum = 0.0;
                    for dy in 0..3 {
                        for dx in 0..3 {
                            let x = s.ox as isize + (col * 3 + dx) as isize;
                            let y = s.oy as isize + (r * 3 + dy) as isize;
                            sum += px(x, y, p);
                        }
                    }
                    let got = s.inter[(p * s.inter_h + r) * s.inter_w + col];
                    assert!((got - sum / 9.0).abs() < 1e-3, "{p} {r} {col}");
                }
            }
        }
    }

    /// `sample_rect`'s output against the resampling written out per pixel (each column's own
    /// taps only, summed as `Iterator::sum` does): the same bits, for footprints of 1 to 8
    /// taps per axis (aspect ratios to [`MAX_SAMPLE_ASPECT`], up- and downscaling, regions over
    /// the frame's edge), so the weight-0 taps the pass adds change nothing.
    #[test]
    fn rect_sampling_gives_the_per_pixel_resamplings_bits() {
        let (w, h) = (61, 47);
        let d: Vec<u8> = (0..w * h * 3)
            .map(|i| ((i * 197 + i / 5) % 256) as u8)
            .collect();
        let f = Frame::packed(&d, w, h, PixelFormat::Rgb8).unwrap();
        let mut widths = std::collections::BTreeSet::new();
        for (cx, cy, rw, rh, side) in [
            (30.0, 20.0, 40.0, 40.0, 16),
            (30.5, 23.2, 57.0, 19.0, 12),
            (3.0, 44.0, 21.0, 63.0, 9),
            (40.0, 10.0, 10.0, 7.0, 24),
            (58.0, 2.0, 90.0, 30.0, 10),
            (20.0, 30.0, 33.0, 11.0, 5),
        ] {
            let c = Point2 { x: cx, y: cy };
            let mut s = Sampler::default();
            s.prepare(&f, c, f32::min(rw, rh), f32::max(rw, rh), side);
            let mut out = Patch::new(side, 3);
            s.sample_rect(c, rw, rh, &mut out);
            widths.extend(out.cols.iter().map(|t| t.len));
            let (iw, ih) = (s.inter_w, s.inter_h);
            for p in 0..3 {
                let src = &s.inter[p * iw * ih..(p + 1) * iw * ih];
                for (r, rt) in out.rows.iter().enumerate() {
                    let mut tmp = vec![0.0f32; iw];
                    for t in 0..rt.len {
                        for (a, b) in tmp.iter_mut().zip(&src[(rt.start + t) * iw..]) {
                            *a += rt.w[t] * b;
                        }
                    }
                    for (j, ct) in out.cols.iter().enumerate() {
                        let taps = &tmp[ct.start..ct.start + ct.len];
                        let want: f32 = taps.iter().zip(&ct.w).map(|(a, b)| a * b).sum();
                        let got = out.data[(p * side + r) * side + j];
                        assert_eq!(
                            got.to_bits(),
                            want.to_bits(),
                            "{rw}x{rh} -> {side}: ({p}, {r}, {j})"
                        );
                    }
                }
            }
        }
        // Both kinds of pass were met: a specialised tap count (up to 4) and the general one.
        assert!(
            widths.iter().any(|&n| n <= 4) && widths.iter().any(|&n| n > 4),
            "{widths:?}"
        );
    }

    #[test]
    fn prepared_region_is_exact_for_every_format_factor_and_overhang() {
        // Regions over each edge and beyond the frame (whole output rows and columns
        // outside it), every pixel format, factors 1 to 4: each box average is the exact
        // integer sum of the clamped pixels times 1/factor².
        for (cx, cy, region, out_side) in [
            (2.0, 1.0, 40.0, 40),
            (11.0, 6.0, 60.0, 20),
            (21.5, 12.0, 45.0, 15),
            (0.0, 12.9, 80.0, 20),
            (12.0, 0.0, 9.0, 9),
        ] {
            assert_prepared_region_exact(23, 13, cx, cy, region, out_side, None);
        }
    }

    #[test]
    fn prepared_region_is_exact_for_large_factors_inside_and_over_the_edges() {
        // Factors 1 to 17 (single pixels, the boxed column sums up to 16, the one-by-one sums above) on a
        // frame wide enough for many output columns inside it, the region inside the frame,
        // over its left edge and over its right edge.
        for fac in [1usize, 2, 3, 5, 8, 15, 16, 17] {
            for (cx, out_side) in [(200.0, 12), (10.0, 9), (395.0, 7)] {
                let region = (fac * out_side) as f32;
                assert_prepared_region_exact(400, 30, cx, 15.0, region, out_side, Some(fac));
            }
        }
    }

    /// Prepares a `region` around (`cx`, `cy`) of a `w × h` frame in every pixel format and
    /// checks each box average against the exact integer sum of the clamped pixels times
    /// 1/factor² (and the factor, when given).
    fn assert_prepared_region_exact(
        w: usize,
        h: usize,
        cx: f32,
        cy: f32,
        region: f32,
        out_side: usize,
        factor: Option<usize>,
    ) {
        for format in [
            PixelFormat::Rgb8,
            PixelFormat::Bgr8,
            PixelFormat::Rgba8,
            PixelFormat::Bgra8,
            PixelFormat::Mono8,
        ] {
            let bpp = format.bytes_per_pixel();
            let d: Vec<u8> = (0..w * h * bpp)
                .map(|i| ((i * 131 + i / 7) % 251) as u8)
                .collect();
            let f = Frame::packed(&d, w, h, format).unwrap();
            let offs = format.rgb_offsets();
            let mut s = Sampler::default();
            s.prepare(&f, Point2 { x: cx, y: cy }, region, region, out_side);
            let fac = s.factor;
            if let Some(want) = factor {
                assert_eq!(fac, want, "{format:?} region {region} side {out_side}");
            }
            let inv = 1.0 / (fac * fac) as f32;
            let px = |x: isize, y: isize, p: usize| {
                let (x, y) = (x.clamp(0, w as isize - 1), y.clamp(0, h as isize - 1));
                u32::from(d[(y as usize * w + x as usize) * bpp + offs[p]])
            };
            for p in 0..format.planes() {
                for r in 0..s.inter_h {
                    for col in 0..s.inter_w {
                        let mut sum = 0u32;
                        for dy in 0..fac {
                            for dx in 0..fac {
                                let x = s.ox as isize + (col * fac + dx) as isize;
                                let y = s.oy as isize + (r * fac + dy) as isize;
                                sum += px(x, y, p);
                            }
                        }
                        let got = s.inter[(p * s.inter_h + r) * s.inter_w + col];
                        assert_eq!(
                            got.to_bits(),
                            (sum as f32 * inv).to_bits(),
                            "{format:?} factor {fac} plane {p} row {r} col {col} centre {cx}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn bgr_is_reordered_to_rgb() {
        let d = vec![10u8, 20, 30];
        let f = Frame::packed(&d, 1, 1, PixelFormat::Bgr8).unwrap();
        let mut s = Sampler::default();
        let c = Point2 { x: 0.5, y: 0.5 };
        s.prepare(&f, c, 1.0, 1.0, 1);
        let mut p = Patch::new(1, 3);
        s.sample(c, 1.0, &mut p);
        assert_eq!(p.data, vec![30.0, 20.0, 10.0]);
    }
}
