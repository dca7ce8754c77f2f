//! Felzenszwalb HOG ("fHOG", as P. Dollár's `fhog` computes it), 31 channels, plus an
//! optional grayscale channel.
//!
//! Per pixel: central-difference gradient (one-sided at the patch border; for colour the
//! channel of largest magnitude), hard orientation binning into 18 contrast-sensitive bins
//! (nearest of `k·20°`), bilinear spatial voting into cells with weight `|∇I| / cell²`.
//! Per cell, four 2×2-block energies of the 9 contrast-insensitive histograms give four
//! normalisers `n_k = 1/sqrt(energy + ε)`. Channels: 18 sensitive and 9 insensitive bins
//! `0.5·Σ_k min(h·n_k, 0.2)`, then 4 texture channels `0.2357·Σ_o min(h_o·n_k, 0.2)`.
//! (Dollár's 32nd, all-zero channel is dropped.)
//!
//! Optional groups, in this channel order after the 31 HOG channels: one grayscale channel
//! ([`gray`]) and the 10 colour-name channels ([`colornames`], colour input only: for a
//! one-plane input the group is left out, see [`FeatureExtractor::set_input_planes`]).

use super::{colornames, gray, FeatureExtractor, FeatureMap, LayerInfo};
use crate::error::TrackError;
use crate::image::Patch;

/// Number of contrast-insensitive orientations.
pub const ORIENTATIONS: usize = 9;
/// Number of HOG channels: 2·9 sensitive + 9 insensitive + 4 texture.
pub const HOG_CHANNELS: usize = 3 * ORIENTATIONS + 4;
/// Truncation of normalised histogram values.
const CLIP: f32 = 0.2;
/// Weight of the texture (gradient energy) channels, `1/sqrt(18)`.
const TEXTURE_WEIGHT: f32 = 0.2357;

/// The fHOG extractor with its scratch buffers.
#[derive(Debug, Clone)]
pub struct Hog {
    cell: usize,
    grayscale: bool,
    /// Colour names requested by the configuration.
    colornames: bool,
    /// Colour names produced: requested and the input has colour.
    cn_active: bool,
    layers: Vec<LayerInfo>,
    hist: Vec<f32>,
    energy: Vec<f32>,
    norm: Vec<f32>,
    /// Each cell's four block normalisers, `[4][cell]`.
    quad: Vec<f32>,
    /// Texture channel sums, `[4][cell]`.
    tex: Vec<f32>,
    col_bin: Vec<(usize, usize, f32, f32)>,
    mag: Vec<f32>,
    bin: Vec<u8>,
    row_gx: Vec<f32>,
    row_gy: Vec<f32>,
    row_m2: Vec<f32>,
    /// Colour names' row buffers.
    cn_scratch: colornames::Scratch,
}

/// `atan2(y, x)` in (−π, π] to within 1e-5 rad (a minimax polynomial on [0, 1]), far below
/// the 20° bin width.
#[allow(clippy::excessive_precision)] // published minimax coefficients, kept as printed
fn fast_atan2(y: f32, x: f32) -> f32 {
    use std::f32::consts::{FRAC_PI_2, PI};
    // Branch-free (selects only) so the per-row loop vectorises.
    let (ax, ay) = (x.abs(), y.abs());
    let (mn, mx) = (ax.min(ay), ax.max(ay));
    let a = if mx > 0.0 { mn / mx } else { 0.0 };
    let s = a * a;
    let r = ((((-0.013_480_470 * s + 0.057_477_314) * s - 0.121_239_071) * s + 0.195_635_925) * s
        - 0.332_994_597)
        * s
        * a
        + 0.999_995_630 * a;
    let r = if ay > ax { FRAC_PI_2 - r } else { r };
    let r = if x < 0.0 { PI - r } else { r };
    if y < 0.0 {
        -r
    } else {
        r
    }
}

/// Nearest of the 18 directions `k·20°` of the gradient `(gx, gy)`, θ ∈ [0, 2π), ties
/// upward as Dollár's `(int)(θ·18/2π + 0.5)`, so opposite gradients land in opposite bins.
#[inline(always)]
fn orientation_bin(gx: f32, gy: f32) -> u8 {
    let nbins = (2 * ORIENTATIONS) as u32;
    let t = fast_atan2(gy, gx) * (ORIENTATIONS as f32 / std::f32::consts::PI);
    let t = if t < 0.0 { t + nbins as f32 } else { t };
    // t + 0.5 lies in [0.5, 18.5): truncation is the floor. The bound keeps a NaN (which
    // finite pixels cannot give) in range.
    let b = floor_small(t + 0.5);
    (if b >= nbins { b - nbins } else { b }).min(nbins - 1) as u8
}

/// `⌊x⌋` for `0 ≤ x < 2²²`, exactly, without a float-to-int conversion (Rust's `as` is
/// saturating, which keeps LLVM from vectorising the loops around it on baseline x86-64):
/// `x + 2²³` rounds `x` to an integer, stepped down by one where it rounded up, and that
/// integer is the low mantissa bits of `y ∈ [2²³, 2²⁴)`. Outside the range (or NaN) the
/// result is unspecified but no panic.
#[inline(always)]
pub(crate) fn floor_small(x: f32) -> u32 {
    const MAGIC: f32 = 8_388_608.0; // 2^23
    let y = x + MAGIC;
    let y = if y - MAGIC > x { y - 1.0 } else { y };
    y.to_bits().wrapping_sub(MAGIC.to_bits())
}

/// Central differences over the pixels `[a, b)` of the planes' flat index, the rows above
/// and below at offsets `up` and `dn` from each pixel, vertical weight `sy`. A function,
/// not a closure in [`Hog::gradients`]: a closure called three times was not inlined into
/// `hog_channels`' AVX2 clone and ran as baseline code, twice as slow as the rows it
/// replaced on a 100-pixel patch.
#[inline(always)]
fn gradient_run(
    patch: &Patch,
    mag: &mut [f32],
    bin: &mut [u8],
    (a, b): (usize, usize),
    (up, dn): (usize, usize),
    sy: f32,
) {
    let n = patch.side * patch.side;
    let taps = |p: usize| {
        let pl = &patch.data[p * n..(p + 1) * n];
        (
            &pl[a - up..b - up],
            &pl[a + dn..b + dn],
            &pl[a - 1..b - 1],
            &pl[a + 1..b + 1],
        )
    };
    if patch.planes == 3 {
        fused3(
            &mut mag[a..b],
            &mut bin[a..b],
            [taps(0), taps(1), taps(2)],
            sy,
        );
    } else {
        fused1(&mut mag[a..b], &mut bin[a..b], taps(0), sy);
    }
}

/// One plane's taps at a run of pixels: the rows above and below, the columns left and
/// right.
type Taps<'a> = (&'a [f32], &'a [f32], &'a [f32], &'a [f32]);

/// Central-difference gradients of a run of pixels of three planes, the plane of largest
/// magnitude kept; branch-free (selects only) so the loop vectorises, and ties keep the
/// earlier plane, as a strict `>` scan does.
#[inline(always)]
fn fused3(mrow: &mut [f32], brow: &mut [u8], taps: [Taps<'_>; 3], sy: f32) {
    let m = mrow.len();
    let [(u0, d0, l0, r0), (u1, d1, l1, r1), (u2, d2, l2, r2)] = taps;
    let (u0, d0, l0, r0) = (&u0[..m], &d0[..m], &l0[..m], &r0[..m]);
    let (u1, d1, l1, r1) = (&u1[..m], &d1[..m], &l1[..m], &r1[..m]);
    let (u2, d2, l2, r2) = (&u2[..m], &d2[..m], &l2[..m], &r2[..m]);
    let brow = &mut brow[..m];
    for i in 0..m {
        let gx0 = (r0[i] - l0[i]) * 0.5;
        let gy0 = (d0[i] - u0[i]) * sy;
        let m0 = gx0 * gx0 + gy0 * gy0;
        let gx1 = (r1[i] - l1[i]) * 0.5;
        let gy1 = (d1[i] - u1[i]) * sy;
        let m1 = gx1 * gx1 + gy1 * gy1;
        let gx2 = (r2[i] - l2[i]) * 0.5;
        let gy2 = (d2[i] - u2[i]) * sy;
        let m2 = gx2 * gx2 + gy2 * gy2;
        let t1 = m1 > m0;
        let (gx, gy, mm) = (
            if t1 { gx1 } else { gx0 },
            if t1 { gy1 } else { gy0 },
            if t1 { m1 } else { m0 },
        );
        let t2 = m2 > mm;
        let (gx, gy, mm) = (
            if t2 { gx2 } else { gx },
            if t2 { gy2 } else { gy },
            if t2 { m2 } else { mm },
        );
        mrow[i] = mm.sqrt();
        brow[i] = orientation_bin(gx, gy);
    }
}

/// [`fused3`] for one plane.
#[inline(always)]
fn fused1(mrow: &mut [f32], brow: &mut [u8], taps: Taps<'_>, sy: f32) {
    let m = mrow.len();
    let (u0, d0, l0, r0) = taps;
    let (u0, d0, l0, r0) = (&u0[..m], &d0[..m], &l0[..m], &r0[..m]);
    let brow = &mut brow[..m];
    for i in 0..m {
        let gx = (r0[i] - l0[i]) * 0.5;
        let gy = (d0[i] - u0[i]) * sy;
        mrow[i] = (gx * gx + gy * gy).sqrt();
        brow[i] = orientation_bin(gx, gy);
    }
}

impl Hog {
    /// An extractor with maximal cell size `cell` (pixels), optionally appending a
    /// grayscale channel.
    pub fn new(cell: usize, grayscale: bool) -> Self {
        Self::with_colornames(cell, grayscale, false)
    }

    /// As [`Hog::new`], optionally appending the 10 colour-name channels (for colour input;
    /// the input is assumed to have colour until [`FeatureExtractor::set_input_planes`]
    /// says otherwise).
    pub fn with_colornames(cell: usize, grayscale: bool, colornames: bool) -> Self {
        Self {
            cell: cell.max(1),
            grayscale,
            colornames,
            cn_active: colornames,
            layers: Self::layer_info(grayscale, colornames),
            hist: Vec::new(),
            energy: Vec::new(),
            norm: Vec::new(),
            quad: Vec::new(),
            tex: Vec::new(),
            col_bin: Vec::new(),
            mag: Vec::new(),
            bin: Vec::new(),
            row_gx: Vec::new(),
            row_gy: Vec::new(),
            row_m2: Vec::new(),
            cn_scratch: colornames::Scratch::default(),
        }
    }

    fn layer_info(grayscale: bool, cn: bool) -> Vec<LayerInfo> {
        let channels =
            HOG_CHANNELS + usize::from(grayscale) + if cn { colornames::CN_CHANNELS } else { 0 };
        let name = match (grayscale, cn) {
            (false, false) => "hog",
            (true, false) => "hog+gray",
            (false, true) => "hog+cn",
            (true, true) => "hog+gray+cn",
        };
        vec![LayerInfo {
            name: name.into(),
            channels,
            weight: 1.0,
        }]
    }

    /// Gradient magnitude and orientation bin (0..18) of every pixel.
    ///
    /// The rows between the first and the last are one run along the plane (central
    /// differences at every pixel from `(1, 1)` to `(s − 2, s − 2)`, so the loop has one
    /// tail, not one a row: on the scale filter's 24-pixel samples a row's 22 pixels left
    /// 6 to the scalar tail), then each row's border columns are written over the run's
    /// values there with their one-sided differences; the first and last rows go on their
    /// own. Every pixel gets the same arithmetic as row by row, so the same bits
    /// (`fused_gradients_equal_the_plane_by_plane_scan`).
    #[inline(always)] // into each of `hog_channels`' clones
    fn gradients(&mut self, patch: &Patch) {
        let s = patch.side;
        let n = s * s;
        self.mag.resize(n, 0.0);
        self.bin.resize(n, 0);
        if s < 3 || !(patch.planes == 1 || patch.planes == 3) {
            self.gradients_generic(patch);
            return;
        }
        let planes = patch.planes;
        let plane = |p: usize| &patch.data[p * n..(p + 1) * n];
        // First row (one-sided along y: the row below less this one), the rows between
        // as one run, the last row (this one less the row above).
        let (mag, bin) = (&mut self.mag[..], &mut self.bin[..]);
        gradient_run(patch, mag, bin, (1, s - 1), (0, s), 1.0);
        gradient_run(patch, mag, bin, (s + 1, (s - 2) * s + s - 1), (s, s), 0.5);
        gradient_run(patch, mag, bin, ((s - 1) * s + 1, n - 1), (s, 0), 1.0);
        // Border columns: one-sided differences along x.
        for r in 0..s {
            let (ru, rd, sy) = match r {
                0 => (0, 1, 1.0),
                r if r == s - 1 => (r - 1, r, 1.0),
                r => (r - 1, r + 1, 0.5),
            };
            for (c, a, b) in [(0, 0, 1), (s - 1, s - 2, s - 1)] {
                let (mut bx, mut by, mut bm) = (0.0f32, 0.0f32, 0.0f32);
                for p in 0..planes {
                    let pl = plane(p);
                    let gx = pl[r * s + b] - pl[r * s + a];
                    let gy = (pl[rd * s + c] - pl[ru * s + c]) * sy;
                    let m2 = gx * gx + gy * gy;
                    if p == 0 || m2 > bm {
                        (bx, by, bm) = (gx, gy, m2);
                    }
                }
                self.mag[r * s + c] = bm.sqrt();
                self.bin[r * s + c] = orientation_bin(bx, by);
            }
        }
    }

    /// [`Self::gradients`] for any plane count and side (row buffers, plane by plane).
    fn gradients_generic(&mut self, patch: &Patch) {
        let s = patch.side;
        let n = s * s;
        self.mag.resize(n, 0.0);
        self.bin.resize(n, 0);
        self.row_gx.resize(s, 0.0);
        self.row_gy.resize(s, 0.0);
        self.row_m2.resize(s, 0.0);
        for r in 0..s {
            let (ru, rd, sy) = match r {
                _ if s == 1 => (0, 0, 0.0),
                0 => (0, 1, 1.0),
                r if r == s - 1 => (r - 1, r, 1.0),
                r => (r - 1, r + 1, 0.5),
            };
            for p in 0..patch.planes {
                let pl = &patch.data[p * n..(p + 1) * n];
                let up = &pl[ru * s..ru * s + s];
                let dn = &pl[rd * s..rd * s + s];
                let cur = &pl[r * s..r * s + s];
                let first = p == 0;
                let mut put = |c: usize, gx: f32, gy: f32| {
                    let m2 = gx * gx + gy * gy;
                    if first || m2 > self.row_m2[c] {
                        self.row_gx[c] = gx;
                        self.row_gy[c] = gy;
                        self.row_m2[c] = m2;
                    }
                };
                if s == 1 {
                    put(0, 0.0, 0.0);
                    continue;
                }
                put(0, cur[1] - cur[0], (dn[0] - up[0]) * sy);
                put(s - 1, cur[s - 1] - cur[s - 2], (dn[s - 1] - up[s - 1]) * sy);
                // Interior columns: central differences, written as slice zips so they
                // vectorise.
                let gxs = &mut self.row_gx[1..s - 1];
                let gys = &mut self.row_gy[1..s - 1];
                let m2s = &mut self.row_m2[1..s - 1];
                let left = &cur[..s - 2];
                let right = &cur[2..];
                for i in 0..s - 2 {
                    let gx = (right[i] - left[i]) * 0.5;
                    let gy = (dn[i + 1] - up[i + 1]) * sy;
                    let m2 = gx * gx + gy * gy;
                    let take = first || m2 > m2s[i];
                    gxs[i] = if take { gx } else { gxs[i] };
                    gys[i] = if take { gy } else { gys[i] };
                    m2s[i] = if take { m2 } else { m2s[i] };
                }
            }
            let mrow = &mut self.mag[r * s..(r + 1) * s];
            let brow = &mut self.bin[r * s..(r + 1) * s];
            for c in 0..s {
                mrow[c] = self.row_m2[c].sqrt();
                brow[c] = orientation_bin(self.row_gx[c], self.row_gy[c]);
            }
        }
    }

    /// Histograms `hist[o][cy][cx]` (18 sensitive bins, orientation-major, so the
    /// per-cell arithmetic below runs along contiguous cells) with bilinear spatial voting.
    /// Each bin receives its votes in pixel order whatever the layout, so the sums are the
    /// same bits in either.
    #[inline(always)] // into each of `hog_channels`' clones
    fn histograms(&mut self, side: usize, cell: usize, hb: usize, wb: usize) {
        let nb = hb * wb;
        let no = 2 * ORIENTATIONS;
        self.hist.clear();
        self.hist.resize(no * nb, 0.0);
        let inv = 1.0 / cell as f32;
        let norm = inv * inv;
        // Per pixel column (and row): the two neighbouring cells and their weights; a cell
        // outside the grid gets weight 0 and a harmless in-range index.
        let split = |x: usize, n: usize| {
            let xb = (x as f32 + 0.5) * inv - 0.5;
            let x0 = xb.floor();
            let d = xb - x0;
            let x0 = x0 as isize;
            let lo_ok = x0 >= 0;
            let hi_ok = x0 + 1 < n as isize;
            let i0 = if lo_ok { x0 as usize } else { 0 };
            let i1 = if hi_ok { (x0 + 1) as usize } else { n - 1 };
            (
                i0,
                i1,
                if lo_ok { 1.0 - d } else { 0.0 },
                if hi_ok { d } else { 0.0 },
            )
        };
        self.col_bin.clear();
        for x in 0..(wb * cell).min(side) {
            self.col_bin.push(split(x, wb));
        }
        // Local slices, so the loop keeps the buffers' addresses in registers (through
        // `self` they were reloaded after every store).
        let hist = &mut self.hist[..];
        let cols = &self.col_bin[..];
        let n = cols.len();
        for y in 0..(hb * cell).min(side) {
            let (y0, y1, wy0, wy1) = split(y, hb);
            let (r0, r1) = (y0 * wb, y1 * wb);
            let mrow = &self.mag[y * side..y * side + n];
            let brow = &self.bin[y * side..y * side + n];
            for ((&m, &o), &(x0, x1, wx0, wx1)) in mrow.iter().zip(brow).zip(cols) {
                let m = m * norm;
                let o = usize::from(o) * nb;
                let (a, b) = (m * wy0, m * wy1);
                hist[o + r0 + x0] += a * wx0;
                hist[o + r0 + x1] += a * wx1;
                hist[o + r1 + x0] += b * wx0;
                hist[o + r1 + x1] += b * wx1;
            }
        }
    }

    /// Block normalisers `norm[(hb+1) × (wb+1)]` from the insensitive histograms, then
    /// each cell's four (`quad[k·nb + cell]`, `k` as in the channel formulas).
    #[inline(always)] // into each of `hog_channels`' clones
    fn normalisers(&mut self, cell: usize, hb: usize, wb: usize) {
        let nb = hb * wb;
        self.energy.clear();
        self.energy.resize(nb, 0.0);
        for o in 0..ORIENTATIONS {
            let (a, b) = (
                &self.hist[o * nb..(o + 1) * nb],
                &self.hist[(o + ORIENTATIONS) * nb..(o + ORIENTATIONS + 1) * nb],
            );
            for ((e, &a), &b) in self.energy.iter_mut().zip(a).zip(b) {
                let v = a + b;
                *e += v * v;
            }
        }
        let c4 = (cell * cell * cell * cell) as f32;
        let eps = 1e-4 / 4.0 / c4;
        let (hb1, wb1) = (hb + 1, wb + 1);
        self.norm.clear();
        self.norm.resize(hb1 * wb1, 0.0);
        // Interior entries (i, j) in 1..hb × 1..wb: the block of cells (i-1..=i, j-1..=j);
        // border entries replicate the nearest interior one.
        let clampi = |i: usize, n: usize| i.clamp(1, n.saturating_sub(1).max(1));
        for i in 0..hb1 {
            for j in 0..wb1 {
                let bi = clampi(i, hb) - 1;
                let bj = clampi(j, wb) - 1;
                let e = |y: usize, x: usize| self.energy[y.min(hb - 1) * wb + x.min(wb - 1)];
                let s = e(bi, bj) + e(bi, bj + 1) + e(bi + 1, bj) + e(bi + 1, bj + 1);
                self.norm[i * wb1 + j] = 1.0 / (s + eps).sqrt();
            }
        }
        // Cell (cy, cx) takes the normalisers of its four blocks: below right, above right,
        // below left, above left.
        self.quad.clear();
        self.quad.resize(4 * nb, 0.0);
        for (k, (dy, dx)) in [(1, 1), (0, 1), (1, 0), (0, 0)].into_iter().enumerate() {
            for cy in 0..hb {
                let src = &self.norm[(cy + dy) * wb1 + dx..(cy + dy) * wb1 + dx + wb];
                self.quad[k * nb + cy * wb..k * nb + (cy + 1) * wb].copy_from_slice(src);
            }
        }
    }
}

/// The 31 HOG channels of `patch` into the start of `data` (`hb × wb` cells of side
/// `cell`; the caller has checked the sizes). Compiled twice: for the baseline and
/// with AVX2 + FMA, chosen at run time (the same code, so the same bits).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
fn hog_channels(hog: &mut Hog, patch: &Patch, cell: usize, hb: usize, wb: usize, data: &mut [f32]) {
    let nb = hb * wb;
    hog.gradients(patch);
    hog.histograms(patch.side, cell, hb, wb);
    hog.normalisers(cell, hb, wb);
    let no = 2 * ORIENTATIONS;
    // Channel by channel along the cells (vectorises): value `0.5·Σ_k min(h·n_k, 0.2)`,
    // the sensitive bins' terms also summed per `k` over the bins into the texture
    // channels; the same additions in the same order as cell by cell.
    let (n0, rest) = hog.quad.split_at(nb);
    let (n1, rest) = rest.split_at(nb);
    let (n2, n3) = rest.split_at(nb);
    hog.tex.clear();
    hog.tex.resize(4 * nb, 0.0);
    let (t0, rest) = hog.tex.split_at_mut(nb);
    let (t1, rest) = rest.split_at_mut(nb);
    let (t2, t3) = rest.split_at_mut(nb);
    for o in 0..no {
        let h = &hog.hist[o * nb..(o + 1) * nb];
        let dst = &mut data[o * nb..(o + 1) * nb];
        for i in 0..nb {
            let hv = h[i];
            let a = (hv * n0[i]).min(CLIP);
            let b = (hv * n1[i]).min(CLIP);
            let c = (hv * n2[i]).min(CLIP);
            let d = (hv * n3[i]).min(CLIP);
            dst[i] = 0.5 * (((a + b) + c) + d);
            t0[i] += a;
            t1[i] += b;
            t2[i] += c;
            t3[i] += d;
        }
    }
    for o in 0..ORIENTATIONS {
        let (ha, hb_) = (
            &hog.hist[o * nb..(o + 1) * nb],
            &hog.hist[(o + ORIENTATIONS) * nb..(o + ORIENTATIONS + 1) * nb],
        );
        let dst = &mut data[(no + o) * nb..(no + o + 1) * nb];
        for i in 0..nb {
            let hv = ha[i] + hb_[i];
            let a = (hv * n0[i]).min(CLIP);
            let b = (hv * n1[i]).min(CLIP);
            let c = (hv * n2[i]).min(CLIP);
            let d = (hv * n3[i]).min(CLIP);
            dst[i] = 0.5 * (((a + b) + c) + d);
        }
    }
    for (k, t) in [&*t0, &*t1, &*t2, &*t3].into_iter().enumerate() {
        let dst = &mut data[(3 * ORIENTATIONS + k) * nb..(3 * ORIENTATIONS + k + 1) * nb];
        for (o, &v) in dst.iter_mut().zip(t) {
            *o = TEXTURE_WEIGHT * v;
        }
    }
}

impl FeatureExtractor for Hog {
    fn layers(&self) -> &[LayerInfo] {
        &self.layers
    }

    fn cell_size(&self) -> usize {
        self.cell
    }

    fn set_input_planes(&mut self, planes: usize) {
        self.cn_active = self.colornames && planes >= 3;
        self.layers = Self::layer_info(self.grayscale, self.cn_active);
    }

    fn extract(
        &mut self,
        patch: &Patch,
        cell: usize,
        out: &mut FeatureMap,
    ) -> Result<(), TrackError> {
        let (hb, wb) = (out.grid.h, out.grid.w);
        let nb = hb * wb;
        if cell == 0 || hb < 2 || wb < 2 || patch.side < hb * cell || patch.side < wb * cell {
            return Err(TrackError::Feature(format!(
                "patch of side {} cannot give a {hb}x{wb} grid of {cell}-px cells",
                patch.side
            )));
        }
        if out.channels != self.channels() || out.data.len() != nb * out.channels {
            return Err(TrackError::Feature(format!(
                "feature map has {} channels, hog gives {}",
                out.channels,
                self.channels()
            )));
        }
        hog_channels(self, patch, cell, hb, wb, &mut out.data);
        let mut next = HOG_CHANNELS;
        if self.grayscale {
            gray::cell_gray(
                patch,
                cell,
                hb,
                wb,
                &mut out.data[next * nb..(next + 1) * nb],
            );
            next += 1;
        }
        if self.cn_active {
            if patch.planes < 3 {
                return Err(TrackError::Feature(format!(
                    "colour names need a colour patch, got {} plane(s)",
                    patch.planes
                )));
            }
            colornames::cell_colornames_with(
                patch,
                cell,
                hb,
                wb,
                &mut out.data[next * nb..(next + colornames::CN_CHANNELS) * nb],
                &mut self.cn_scratch,
            );
        }
        Ok(())
    }

    fn boxed_clone(&self) -> Box<dyn FeatureExtractor> {
        Box::new(self.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::GridSize;

    #[test]
    fn floor_small_equals_truncation_on_its_range() {
        // Integers, their neighbours, halves (the ties of the rounding step) and random
        // values across [0, 2^22).
        let mut xs: Vec<f32> = Vec::new();
        for i in 0..40u32 {
            let v = i as f32;
            xs.extend([
                v,
                v + 0.5,
                v.next_up(),
                v.next_down().max(0.0),
                v + 0.999_99,
            ]);
        }
        let mut seed = 7u32;
        for _ in 0..100_000 {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let e = (seed >> 27) as i32 - 10; // 2^-10 .. 2^21
            xs.push((seed & 0xffff) as f32 / 65_536.0 * 2f32.powi(e));
        }
        xs.push(4_194_303.5);
        for x in xs {
            assert_eq!(floor_small(x), x as i32 as u32, "{x}");
        }
    }

    #[test]
    fn orientation_bins_equal_the_converting_form() {
        // The bin formula as it was written with a float-to-int conversion.
        let reference = |gx: f32, gy: f32| {
            let nbins = (2 * ORIENTATIONS) as u32;
            let t = fast_atan2(gy, gx) * (ORIENTATIONS as f32 / std::f32::consts::PI);
            let t = if t < 0.0 { t + nbins as f32 } else { t };
            let b = (t + 0.5) as i32 as u32;
            (if b >= nbins { b - nbins } else { b }) as u8
        };
        let mut seed = 3u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            ((seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5) * 510.0
        };
        for i in 0..200_000 {
            let (gx, gy) = if i % 5 == 0 {
                (next().round(), 0.0)
            } else {
                (next(), next())
            };
            assert_eq!(orientation_bin(gx, gy), reference(gx, gy), "{gx} {gy}");
        }
        assert_eq!(orientation_bin(0.0, 0.0), reference(0.0, 0.0));
    }

    fn extract(p: &Patch, cell: usize, gray: bool) -> FeatureMap {
        let mut hog = Hog::new(cell, gray);
        let g = p.side / cell;
        let mut f = FeatureMap::new(GridSize { h: g, w: g }, hog.channels());
        hog.extract(p, cell, &mut f).unwrap();
        f
    }

    #[test]
    fn hog_has_31_channels_and_32_with_gray() {
        assert_eq!(Hog::new(4, false).channels(), 31);
        assert_eq!(Hog::new(4, true).channels(), 32);
    }

    #[test]
    fn flat_patch_gives_all_zero_hog() {
        let mut p = Patch::new(32, 3);
        p.data.iter_mut().for_each(|v| *v = 77.0);
        let f = extract(&p, 4, false);
        assert!(f.data.iter().all(|v| v.abs() < 1e-6));
    }

    #[test]
    fn vertical_edge_votes_into_the_horizontal_gradient_bin() {
        // Intensity rises left to right: gradient points along +x, orientation 0.
        let s = 32;
        let mut p = Patch::new(s, 1);
        for r in 0..s {
            for c in 0..s {
                p.data[r * s + c] = if c >= s / 2 { 200.0 } else { 0.0 };
            }
        }
        let f = extract(&p, 4, false);
        let nb = 64;
        let i = 3 * 8 + 3; // cell next to the edge
        let sens: Vec<f32> = (0..18).map(|o| f.data[o * nb + i]).collect();
        let (best, _) =
            sens.iter()
                .enumerate()
                .fold((0, f32::MIN), |a, (k, &v)| if v > a.1 { (k, v) } else { a });
        assert_eq!(best, 0, "{sens:?}");
        // Contrast-insensitive bin 0 carries it too; the opposite sensitive bin does not.
        assert!(f.data[18 * nb + i] > 0.1);
        assert!(f.data[9 * nb + i] < 1e-6);
        // A darkening edge lands in the opposite sensitive bin.
        for v in &mut p.data {
            *v = 200.0 - *v;
        }
        let g = extract(&p, 4, false);
        assert!(g.data[9 * nb + i] > 0.1);
    }

    #[test]
    fn values_are_bounded_by_the_clip() {
        let s = 40;
        let mut p = Patch::new(s, 3);
        for (i, v) in p.data.iter_mut().enumerate() {
            *v = ((i * 7919) % 255) as f32;
        }
        let f = extract(&p, 4, true);
        let nb = 100;
        for d in 0..27 {
            for i in 0..nb {
                let v = f.data[d * nb + i];
                assert!((0.0..=0.4 + 1e-5).contains(&v), "{d} {v}");
            }
        }
        for d in 27..31 {
            for i in 0..nb {
                assert!(f.data[d * nb + i] <= TEXTURE_WEIGHT * 18.0 * CLIP + 1e-4);
            }
        }
    }

    /// The channel formulas cell by cell, as Dollár's `fhog` loops (and as this module did
    /// before the orientation-major layout), from the extractor's own histograms and
    /// normalisers: the channels along the cells are the same bits.
    #[test]
    fn channels_along_the_cells_equal_the_cell_by_cell_formulas_bit_for_bit() {
        for (side, cell) in [(40, 4), (37, 3), (24, 4)] {
            let mut p = Patch::new(side, 3);
            for (i, v) in p.data.iter_mut().enumerate() {
                *v = ((i * 7919 + i / 11) % 256) as f32;
            }
            let g = side / cell;
            let mut hog = Hog::new(cell, false);
            let mut f = FeatureMap::new(GridSize { h: g, w: g }, hog.channels());
            hog.extract(&p, cell, &mut f).unwrap();
            let (nb, wb1, no) = (g * g, g + 1, 2 * ORIENTATIONS);
            let mut nonzero = 0;
            for cy in 0..g {
                for cx in 0..g {
                    let i = cy * g + cx;
                    let n = [
                        hog.norm[(cy + 1) * wb1 + cx + 1],
                        hog.norm[cy * wb1 + cx + 1],
                        hog.norm[(cy + 1) * wb1 + cx],
                        hog.norm[cy * wb1 + cx],
                    ];
                    let h = |o: usize| hog.hist[o * nb + i];
                    let mut tex = [0.0f32; 4];
                    let mut want = [0.0f32; HOG_CHANNELS];
                    for o in 0..no {
                        let mut acc = 0.0;
                        for (k, nk) in n.iter().enumerate() {
                            let t = (h(o) * nk).min(CLIP);
                            acc += t;
                            tex[k] += t;
                        }
                        want[o] = 0.5 * acc;
                    }
                    for o in 0..ORIENTATIONS {
                        let v = h(o) + h(o + ORIENTATIONS);
                        want[no + o] = 0.5 * n.iter().map(|nk| (v * nk).min(CLIP)).sum::<f32>();
                    }
                    for (k, t) in tex.iter().enumerate() {
                        want[3 * ORIENTATIONS + k] = TEXTURE_WEIGHT * t;
                    }
                    for (d, w) in want.iter().enumerate() {
                        let got = f.data[d * nb + i];
                        assert_eq!(
                            got.to_bits(),
                            w.to_bits(),
                            "side {side} cell {cell} channel {d}"
                        );
                        nonzero += usize::from(got > 0.0);
                    }
                }
            }
            assert!(nonzero > nb * 5, "a textured patch: {nonzero}");
        }
    }

    #[test]
    fn fused_gradients_equal_the_plane_by_plane_scan() {
        // Sides from the smallest the run takes to the scale filter's 24 and a side whose
        // run's length is no multiple of the vector width.
        for (planes, s) in [1, 3]
            .into_iter()
            .flat_map(|p| [3, 4, 5, 24, 37].map(|s| (p, s)))
        {
            let mut p = Patch::new(s, planes);
            for (i, v) in p.data.iter_mut().enumerate() {
                *v = ((i * 7919 + i / 13) % 256) as f32 * 0.75;
            }
            // Equal magnitudes in two planes: the tie keeps the earlier plane.
            if planes == 3 {
                let n = s * s;
                for i in 0..n {
                    p.data[n + i] = 255.0 - p.data[i];
                }
            }
            let mut fast = Hog::new(4, false);
            fast.gradients(&p);
            let mut slow = Hog::new(4, false);
            slow.gradients_generic(&p);
            assert_eq!(fast.bin, slow.bin, "{planes} planes, side {s}");
            assert!(
                fast.mag
                    .iter()
                    .zip(&slow.mag)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{planes} planes, side {s}"
            );
        }
    }

    #[test]
    fn fast_atan2_matches_std() {
        for i in 0..3600 {
            let a = i as f32 * std::f32::consts::PI / 1800.0 - std::f32::consts::PI + 1e-4;
            for r in [0.01f32, 1.0, 300.0] {
                let (y, x) = (r * a.sin(), r * a.cos());
                assert!((fast_atan2(y, x) - y.atan2(x)).abs() < 2e-5, "{a}");
            }
        }
        assert_eq!(fast_atan2(0.0, 0.0), 0.0);
    }

    #[test]
    fn opposite_vertical_gradients_share_an_insensitive_bin() {
        // θ = 90° and 270° sit exactly between two bins; they must fall in opposite
        // sensitive bins (k and k + 9) so the insensitive channel sees one orientation.
        let s = 16;
        let mut up = Patch::new(s, 1);
        for r in 0..s {
            for c in 0..s {
                up.data[r * s + c] = if r >= s / 2 { 100.0 } else { 0.0 };
            }
        }
        let mut down = up.clone();
        down.data.iter_mut().for_each(|v| *v = 100.0 - *v);
        let mut h = Hog::new(4, false);
        h.gradients(&up);
        let a = h.bin[(s / 2) * s + 3];
        h.gradients(&down);
        let b = h.bin[(s / 2) * s + 3];
        assert_eq!(
            (a as usize + ORIENTATIONS) % (2 * ORIENTATIONS),
            b as usize,
            "{a} {b}"
        );
    }

    #[test]
    fn colour_names_add_ten_channels_for_colour_and_none_for_mono() {
        let mut h = Hog::with_colornames(4, true, true);
        assert_eq!(h.channels(), 42);
        assert_eq!(h.layers()[0].name, "hog+gray+cn");
        h.set_input_planes(1);
        assert_eq!(h.channels(), 32);
        let mut p = Patch::new(16, 1);
        p.data.iter_mut().for_each(|v| *v = 50.0);
        let mut f = FeatureMap::new(GridSize { h: 4, w: 4 }, 32);
        h.extract(&p, 4, &mut f).unwrap();
        h.set_input_planes(3);
        assert_eq!(h.channels(), 42);
        // Colour input: the last ten channels are the table row of the (flat) colour.
        let mut p = Patch::new(16, 3);
        for (i, v) in p.data.iter_mut().enumerate() {
            *v = [200.0, 40.0, 90.0][i / 256];
        }
        let mut f = FeatureMap::new(GridSize { h: 4, w: 4 }, 42);
        h.extract(&p, 4, &mut f).unwrap();
        let row = colornames::table()[colornames::bin_index(200.0, 40.0, 90.0)];
        for d in 0..10 {
            assert!(f.channel(32 + d).iter().all(|v| (v - row[d]).abs() < 1e-5));
        }
        // A colour-names extractor fed a mono patch without being told is an error.
        let p = Patch::new(16, 1);
        assert!(h.extract(&p, 4, &mut f).is_err());
    }

    #[test]
    fn too_small_patch_is_an_error() {
        let p = Patch::new(4, 1);
        let mut hog = Hog::new(4, false);
        let mut f = FeatureMap::new(GridSize { h: 4, w: 4 }, 31);
        assert!(hog.extract(&p, 4, &mut f).is_err());
    }
}
