//! A depthwise 2-D convolution (one group per channel, as in NanoTrack v2's backbone and
//! head), written so that the compiler vectorises it on any target (SSE2 / AVX2 on x86_64,
//! NEON on aarch64; no `target-cpu`, no `unsafe`); [`crate::nn`] runs every such `Conv`
//! node on it.
//!
//! Written when tract ran the verifier: tract 0.23.9 computed a depthwise convolution zone
//! by zone around each output point, and in NanoTrack v2's backbone those eight nodes were
//! 35.7 M of a 255×255 pass's 62.6 M instructions (callgrind), mostly bookkeeping around
//! short runs. Here a channel is computed kernel row by kernel row over the whole output
//! plane at once:
//!
//! 1. the channel's input plane is copied into a padded scratch plane split by stride
//!    phase (for stride 2, even and odd rows and columns go to four sub-planes), so that
//!    every kernel tap reads a *contiguous* run of one sub-plane; the padding is zeroed
//!    once per call, since every channel writes the same interior positions;
//! 2. the output is accumulated "wide": output row `oy` lives at `oy · wq` in a buffer whose
//!    rows are as wide as the sub-planes (`wq`), starting at the bias, so a kernel row of
//!    `k` taps is one loop `out[i] += Σ w_kx · src_kx[i]` over `(ho − 1) · wq + wo` values
//!    (the few extra columns between rows are computed and dropped); zipped slice
//!    iterators (kernel rows of 3 and 5 taps) let the compiler drop bounds checks and use
//!    4-wide SSE2 / NEON;
//! 3. the valid columns are copied to the output.
//!
//! Where each input row goes (its phase and offset: divisions by the strides) is worked out
//! once per call, not per channel: on 12 × 12 maps those divisions cost more than the
//! copies. On x86-64 CPUs with AVX-512 the work runs on 16-value blocks (pulp's `x86::V4`,
//! safe code), the wide buffer padded to whole blocks: for the networks' square kernels (3 × 3
//! and 5 × 5) each block summed over all kernel rows in registers and stored once, for other
//! kernels row by row; each value is the same multiplies and adds in the same order as in
//! the other rows, so the same bits. At column stride 1 the copies of step 1 go in 16-value
//! blocks, and where the output rows take no more blocks than the wide rows (12 × 12 and
//! 16 × 16 maps: a row is one block) each block is stored straight into the output plane,
//! with no wide buffer and no step 3; the taps of a kernel row are read from one window.
//! At stride 2 (the backbone's down-sampling layers) square kernels skip all three steps
//! where rows hold at least 32 values: each block's taps are the even and odd lanes of two
//! loads from the input row where it lies, one AVX-512 permute per tap. On CPUs with AVX2 and
//! without AVX-512 the square kernels at stride 1 are summed in registers on 8-value blocks
//! (`rows8`, pulp's `x86::V3`), each padded row's taps loaded once for the output rows that
//! read them; other kernels and strides take the wide rows.
//!
//! Tested against a naive reference here; the networks' outputs against ONNX Runtime's
//! reference values (`tests/integration/verifier.rs`).

/// The shape of one depthwise convolution (one batch item).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Geometry {
    /// Channels (input = output).
    pub channels: usize,
    /// Input height.
    pub in_h: usize,
    /// Input width.
    pub in_w: usize,
    /// Kernel height.
    pub k_h: usize,
    /// Kernel width.
    pub k_w: usize,
    /// Vertical stride (≥ 1).
    pub stride_h: usize,
    /// Horizontal stride (≥ 1).
    pub stride_w: usize,
    /// Zero rows above the input.
    pub pad_top: usize,
    /// Zero columns left of the input.
    pub pad_left: usize,
    /// Output height.
    pub out_h: usize,
    /// Output width.
    pub out_w: usize,
}

impl Geometry {
    /// The output size for `pad_bottom` / `pad_right`, or `None` when the kernel does not
    /// fit the padded input or a size is zero.
    fn output(
        in_len: usize,
        k: usize,
        stride: usize,
        pad_before: usize,
        pad_after: usize,
    ) -> Option<usize> {
        let padded = in_len.checked_add(pad_before)?.checked_add(pad_after)?;
        if in_len == 0 || k == 0 || stride == 0 || padded < k {
            return None;
        }
        Some((padded - k) / stride + 1)
    }

    /// A geometry, or `None` for an impossible one (zero sizes or stride, a kernel larger
    /// than the padded input, padding wider than the kernel).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        channels: usize,
        (in_h, in_w): (usize, usize),
        (k_h, k_w): (usize, usize),
        (stride_h, stride_w): (usize, usize),
        (pad_top, pad_bottom): (usize, usize),
        (pad_left, pad_right): (usize, usize),
    ) -> Option<Self> {
        if channels == 0 || pad_top >= k_h.max(1) || pad_left >= k_w.max(1) {
            return None;
        }
        let out_h = Self::output(in_h, k_h, stride_h, pad_top, pad_bottom)?;
        let out_w = Self::output(in_w, k_w, stride_w, pad_left, pad_right)?;
        Some(Self {
            channels,
            in_h,
            in_w,
            k_h,
            k_w,
            stride_h,
            stride_w,
            pad_top,
            pad_left,
            out_h,
            out_w,
        })
    }

    /// Rows of a stride-phase sub-plane.
    fn phase_h(&self) -> usize {
        // Rows the taps read: (out_h − 1)·stride + k_h, split into stride phases.
        ((self.out_h - 1) * self.stride_h + self.k_h).div_ceil(self.stride_h)
    }

    /// Columns of a stride-phase sub-plane (the wide output's row pitch).
    fn phase_w(&self) -> usize {
        ((self.out_w - 1) * self.stride_w + self.k_w).div_ceil(self.stride_w)
    }

    /// Values of one channel's input plane.
    pub fn in_plane(&self) -> usize {
        self.in_h * self.in_w
    }

    /// Values of one channel's output plane.
    pub fn out_plane(&self) -> usize {
        self.out_h * self.out_w
    }
}

/// Reusable buffers of [`depthwise`].
#[derive(Debug, Default)]
pub struct Scratch {
    phases: Vec<f32>,
    wide: Vec<f32>,
    /// Per input row read: its offset in a channel's plane, its base in the phases.
    rows: Vec<(usize, usize)>,
    /// Per column phase `r`: `r`, its first destination from a row's base, its count.
    cols: Vec<(usize, usize, usize)>,
    /// Per kernel tap: where it starts reading in the phases.
    starts: Vec<usize>,
    /// Per output block and tap pair of a stride-2 convolution read in place: its windows.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))] // the AVX-512 rows' only
    windows: Vec<Window>,
}

/// Where a pair of kernel taps reads one output block's inputs from an input row
/// ([`wide16::planes_s2`]): two 16-value loads from `base`, then per parity (`even`, `odd`)
/// the lanes of the permute and which of them are kept (the others read outside the row:
/// zeros).
#[derive(Debug, Clone, Copy)]
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))] // read by the AVX-512 rows only
pub(crate) struct Window {
    base: usize,
    even: [u32; LANES],
    odd: [u32; LANES],
    keep: [u16; 2],
}

/// Places the windows of a stride-2 `k`-wide kernel over rows of `in_w ≥ 32` values with
/// `pad_left` zeros before them, for `out_w` outputs a row: per 16-output block and tap pair
/// (taps `2j` and `2j + 1` read every other value from column `2·x₀ − pad_left + 2j` on)
/// where its two loads start (inside the row; at the row's ends the nearest such start)
/// and, per parity, the permute's lanes and the lanes kept (those reading inside the row).
/// The same for every channel and row.
pub(crate) fn place_s2(
    windows: &mut Vec<Window>,
    in_w: usize,
    out_w: usize,
    k: usize,
    pad_left: usize,
) {
    windows.clear();
    let last = in_w.saturating_sub(2 * LANES) as isize;
    for b in 0..out_w.div_ceil(LANES) {
        for j in 0..k.div_ceil(2) {
            let at = (2 * b * LANES + 2 * j) as isize - pad_left as isize;
            let base = at.clamp(0, last);
            let lanes = |odd: isize| {
                let idx: [u32; LANES] =
                    std::array::from_fn(|i| (2 * i as isize + odd + at - base) as u32);
                let keep = (0..LANES).filter(|&i| idx[i] < 2 * LANES as u32);
                (idx, keep.fold(0u16, |k, i| k | (1 << i)))
            };
            let ((even, keep_even), (odd, keep_odd)) = (lanes(0), lanes(1));
            windows.push(Window {
                base: base as usize,
                even,
                odd,
                keep: [keep_even, keep_odd],
            });
        }
    }
}

impl Scratch {
    /// [`place_s2`]'s windows, in this scratch's buffer.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))] // the AVX-512 rows' only
    pub(crate) fn windows_s2(
        &mut self,
        in_w: usize,
        out_w: usize,
        k: usize,
        pl: usize,
    ) -> &[Window] {
        place_s2(&mut self.windows, in_w, out_w, k, pl);
        &self.windows
    }
}

/// Depthwise convolution of `input` (`channels` planes of `in_h × in_w`, row-major) with
/// `weights` (`channels` kernels of `k_h × k_w`) plus `bias` (one per channel) into `output`
/// (`channels` planes of `out_h × out_w`), zero padding. Returns `false` (and leaves
/// `output` alone) when a slice has the wrong length.
///
/// On x86-64 CPUs with AVX-512 the work runs on 16-value blocks (safe code through pulp's
/// `x86::V4`), each output the same operations in the same order: the same bits.
pub fn depthwise(
    g: &Geometry,
    input: &[f32],
    weights: &[f32],
    bias: &[f32],
    output: &mut [f32],
    scratch: &mut Scratch,
) -> bool {
    depthwise_rows(g, input, weights, bias, output, scratch, true)
}

/// [`depthwise`], with the AVX-512 rows allowed (`wide`, where the CPU has them) or not.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
fn depthwise_rows(
    g: &Geometry,
    input: &[f32],
    weights: &[f32],
    bias: &[f32],
    output: &mut [f32],
    scratch: &mut Scratch,
    wide: bool,
) -> bool {
    let taps = g.k_h * g.k_w;
    if input.len() != g.channels * g.in_plane()
        || weights.len() != g.channels * taps
        || bias.len() != g.channels
        || output.len() != g.channels * g.out_plane()
    {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    let v4 = pulp::x86::V4::try_new().filter(|_| wide);
    #[cfg(not(target_arch = "x86_64"))]
    let _ = wide;
    // Square kernels at stride 2 on AVX-512 read the input planes where they lie: no
    // phase split, no wide rows ([`wide16::planes_s2`]).
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = v4 {
        let data = (input, weights, bias);
        let done = match (g.k_h, g.k_w) {
            (3, 3) => wide16::planes_s2::<3, 9>(simd, g, data, output, &mut scratch.windows),
            (5, 5) => wide16::planes_s2::<5, 25>(simd, g, data, output, &mut scratch.windows),
            _ => false,
        };
        if done {
            return true;
        }
    }
    let (hq, wq) = (g.phase_h(), g.phase_w());
    let (sh, sw) = (g.stride_h, g.stride_w);
    let sub = hq * wq;
    // Outputs computed per tap: the wide rows, the last one cut at out_w, rounded up to whole
    // blocks of `LANES` for the AVX-512 rows (the values past the last output are computed
    // from the phases' zero slack and dropped).
    let span = ((g.out_h - 1) * wq + g.out_w).next_multiple_of(LANES);
    // The slack past the sub-planes: the wide rows' last block and [`wide16::rows_out`]'s
    // windows read up to `2 · LANES + 4` values beyond them (into lanes that are dropped).
    scratch.phases.resize(sh * sw * sub + 2 * LANES + 8, 0.0);
    scratch.wide.resize(span, 0.0);
    let rows_read = hq * sh;
    let cols_read = wq * sw;
    // Padding and the columns and rows no tap reads stay zero for every channel: each
    // channel overwrites the same interior positions.
    scratch.phases.fill(0.0);
    // Input columns that land inside the read window.
    let x_end = g.in_w.min(cols_read.saturating_sub(g.pad_left));
    // Where each tap (ky, kx) starts reading: its phase sub-plane, shifted by ky / sh rows
    // and kx / sw columns.
    scratch.starts.clear();
    scratch.starts.extend((0..taps).map(|t| {
        let (ky, kx) = (t / g.k_w, t % g.k_w);
        ((ky % sh) * sw + kx % sw) * sub + (ky / sh) * wq + kx / sw
    }));
    let starts = &scratch.starts;
    // The networks' square kernels at column stride 1 on AVX-512 go straight to the output
    // rows ([`wide16::rows_out`]) where that computes no more blocks than the wide rows and
    // every window lies in the phases (at column stride 1 a kernel row's taps are adjacent).
    #[cfg(target_arch = "x86_64")]
    let direct = v4.filter(|_| {
        let (k, across) = (g.k_w, g.out_w.div_ceil(LANES));
        let read = (g.out_h - 1) * wq + across * LANES + k - 1;
        let last = starts.iter().max().map_or(0, |&s| s + read);
        g.k_h == k
            && matches!(k, 3 | 5)
            && sw == 1
            && g.out_h * across <= span / LANES
            && last <= scratch.phases.len()
    });
    // At both strides 1 the same kernels go to [`wide16::rows_ring`], whose windows start
    // at each padded row (`p · wq`) and block, the last one ending in the phases' slack.
    #[cfg(target_arch = "x86_64")]
    let ring = v4.filter(|_| {
        let (k, across) = (g.k_w, g.out_w.div_ceil(LANES));
        let last = (g.out_h + k - 2) * wq + (across - 1) * LANES + LANES + k - 1;
        g.k_h == k && matches!(k, 3 | 5) && (sh, sw) == (1, 1) && last <= scratch.phases.len()
    });
    // On a CPU with AVX2 and without AVX-512, the same square kernels at both strides 1 go
    // to [`rows8::ring`], whose windows start at each padded row and 8-value block.
    #[cfg(target_arch = "x86_64")]
    let v3 = pulp::x86::V3::try_new().filter(|_| {
        let (k, blocks) = (g.k_w, g.out_w.div_ceil(8));
        let last = (g.out_h + k - 2) * wq + blocks * 8 + k - 1;
        wide && v4.is_none()
            && g.k_h == k
            && matches!(k, 3 | 5)
            && (sh, sw) == (1, 1)
            && last <= scratch.phases.len()
    });
    // Where each input row's values go, worked out once for all channels (every channel's
    // plane has the same layout; the divisions by the strides cost more per row than the
    // copies of 12-value rows themselves): per input row its offset in the plane and its
    // base in the phases; per column phase `r`, the first destination and the count.
    scratch.rows.clear();
    scratch.rows.extend(
        (0..g.in_h)
            .map(|y| (y, y + g.pad_top))
            .take_while(|&(_, py)| py < rows_read)
            .map(|(y, py)| (y * g.in_w, (py % sh) * sw * sub + (py / sh) * wq)),
    );
    scratch.cols.clear();
    scratch.cols.extend((0..sw.min(x_end)).map(|r| {
        let px = g.pad_left + r;
        (r, (px % sw) * sub + px / sw, (x_end - r).div_ceil(sw))
    }));
    // Stride 2: pairs of input columns split to the two column phases at once; `a` takes
    // the even input columns, `b` the odd ones (offsets from the row's base).
    let (c0, c1) = (g.pad_left / 2, g.pad_left.div_ceil(2));
    let pairs = x_end / 2;
    let (a_at, b_at) = if g.pad_left.is_multiple_of(2) {
        (c0, sub + c1)
    } else {
        (sub + c0, c1)
    };
    let odd_tail = (x_end % 2 == 1).then(|| {
        let px = g.pad_left + x_end - 1;
        (px % 2) * sub + px / 2
    });
    for c in 0..g.channels {
        let plane = &input[c * g.in_plane()..(c + 1) * g.in_plane()];
        // 1. Padded, phase-split copy. Padded row py = y + pad_top goes to phase py % sh,
        //    row py / sh; likewise columns: input columns x ≡ r (mod sw) land in column
        //    phase (pad_left + r) % sw, from column (pad_left + r) / sw on.
        #[cfg(target_arch = "x86_64")]
        let copied = match v4 {
            Some(simd) if sw == 1 => {
                let first = scratch.cols.first().map_or(0, |c| c.1);
                wide16::copy_rows(
                    simd,
                    &mut scratch.phases,
                    plane,
                    &scratch.rows,
                    x_end,
                    first,
                );
                true
            }
            _ => false,
        };
        #[cfg(not(target_arch = "x86_64"))]
        let copied = false;
        for &(at, base_y) in scratch.rows.iter().filter(|_| !copied) {
            let row = &plane[at..at + x_end];
            if sw == 2 {
                let (lo, hi) = scratch.phases.split_at_mut(base_y + b_at.max(a_at));
                let (a, b) = if a_at < b_at {
                    (
                        &mut lo[base_y + a_at..base_y + a_at + pairs],
                        &mut hi[..pairs],
                    )
                } else {
                    (
                        &mut hi[..pairs],
                        &mut lo[base_y + b_at..base_y + b_at + pairs],
                    )
                };
                split_pairs(a, b, &row[..2 * pairs]);
                if let Some(t) = odd_tail {
                    scratch.phases[base_y + t] = row[x_end - 1];
                }
                continue;
            }
            for &(r, first, n) in &scratch.cols {
                let dst = &mut scratch.phases[base_y + first..base_y + first + n];
                if sw == 1 {
                    copy_short(dst, row);
                } else {
                    for (d, &v) in dst.iter_mut().zip(row[r..].iter().step_by(sw)) {
                        *d = v;
                    }
                }
            }
        }
        let wide = &mut scratch.wide[..span];
        let kernel = &weights[c * taps..(c + 1) * taps];
        let out = &mut output[c * g.out_plane()..(c + 1) * g.out_plane()];
        // 2. and 3. in registers for the networks' square kernels: on AVX2 alone the stride-1
        //    ring ([`rows8`]); on AVX-512 each block summed over every kernel row, at stride 1
        //    straight into the output rows (each padded row's taps loaded once for the output
        //    rows that read them where both strides are 1; else where that costs no more
        //    blocks), else (below) into the wide rows, then their valid columns. Each path
        //    returns false (nothing written) on sizes it does not take.
        #[cfg(target_arch = "x86_64")]
        {
            let (phases, shape, b) = (&scratch.phases[..], (g.out_h, g.out_w, wq), bias[c]);
            let k3 = g.k_w == 3;
            let done = v3.is_some_and(|simd| match k3 {
                true => rows8::ring::<3, 10>(simd, out, shape, phases, kernel, b),
                false => rows8::ring::<5, 12>(simd, out, shape, phases, kernel, b),
            }) || ring.is_some_and(|simd| match k3 {
                true => wide16::rows_ring::<3, 9, 18>(simd, out, shape, phases, kernel, b),
                false => wide16::rows_ring::<5, 25, 20>(simd, out, shape, phases, kernel, b),
            }) || direct.is_some_and(|simd| match k3 {
                true => wide16::rows_out::<3, 9, 18>(simd, out, shape, phases, starts, kernel, b),
                false => wide16::rows_out::<5, 25, 20>(simd, out, shape, phases, starts, kernel, b),
            });
            if done {
                continue;
            }
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(simd) = v4 {
            let phases = &scratch.phases[..];
            let done = match (g.k_h, g.k_w) {
                (3, 3) => wide16::channel::<3, 9>(simd, wide, phases, starts, kernel, bias[c]),
                (5, 5) => wide16::channel::<5, 25>(simd, wide, phases, starts, kernel, bias[c]),
                _ => false,
            };
            if done {
                for (oy, dst) in out.chunks_exact_mut(g.out_w).enumerate() {
                    copy_short(dst, &wide[oy * wq..oy * wq + g.out_w]);
                }
                continue;
            }
        }
        // 2. Kernel row by kernel row over the wide output, which starts at the bias; the
        //    last kernel row, 3., writes the valid columns straight to the output.
        wide.fill(bias[c]);
        for ky in 0..g.k_h {
            let w = &kernel[ky * g.k_w..(ky + 1) * g.k_w];
            let row_starts = &starts[ky * g.k_w..(ky + 1) * g.k_w];
            let src = |kx: usize| &scratch.phases[row_starts[kx]..row_starts[kx] + span];
            if ky + 1 == g.k_h && g.k_w == 3 {
                // 3. The valid columns, each the same `o + (w₀·a + w₁·b + w₂·c)` as `row3`'s
                //    (the same bits), without a pass over the wide buffer to copy them out.
                let s = [src(0), src(1), src(2)];
                for (oy, dst) in out.chunks_exact_mut(g.out_w).enumerate() {
                    let at = oy * wq..oy * wq + g.out_w;
                    let taps = [&s[0][at.clone()], &s[1][at.clone()], &s[2][at.clone()]];
                    row3_to(dst, &wide[at], taps, [w[0], w[1], w[2]]);
                }
                break;
            }
            // The AVX-512 rows where the CPU has them, else the rows below; either way the
            // last kernel row's valid columns are copied out after it (3.).
            #[cfg(target_arch = "x86_64")]
            let done = match (v4, g.k_w) {
                (Some(simd), 3) => {
                    wide16::row3(simd, wide, [src(0), src(1), src(2)], [w[0], w[1], w[2]]);
                    true
                }
                (Some(simd), 5) => {
                    let s = [src(0), src(1), src(2), src(3), src(4)];
                    wide16::row5(simd, wide, s, [w[0], w[1], w[2], w[3], w[4]]);
                    true
                }
                _ => false,
            };
            #[cfg(not(target_arch = "x86_64"))]
            let done = false;
            if !done {
                match g.k_w {
                    3 => row3(wide, [src(0), src(1), src(2)], [w[0], w[1], w[2]]),
                    5 => row5(
                        wide,
                        [src(0), src(1), src(2), src(3), src(4)],
                        [w[0], w[1], w[2], w[3], w[4]],
                    ),
                    _ => {
                        for kx in 0..g.k_w {
                            let wk = w[kx];
                            for (o, &v) in wide.iter_mut().zip(src(kx)) {
                                *o += wk * v;
                            }
                        }
                    }
                }
            }
            if ky + 1 == g.k_h {
                // 3. The valid columns.
                for (oy, dst) in out.chunks_exact_mut(g.out_w).enumerate() {
                    copy_short(dst, &wide[oy * wq..oy * wq + g.out_w]);
                }
            }
        }
    }
    true
}

/// Block of the wide buffer's length: it holds whole blocks of 16 values for [`wide16`].
const LANES: usize = 16;

/// The networks' square kernels (3 × 3 and 5 × 5) at stride 1 summed in registers on 8-value
/// blocks, for x86-64 CPUs with AVX2 and without AVX-512 (pulp's `x86::V3`, safe code):
/// [`wide16`]'s `rows_ring` on AVX2's 8 lanes. Each output is the sum of the rows above (the
/// bias, then kernel row after kernel row, each `w₀·t₀ + w₁·t₁ + …` from the left, multiplies
/// and adds apart): the same bits. A block past a row's end computes lanes it does not store.
///
/// Not used at stride 2: written on arrays for the compiler to vectorise, the same sums stayed
/// scalar; each block read from its own `K²` taps, as `rows_out` does, was slower than the
/// wide rows, whose taps are not side by side; and the same ring on the phase split (each
/// padded row's taps loaded once) took 97 µs instead of 82 on the 128 × 128 3 × 3 layer, whose
/// four phase planes (67 KB a channel) leave L1 while a column block walks down them, and
/// gained 3 µs on the 32 × 32 5 × 5 one (docs/benchmarks.md).
#[cfg(target_arch = "x86_64")]
mod rows8 {
    use pulp::x86::V3;
    use pulp::{f32x8, Simd};

    /// Values a block.
    const N: usize = 8;

    /// The 8 values from `win[o..]`.
    #[inline(always)]
    fn at<const W: usize>(win: &[f32; W], o: usize) -> f32x8 {
        let (arrays, _) = pulp::as_arrays::<N, f32>(&win[o..o + N]);
        pulp::cast(arrays[0])
    }

    /// A kernel row's sum over its taps `t` (`t[kx]` the row's values shifted by `kx`), `w`
    /// its weights splat.
    #[inline(always)]
    fn row_sum<const K: usize>(simd: V3, w: &[f32x8; K], t: &[f32x8; K]) -> f32x8 {
        let mut s = simd.mul_f32s(w[0], t[0]);
        for kx in 1..K {
            s = simd.add_f32s(s, simd.mul_f32s(w[kx], t[kx]));
        }
        s
    }

    /// The first `n` values of `v` to `out[o..]`, if they fit.
    #[inline(always)]
    fn store(simd: V3, out: &mut [f32], o: usize, v: f32x8, n: usize) {
        if n == N {
            if let Some(dst) = out.get_mut(o..o + N) {
                dst.copy_from_slice(&pulp::cast::<f32x8, [f32; N]>(v));
            }
        } else if let Some(dst) = out.get_mut(o..o + n) {
            simd.partial_store_f32s(dst, v);
        }
    }

    /// A square `K × K` kernel at stride 1 in both directions, each padded row's taps loaded
    /// once for the `K` output rows that read them: per column block the padded rows in
    /// order, each row's window (`W = 8 + K − 1` values) summed by every kernel row into the
    /// output row it belongs to (`K` sums in registers, one finished and stored per padded
    /// row). Padded row `p` starts at `p · wq`. The caller has checked that every window
    /// lies in `phases` (one outside reads zeros). `false` (nothing done) when the sizes do
    /// not match.
    pub(super) fn ring<const K: usize, const W: usize>(
        simd: V3,
        out: &mut [f32],
        (out_h, out_w, wq): (usize, usize, usize),
        phases: &[f32],
        kernel: &[f32],
        bias: f32,
    ) -> bool {
        if W != N + K - 1 || kernel.len() != K * K || out.len() != out_h * out_w {
            return false;
        }
        simd.vectorize(
            #[inline(always)]
            || {
                let w: [[f32x8; K]; K] = std::array::from_fn(|ky| {
                    std::array::from_fn(|kx| simd.splat_f32s(kernel[ky * K + kx]))
                });
                let (zeros, b) = ([0.0; W], simd.splat_f32s(bias));
                for x in (0..out_w).step_by(N) {
                    let n = (out_w - x).min(N);
                    // `acc[i]`: output row `p + 1 + i − K` while padded row `p` is summed in
                    // (its kernel row `K − 1 − i`); rows outside the output are summed and
                    // dropped.
                    let mut acc = [b; K];
                    for p in 0..out_h + K - 1 {
                        let s = p * wq + x;
                        let win = phases.get(s..s + W).and_then(|v| v.first_chunk::<W>());
                        let win = win.unwrap_or(&zeros);
                        let taps: [f32x8; K] = std::array::from_fn(|kx| at(win, kx));
                        for (i, a) in acc.iter_mut().enumerate() {
                            let t = row_sum::<K>(simd, &w[K - 1 - i], &taps);
                            *a = simd.add_f32s(if i + 1 == K { b } else { *a }, t);
                        }
                        if let Some(oy) = (p + 1).checked_sub(K) {
                            store(simd, out, oy * out_w + x, acc[0], n);
                        }
                        acc = std::array::from_fn(|i| acc[(i + 1) % K]);
                    }
                }
            },
        );
        true
    }
}

/// [`row3`] and [`row5`] on 16-value AVX-512 blocks, in safe code through pulp's `x86::V4`
/// (detected at run time): each value the same multiplies and adds in the same order, so the
/// same bits. The slices hold whole blocks (the wide buffer is padded to [`LANES`]).
#[cfg(target_arch = "x86_64")]
pub(crate) mod wide16 {
    use super::LANES;
    use core::arch::x86_64::{__m512, __m512i};
    use pulp::x86::V4;
    use pulp::{f32x16, Simd};

    /// The 16 values of block `i` of `s`.
    #[inline(always)]
    fn block(s: &[f32], i: usize) -> f32x16 {
        let (arrays, _) = pulp::as_arrays::<LANES, f32>(&s[i * LANES..(i + 1) * LANES]);
        pulp::cast(arrays[0])
    }

    /// One channel's whole wide output for a `K × K` kernel (`T` = `K²` taps starting at
    /// `starts` in `phases`): per block, from the bias, `o + (((w₀·a + w₁·b) + …) + w_{K−1}·z)`
    /// kernel row after kernel row, as [`row3`] and [`row5`] compute it across passes over
    /// the buffer (the same bits), but summed in registers: one store per block instead of
    /// a load and a store per kernel row, and no pass filling the bias. `false` (nothing
    /// done) when the sizes do not match.
    pub(super) fn channel<const K: usize, const T: usize>(
        simd: V4,
        wide: &mut [f32],
        phases: &[f32],
        starts: &[usize],
        kernel: &[f32],
        bias: f32,
    ) -> bool {
        let span = wide.len();
        if K * K != T
            || kernel.len() != T
            || starts.len() != T
            || starts.iter().any(|&s| s + span > phases.len())
        {
            return false;
        }
        let src: [&[f32]; T] = std::array::from_fn(|t| &phases[starts[t]..starts[t] + span]);
        simd.vectorize(
            #[inline(always)]
            || {
                let w: [f32x16; T] = std::array::from_fn(|t| simd.splat_f32s(kernel[t]));
                for (i, o) in wide.chunks_exact_mut(LANES).enumerate() {
                    let mut acc = simd.splat_f32s(bias);
                    for ky in 0..K {
                        let r = ky * K;
                        let mut t = simd.mul_f32s(w[r], block(src[r], i));
                        for kx in 1..K {
                            t = simd.add_f32s(t, simd.mul_f32s(w[r + kx], block(src[r + kx], i)));
                        }
                        acc = simd.add_f32s(acc, t);
                    }
                    o.copy_from_slice(&pulp::cast::<f32x16, [f32; LANES]>(acc));
                }
            },
        );
        true
    }

    /// One channel's output for a `K × K` kernel at column stride 1 (`T` = `K²` taps
    /// starting at `starts` in `phases`, `W` = `LANES + K − 1`), straight into the
    /// channel's output plane `out` (`shape`: `out_h` rows of `out_w` values, `wq` apart in
    /// the phases). Each output is the same sum as [`channel`]'s, kernel row after kernel row
    /// from the bias (the same bits), without the wide buffer and the copy of its valid
    /// columns.
    ///
    /// Per block and kernel row one window of `W` values holds the row's `K` taps (tap `kx`
    /// at `kx`), so the taps' loads need no bounds checks of their own; two blocks are summed
    /// at a time (two independent sums in flight). A row's last block is stored whole where
    /// `out` has room (its lanes past the row land on outputs after it, which the blocks
    /// after it overwrite), masked at the end. The caller has checked that every window
    /// lies in `phases` (a window outside reads zeros). `false` (nothing done, the caller
    /// takes the wide rows) when the sizes do not match.
    pub(super) fn rows_out<const K: usize, const T: usize, const W: usize>(
        simd: V4,
        out: &mut [f32],
        (out_h, out_w, wq): (usize, usize, usize),
        phases: &[f32],
        starts: &[usize],
        kernel: &[f32],
        bias: f32,
    ) -> bool {
        let blocks = out_h * out_w.div_ceil(LANES);
        if K * K != T
            || W != LANES + K - 1
            || kernel.len() != T
            || starts.len() != T
            || out.len() != out_h * out_w
            || blocks == 0
        {
            return false;
        }
        // Where each kernel row's window starts.
        let first: [usize; K] = std::array::from_fn(|ky| starts[ky * K]);
        simd.vectorize(
            #[inline(always)]
            || {
                let w: [f32x16; T] = std::array::from_fn(|t| simd.splat_f32s(kernel[t]));
                let at = |win: &[f32; W], o: usize| -> f32x16 {
                    let (arrays, _) = pulp::as_arrays::<LANES, f32>(&win[o..o + LANES]);
                    pulp::cast(arrays[0])
                };
                let zeros = [0.0; W];
                let across = out_w.div_ceil(LANES);
                // Where block `i` reads (from each window start), writes, and how many.
                let place = |i: usize| {
                    let (oy, x) = (i / across, (i % across) * LANES);
                    (oy * wq + x, oy * out_w + x, (out_w - x).min(LANES))
                };
                for i in (0..blocks).step_by(2) {
                    // An odd last block is summed twice (the same values stored twice).
                    let both = [place(i), place((i + 1).min(blocks - 1))];
                    let mut acc = [simd.splat_f32s(bias); 2];
                    for (ky, &start) in first.iter().enumerate() {
                        let r = ky * K;
                        for (acc, &(p, _, _)) in acc.iter_mut().zip(&both) {
                            let s = start + p;
                            let win = phases.get(s..s + W).and_then(|v| v.first_chunk::<W>());
                            let win = win.unwrap_or(&zeros);
                            let mut t = simd.mul_f32s(w[r], at(win, 0));
                            for kx in 1..K {
                                t = simd.add_f32s(t, simd.mul_f32s(w[r + kx], at(win, kx)));
                            }
                            *acc = simd.add_f32s(*acc, t);
                        }
                    }
                    for (acc, &(_, o, n)) in acc.iter().zip(&both) {
                        if let Some(dst) = out.get_mut(o..o + LANES) {
                            dst.copy_from_slice(&pulp::cast::<f32x16, [f32; LANES]>(*acc));
                        } else if let Some(dst) = out.get_mut(o..o + n) {
                            simd.partial_store_f32s(dst, *acc);
                        }
                    }
                }
            },
        );
        true
    }

    /// [`rows_out`] at stride 1 in both directions, each kernel row's taps loaded once for
    /// the `K` output rows that read them: per column block, the padded rows in order, each
    /// row's `K` taps (one window) summed by every kernel row into the output row it belongs
    /// to (`K` sums in registers, one finished and stored per padded row). Each output is
    /// the same sum as [`rows_out`]'s, kernel row after kernel row from the bias (the same
    /// bits), with `K` loads a block instead of `K²`. Phase row `p` starts at `p · wq`.
    /// `false` when the sizes do not match.
    pub(super) fn rows_ring<const K: usize, const T: usize, const W: usize>(
        simd: V4,
        out: &mut [f32],
        (out_h, out_w, wq): (usize, usize, usize),
        phases: &[f32],
        kernel: &[f32],
        bias: f32,
    ) -> bool {
        if K * K != T
            || W != LANES + K - 1
            || kernel.len() != T
            || out.len() != out_h * out_w
            || out_h == 0
            || out_w == 0
        {
            return false;
        }
        simd.vectorize(
            #[inline(always)]
            || {
                let w: [f32x16; T] = std::array::from_fn(|t| simd.splat_f32s(kernel[t]));
                let at = |win: &[f32; W], o: usize| -> f32x16 {
                    let (arrays, _) = pulp::as_arrays::<LANES, f32>(&win[o..o + LANES]);
                    pulp::cast(arrays[0])
                };
                let (zeros, b) = ([0.0; W], simd.splat_f32s(bias));
                for x in (0..out_w).step_by(LANES) {
                    let n = (out_w - x).min(LANES);
                    // `acc[i]`: output row `p + 1 + i − K` while padded row `p` is summed in
                    // (kernel row `K − 1 − i` of it); rows outside the output are summed and
                    // dropped.
                    let mut acc = [simd.splat_f32s(0.0); K];
                    for p in 0..out_h + K - 1 {
                        let s = p * wq + x;
                        let win = phases.get(s..s + W).and_then(|v| v.first_chunk::<W>());
                        let win = win.unwrap_or(&zeros);
                        let taps: [f32x16; K] = std::array::from_fn(|kx| at(win, kx));
                        for (i, a) in acc.iter_mut().enumerate() {
                            let r = (K - 1 - i) * K;
                            let mut t = simd.mul_f32s(w[r], taps[0]);
                            for kx in 1..K {
                                t = simd.add_f32s(t, simd.mul_f32s(w[r + kx], taps[kx]));
                            }
                            *a = simd.add_f32s(if i + 1 == K { b } else { *a }, t);
                        }
                        if let Some(oy) = (p + 1).checked_sub(K) {
                            let o = oy * out_w + x;
                            if let Some(dst) = out.get_mut(o..o + n) {
                                if n == LANES {
                                    dst.copy_from_slice(&pulp::cast::<f32x16, [f32; LANES]>(
                                        acc[0],
                                    ));
                                } else {
                                    simd.partial_store_f32s(dst, acc[0]);
                                }
                            }
                        }
                        acc = std::array::from_fn(|i| acc[(i + 1) % K]);
                    }
                }
            },
        );
        true
    }

    /// One output block's `K` taps at stride 2 from an input row, the block's windows
    /// ([`super::place_s2`]) held in registers: per tap pair two 16-value loads from the
    /// window's base and one masked permute per tap (the lanes reading outside the row are
    /// zeros).
    pub(crate) struct Taps2<const K: usize> {
        base: [usize; K],
        keep: [[u16; 2]; K],
        idx: [[__m512i; 2]; K],
    }

    impl<const K: usize> Taps2<K> {
        /// The block's windows: `win` holds its `K.div_ceil(2)` pairs.
        #[inline(always)]
        pub(crate) fn new(win: &[super::Window]) -> Self {
            let at = |j: usize| &win[j.min(win.len().saturating_sub(1))];
            Self {
                base: std::array::from_fn(|j| at(j).base),
                keep: std::array::from_fn(|j| at(j).keep),
                idx: std::array::from_fn(|j| [pulp::cast(at(j).even), pulp::cast(at(j).odd)]),
            }
        }

        /// Tap `kx`'s 16 values of `row` (one input row, at least 32 values) for the block.
        #[inline(always)]
        pub(crate) fn row(&self, simd: V4, row: &[f32]) -> [f32x16; K] {
            let mut taps = [simd.splat_f32s(0.0); K];
            for j in 0..K.div_ceil(2) {
                let Some(v) = row.get(self.base[j]..).and_then(|v| v.first_chunk::<32>()) else {
                    continue;
                };
                let (lo, hi) = v.split_at(LANES);
                let lo = pulp::cast::<_, __m512>(*lo.first_chunk().unwrap_or(&[0.0; LANES]));
                let hi = pulp::cast::<_, __m512>(*hi.first_chunk().unwrap_or(&[0.0; LANES]));
                for odd in 0..2 {
                    if let Some(t) = taps.get_mut(2 * j + odd) {
                        let (k, i) = (self.keep[j][odd], self.idx[j][odd]);
                        *t = pulp::cast(simd.avx512f._mm512_maskz_permutex2var_ps(k, lo, i, hi));
                    }
                }
            }
            taps
        }
    }

    /// A whole depthwise convolution for a `K × K` kernel at stride 2 in both directions
    /// (`T` = `K²` taps), read from the input planes where they lie: per output row and
    /// 16-value block, from the bias, `o + (((w₀·a + w₁·b) + …) + w_{K−1}·z)` kernel row after
    /// kernel row, the sum [`channel`] takes over the phase split (the same bits: taps
    /// outside the input are zeros there and here), without the split's copy, the wide rows
    /// and the copy of their valid columns.
    ///
    /// A kernel row's taps for 16 outputs are every other input value from column
    /// `2·ox₀ − pad_left + kx` on: the even and odd lanes of two adjacent 16-value loads (one
    /// permute each), a load pair per two taps. At a row's ends the loads start at the
    /// nearest place inside the row, the permute shifted by the difference and the lanes it
    /// would take from outside the row zeroed (its mask); the windows are placed once per
    /// call ([`super::Window`]). `false` (nothing done, the caller takes the phase split) for
    /// another geometry, rows shorter than two loads (32 values) or mismatched sizes.
    pub(super) fn planes_s2<const K: usize, const T: usize>(
        simd: V4,
        g: &super::Geometry,
        (input, weights, bias): (&[f32], &[f32], &[f32]),
        output: &mut [f32],
        windows: &mut Vec<super::Window>,
    ) -> bool {
        if K * K != T
            || (g.k_h, g.k_w, g.stride_h, g.stride_w) != (K, K, 2, 2)
            || input.len() != g.channels * g.in_plane()
            || weights.len() != g.channels * T
            || bias.len() != g.channels
            || output.len() != g.channels * g.out_plane()
            || g.in_w < 2 * LANES
        {
            return false;
        }
        let (in_w, out_w) = (g.in_w, g.out_w);
        let pairs = K.div_ceil(2);
        super::place_s2(windows, in_w, out_w, K, g.pad_left);
        let windows = &windows[..];
        let (in_h, out_h) = (g.in_h, g.out_h);
        simd.vectorize(
            #[inline(always)]
            || {
                let zero = simd.splat_f32s(0.0);
                for c in 0..g.channels {
                    let plane = &input[c * in_h * in_w..(c + 1) * in_h * in_w];
                    let kernel = &weights[c * T..(c + 1) * T];
                    let out = &mut output[c * out_h * out_w..(c + 1) * out_h * out_w];
                    let w: [f32x16; T] = std::array::from_fn(|t| simd.splat_f32s(kernel[t]));
                    let bias_v = simd.splat_f32s(bias[c]);
                    for (b, win) in windows.chunks_exact(pairs).enumerate() {
                        let x0 = b * LANES;
                        let n = (out_w - x0).min(LANES);
                        // The block's windows, kept in registers across its rows.
                        let taps_of = Taps2::<K>::new(win);
                        // Padded row `p`'s taps (zeros outside the input) and kernel row
                        // `ky`'s sum of them.
                        let taps = |p: usize| {
                            let y = p.checked_sub(g.pad_top).filter(|&y| y < in_h);
                            let row = y.and_then(|y| plane.get(y * in_w..(y + 1) * in_w));
                            row.map_or([zero; K], |row| taps_of.row(simd, row))
                        };
                        let sum = |taps: &[f32x16; K], ky: usize| {
                            let r = ky * K;
                            let mut t = simd.mul_f32s(w[r], taps[0]);
                            for kx in 1..K {
                                t = simd.add_f32s(t, simd.mul_f32s(w[r + kx], taps[kx]));
                            }
                            t
                        };
                        // Each padded row's taps are worked out once for the output rows
                        // that read them: `s[i]` is output row `q − i` while padded rows
                        // `2q` and `2q + 1` are summed in (its kernel rows `2i` and
                        // `2i + 1`); row `q + 1 − live` is then finished. Rows outside the
                        // output are summed and dropped.
                        let live = K.div_ceil(2);
                        let mut s = [zero; K];
                        for q in 0..out_h + live - 1 {
                            for parity in 0..2 {
                                let taps = taps(2 * q + parity);
                                for (i, acc) in s.iter_mut().enumerate().take(live) {
                                    let ky = 2 * i + parity;
                                    if ky < K {
                                        let from = if ky == 0 { bias_v } else { *acc };
                                        *acc = simd.add_f32s(from, sum(&taps, ky));
                                    }
                                }
                            }
                            if let Some(oy) = (q + 1).checked_sub(live).filter(|&y| y < out_h) {
                                let d = &mut out[oy * out_w + x0..oy * out_w + x0 + n];
                                let acc = s[live - 1];
                                if n == LANES {
                                    d.copy_from_slice(&pulp::cast::<f32x16, [f32; LANES]>(acc));
                                } else {
                                    simd.partial_store_f32s(d, acc);
                                }
                            }
                            s = std::array::from_fn(|i| if i == 0 { zero } else { s[i - 1] });
                        }
                    }
                }
            },
        );
        true
    }

    /// Step 1 of [`super::depthwise_rows`] for a column stride of 1: each input row read
    /// (`rows`: its offset in `plane`, its base in `phases`) copied whole to `base + first`,
    /// in blocks of 16, the rest by [`super::copy_short`].
    pub(super) fn copy_rows(
        simd: V4,
        phases: &mut [f32],
        plane: &[f32],
        rows: &[(usize, usize)],
        len: usize,
        first: usize,
    ) {
        simd.vectorize(
            #[inline(always)]
            || {
                for &(at, base) in rows {
                    let (src, dst) = (&plane[at..at + len], &mut phases[base + first..][..len]);
                    let mut d = dst.chunks_exact_mut(LANES);
                    let mut s = src.chunks_exact(LANES);
                    for (d, s) in (&mut d).zip(&mut s) {
                        d.copy_from_slice(s);
                    }
                    super::copy_short(d.into_remainder(), s.remainder());
                }
            },
        );
    }

    /// [`super::row3`]: `o + ((w₀·a + w₁·b) + w₂·c)` per value.
    pub(super) fn row3(simd: V4, wide: &mut [f32], s: [&[f32]; 3], w: [f32; 3]) {
        simd.vectorize(
            #[inline(always)]
            || {
                let w = w.map(|w| simd.splat_f32s(w));
                for (i, o) in wide.chunks_exact_mut(LANES).enumerate() {
                    let t0 = simd.mul_f32s(w[0], block(s[0], i));
                    let t = simd.add_f32s(t0, simd.mul_f32s(w[1], block(s[1], i)));
                    let t = simd.add_f32s(t, simd.mul_f32s(w[2], block(s[2], i)));
                    let v = simd.add_f32s(block(o, 0), t);
                    o.copy_from_slice(&pulp::cast::<f32x16, [f32; LANES]>(v));
                }
            },
        );
    }

    /// [`super::row5`]: `o + ((((w₀·a + w₁·b) + w₂·c) + w₃·d) + w₄·e)` per value.
    pub(super) fn row5(simd: V4, wide: &mut [f32], s: [&[f32]; 5], w: [f32; 5]) {
        simd.vectorize(
            #[inline(always)]
            || {
                let w = w.map(|w| simd.splat_f32s(w));
                for (i, o) in wide.chunks_exact_mut(LANES).enumerate() {
                    let mut t = simd.mul_f32s(w[0], block(s[0], i));
                    for k in 1..5 {
                        t = simd.add_f32s(t, simd.mul_f32s(w[k], block(s[k], i)));
                    }
                    let v = simd.add_f32s(block(o, 0), t);
                    o.copy_from_slice(&pulp::cast::<f32x16, [f32; LANES]>(v));
                }
            },
        );
    }
}

/// `wide[i] += w₀·s₀[i] + w₁·s₁[i] + w₂·s₂[i]` (one kernel row of three taps; the zipped
/// slice iterators let the compiler drop the bounds checks and vectorise).
#[inline(always)] // into each of `depthwise`' clones
fn row3(wide: &mut [f32], s: [&[f32]; 3], w: [f32; 3]) {
    for (((o, &a), &b), &c) in wide.iter_mut().zip(s[0]).zip(s[1]).zip(s[2]) {
        *o += w[0] * a + w[1] * b + w[2] * c;
    }
}

/// `dst[i] = acc[i] + (w₀·s₀[i] + w₁·s₁[i] + w₂·s₂[i])`: [`row3`]'s sum for one output row,
/// stored apart from the accumulator.
#[inline(always)]
fn row3_to(dst: &mut [f32], acc: &[f32], s: [&[f32]; 3], w: [f32; 3]) {
    let it = dst.iter_mut().zip(acc).zip(s[0]).zip(s[1]).zip(s[2]);
    for ((((d, &o), &a), &b), &c) in it {
        *d = o + (w[0] * a + w[1] * b + w[2] * c);
    }
}

/// The even values of `row` into `a` and the odd ones into `b` (`row` holds `2·a.len()`
/// values, `b` as long as `a`), 16 values at a time through arrays so that the compiler
/// turns each block into shuffles (AVX2 / AVX-512 permutes, NEON's `uzp`): pair by pair it
/// stayed scalar, about half of the kernel's own time (`perf`, 7096f42).
#[inline(always)]
fn split_pairs(a: &mut [f32], b: &mut [f32], row: &[f32]) {
    let mut ac = a.chunks_exact_mut(8);
    let mut bc = b.chunks_exact_mut(8);
    let mut rc = row.chunks_exact(16);
    for ((a8, b8), r) in (&mut ac).zip(&mut bc).zip(&mut rc) {
        let mut v = [0.0f32; 16];
        v.copy_from_slice(r);
        let even: [f32; 8] = std::array::from_fn(|i| v[2 * i]);
        let odd: [f32; 8] = std::array::from_fn(|i| v[2 * i + 1]);
        a8.copy_from_slice(&even);
        b8.copy_from_slice(&odd);
    }
    let rest = ac.into_remainder().iter_mut().zip(bc.into_remainder());
    for ((a, b), p) in rest.zip(rc.remainder().chunks_exact(2)) {
        *a = p[0];
        *b = p[1];
    }
}

/// `dst.copy_from_slice(src)` for the short rows of the networks' feature maps and tiles (8
/// to 256 values), in 8-value blocks the compiler keeps in registers: through
/// `copy_from_slice` each row was a call to the C library's `memmove`, whose call overhead
/// on rows this short was 5–8 % of a backbone pass (`perf`).
#[inline(always)]
pub(crate) fn copy_short(dst: &mut [f32], src: &[f32]) {
    let mut d = dst.chunks_exact_mut(8);
    let mut s = src.chunks_exact(8);
    for (d, s) in (&mut d).zip(&mut s) {
        let mut v = [0.0f32; 8];
        v.copy_from_slice(s);
        d.copy_from_slice(&v);
    }
    for (d, &s) in d.into_remainder().iter_mut().zip(s.remainder()) {
        *d = s;
    }
}

/// [`row3`] for a kernel row of five taps.
#[inline(always)]
fn row5(wide: &mut [f32], s: [&[f32]; 5], w: [f32; 5]) {
    let taps = wide
        .iter_mut()
        .zip(s[0])
        .zip(s[1])
        .zip(s[2])
        .zip(s[3])
        .zip(s[4]);
    for (((((o, &a), &b), &c), &d), &e) in taps {
        *o += w[0] * a + w[1] * b + w[2] * c + w[3] * d + w[4] * e;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Straightforward depthwise convolution, zero padding.
    fn naive(g: &Geometry, input: &[f32], weights: &[f32], bias: &[f32]) -> Vec<f32> {
        let mut out = vec![0.0; g.channels * g.out_plane()];
        for c in 0..g.channels {
            for oy in 0..g.out_h {
                for ox in 0..g.out_w {
                    let mut s = f64::from(bias[c]);
                    for ky in 0..g.k_h {
                        for kx in 0..g.k_w {
                            let y = (oy * g.stride_h + ky) as isize - g.pad_top as isize;
                            let x = (ox * g.stride_w + kx) as isize - g.pad_left as isize;
                            if y < 0 || x < 0 || y >= g.in_h as isize || x >= g.in_w as isize {
                                continue;
                            }
                            let v = input[c * g.in_plane() + y as usize * g.in_w + x as usize];
                            let k = weights[c * g.k_h * g.k_w + ky * g.k_w + kx];
                            s += f64::from(v) * f64::from(k);
                        }
                    }
                    out[c * g.out_plane() + oy * g.out_w + ox] = s as f32;
                }
            }
        }
        out
    }

    /// Largest `|depthwise − naive|` over the outputs of `g` (the kernel must accept the
    /// slices; every output is written, the buffer starting as NaN).
    fn worst_against_naive(
        g: &Geometry,
        input: &[f32],
        weights: &[f32],
        bias: &[f32],
        scratch: &mut Scratch,
    ) -> f32 {
        let want = naive(g, input, weights, bias);
        let mut got = vec![f32::NAN; want.len()];
        assert!(depthwise(g, input, weights, bias, &mut got, scratch));
        got.iter()
            .zip(&want)
            .map(|(a, b)| (a - b).abs())
            .fold(
                0.0f32,
                |m, d| if d.is_nan() { f32::INFINITY } else { m.max(d) },
            )
    }

    /// Deterministic values in [-1, 1).
    fn values(n: usize, seed: u32) -> Vec<f32> {
        let mut s = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (s >> 8) as f32 / (1u32 << 23) as f32 - 1.0
            })
            .collect()
    }

    /// One case's input, weights and bias, and its outputs without the register paths.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))] // read by the x86-64 checks
    struct Both {
        input: Vec<f32>,
        weights: Vec<f32>,
        bias: Vec<f32>,
        narrow: Vec<f32>,
    }

    /// A case of `g` from `seed`, run with the register paths allowed (`wide` scratch) and
    /// not (`narrow`): the two outputs must be the same bits.
    fn both_paths(g: &Geometry, seed: u32, wide: &mut Scratch, narrow: &mut Scratch) -> Both {
        let c = g.channels;
        let input = values(c * g.in_plane(), seed);
        let weights = values(c * g.k_h * g.k_w, seed + 1000);
        let bias = values(c, seed + 2000);
        let mut a = vec![f32::NAN; c * g.out_plane()];
        let mut b = vec![f32::NAN; c * g.out_plane()];
        let d = |o: &mut Vec<f32>, s: &mut Scratch, on: bool| {
            depthwise_rows(g, &input, &weights, &bias, o, s, on)
        };
        assert!(d(&mut a, wide, true) && d(&mut b, narrow, false));
        let same = a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(same, "{g:?}: the register paths' bits differ");
        Both {
            input,
            weights,
            bias,
            narrow: b,
        }
    }

    #[test]
    fn matches_a_naive_reference_on_odd_sizes_strides_kernels_and_padding() {
        let mut scratch = Scratch::default();
        let mut cases = 0;
        for &(h, w) in &[(7, 9), (13, 5), (16, 16), (1, 6), (5, 1), (11, 11)] {
            for &k in &[1usize, 3, 5] {
                for &s in &[1, 2, 3] {
                    for &(pt, pb, pl, pr) in &[
                        (0, 0, 0, 0),
                        (k / 2, k / 2, k / 2, k / 2),
                        (k / 2, 0, 0, k / 2),
                        (k - 1, k - 1, k.saturating_sub(2), k - 1),
                    ] {
                        let Some(g) = Geometry::new(3, (h, w), (k, k), (s, s), (pt, pb), (pl, pr))
                        else {
                            continue;
                        };
                        let input = values(3 * h * w, cases);
                        let weights = values(3 * k * k, cases + 1000);
                        let bias = values(3, cases + 2000);
                        let worst = worst_against_naive(&g, &input, &weights, &bias, &mut scratch);
                        assert!(worst <= 1e-5, "{g:?}: {worst}");
                        cases += 1;
                    }
                }
            }
        }
        // Every size, kernel and stride with at least the unpadded and "same" padding,
        // minus those a 1-wide input cannot take.
        assert!(cases > 150, "{cases} cases");
    }

    /// The AVX-512 rows (where the CPU has them) against the AVX2 / baseline rows: the same
    /// bits on NanoTrack's shapes and ragged ones, one scratch reused across shapes (as the
    /// networks do). On a CPU without AVX-512 both runs take the same rows.
    #[test]
    fn the_wide_rows_give_the_narrow_rows_bits() {
        let (mut wide, mut narrow) = (Scratch::default(), Scratch::default());
        // (channels, side, kernel height, kernel width, stride): the square kernels take the
        // in-register blocks (at stride 1 straight to the output rows where that costs no
        // more blocks), the others the AVX-512 rows of 3 and 5 taps.
        for (case, &(c, n, kh, k, s)) in [
            (3usize, 96usize, 3usize, 3usize, 2usize),
            (5, 24, 3, 3, 1),
            (4, 24, 5, 5, 2),
            (7, 12, 5, 5, 1),
            (2, 11, 5, 5, 1),
            (3, 9, 3, 3, 1),
            (2, 3, 3, 3, 1),
            (3, 17, 5, 5, 2),
            (2, 1, 3, 3, 1),
            (3, 16, 1, 5, 1),
            (2, 13, 5, 3, 2),
            // Straight to the output rows: one block a row, two a row, an odd count.
            (2, 16, 5, 5, 1),
            (1, 32, 3, 3, 1),
            (3, 7, 5, 5, 1),
        ]
        .iter()
        .enumerate()
        {
            let cases = case as u32;
            let (ph, p) = (kh / 2, k / 2);
            let Some(g) = Geometry::new(c, (n, n), (kh, k), (s, s), (ph, ph), (p, p)) else {
                panic!("valid geometry refused")
            };
            // The same bits either way, every output written (the buffers start as NaN).
            let b = both_paths(&g, cases, &mut wide, &mut narrow).narrow;
            assert!(
                b.iter().all(|v| v.is_finite()),
                "{g:?}: an output not written"
            );
        }
    }

    /// The stride-2 planes read in place ([`wide16::planes_s2`], where the CPU has AVX-512)
    /// against the phase split's narrow rows: the same bits at every padding a kernel takes,
    /// on sizes whose rows take one block or several, end mid-block, or are shorter than the
    /// kernel's reach (loads before a row's start, past its end, rows of padding).
    #[test]
    fn the_stride_2_planes_give_the_phase_split_bits() {
        let (mut wide, mut narrow) = (Scratch::default(), Scratch::default());
        let mut cases = 0u32;
        #[cfg_attr(not(target_arch = "x86_64"), allow(unused_mut))] // counted on AVX-512
        let mut in_place = 0usize;
        let sizes = [
            (128, 128),
            (64, 64),
            (32, 32),
            (24, 24),
            (16, 16),
            (19, 21),
            (33, 47),
            (5, 70),
            (3, 2),
        ];
        for &(h, w) in &sizes {
            for &k in &[3usize, 5] {
                for &(pt, pb, pl, pr) in &[
                    (k / 2, k / 2, k / 2, k / 2),
                    (0, 0, 0, 0),
                    (k - 1, k - 1, k - 1, k - 1),
                    (1, 0, k - 1, 0),
                ] {
                    let g = Geometry::new(2, (h, w), (k, k), (2, 2), (pt, pb), (pl, pr));
                    let Some(g) = g else {
                        continue;
                    };
                    #[cfg_attr(not(target_arch = "x86_64"), allow(unused_variables))]
                    let both = both_paths(&g, cases, &mut wide, &mut narrow);
                    // The rows of 32 values or more did take the in-place path.
                    #[cfg(target_arch = "x86_64")]
                    if let Some(simd) = pulp::x86::V4::try_new() {
                        let data = (&both.input[..], &both.weights[..], &both.bias[..]);
                        let mut b = both.narrow;
                        let (out, win) = (&mut b[..], &mut wide.windows);
                        let ran = match k {
                            3 => wide16::planes_s2::<3, 9>(simd, &g, data, out, win),
                            _ => wide16::planes_s2::<5, 25>(simd, &g, data, out, win),
                        };
                        assert_eq!(ran, w >= 2 * LANES, "{g:?}");
                        in_place += usize::from(ran);
                    }
                    cases += 1;
                }
            }
        }
        assert!(cases >= 50, "{cases} cases");
        #[cfg(target_arch = "x86_64")]
        if pulp::x86::V4::try_new().is_some() {
            assert!(in_place >= 30, "{in_place} shapes in place");
        }
        let _ = in_place;
    }

    /// The stride-1 rows that load each padded row's taps once ([`wide16::rows_ring`] where
    /// the CPU has AVX-512, [`rows8::ring`] where it has AVX2 only) against the narrow rows:
    /// the same bits at every padding a kernel takes, on NanoTrack's 16 × 16 and 32 × 32 maps
    /// and on rows that end mid-block, take several blocks, or are shorter than the kernel
    /// (rows and columns of padding only).
    #[test]
    fn the_stride_1_ring_gives_the_narrow_rows_bits() {
        let (mut wide, mut narrow) = (Scratch::default(), Scratch::default());
        let mut cases = 0u32;
        #[cfg_attr(not(target_arch = "x86_64"), allow(unused_mut))] // counted with AVX2
        let mut avx2 = 0usize;
        let sizes = [
            (16, 16),
            (32, 32),
            (8, 8),
            (12, 12),
            (17, 33),
            (5, 70),
            (40, 3),
            (3, 2),
            (1, 1),
        ];
        for &(h, w) in &sizes {
            for &k in &[3usize, 5] {
                for &(pt, pb, pl, pr) in &[
                    (k / 2, k / 2, k / 2, k / 2),
                    (0, 0, 0, 0),
                    (k - 1, k - 1, k - 1, k - 1),
                    (1, 0, k - 1, 0),
                    (0, k - 1, 0, 1),
                ] {
                    let g = Geometry::new(3, (h, w), (k, k), (1, 1), (pt, pb), (pl, pr));
                    let Some(g) = g else {
                        continue;
                    };
                    #[cfg_attr(not(target_arch = "x86_64"), allow(unused_variables))]
                    let both = both_paths(&g, cases, &mut wide, &mut narrow);
                    // The AVX2 ring (which the CPUs without AVX-512 take) on the first
                    // channel's padded plane, called itself, so that it cannot pass untried.
                    #[cfg(target_arch = "x86_64")]
                    if let Some(simd) = pulp::x86::V3::try_new() {
                        let Both {
                            input,
                            weights,
                            bias,
                            narrow: b,
                        } = both;
                        let (hq, wq) = (g.phase_h(), g.phase_w());
                        let mut phases = vec![0.0; hq * wq + 16];
                        for (y, row) in input[..h * w].chunks_exact(w).enumerate() {
                            for (x, &v) in row.iter().enumerate() {
                                if y + pt < hq && x + pl < wq {
                                    phases[(y + pt) * wq + x + pl] = v;
                                }
                            }
                        }
                        let mut c = vec![f32::NAN; g.out_plane()];
                        let (shape, kernel) = ((g.out_h, g.out_w, wq), &weights[..k * k]);
                        let ran = match k {
                            3 => {
                                rows8::ring::<3, 10>(simd, &mut c, shape, &phases, kernel, bias[0])
                            }
                            _ => {
                                rows8::ring::<5, 12>(simd, &mut c, shape, &phases, kernel, bias[0])
                            }
                        };
                        let same = c.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits());
                        assert!(ran && same, "{g:?}: the AVX2 ring's bits differ");
                        avx2 += 1;
                    }
                    cases += 1;
                }
            }
        }
        assert!(cases >= 60, "{cases} cases");
        #[cfg(target_arch = "x86_64")]
        if pulp::x86::V3::try_new().is_some() {
            assert_eq!(avx2, cases as usize, "the AVX2 ring ran on every shape");
        }
        let _ = avx2;
    }

    #[test]
    fn a_rectangular_kernel_and_mixed_strides_match_the_reference() {
        let g = Geometry::new(2, (9, 12), (3, 5), (2, 1), (1, 1), (2, 2));
        let Some(g) = g else {
            panic!("valid geometry refused")
        };
        let input = values(2 * 9 * 12, 7);
        let weights = values(2 * 15, 8);
        let bias = [0.25, -0.5];
        let worst = worst_against_naive(&g, &input, &weights, &bias, &mut Scratch::default());
        assert!(worst <= 1e-5, "{worst}");
    }

    #[test]
    fn wrong_lengths_and_impossible_geometries_are_refused() {
        assert!(Geometry::new(0, (4, 4), (3, 3), (1, 1), (1, 1), (1, 1)).is_none());
        assert!(Geometry::new(1, (2, 2), (5, 5), (1, 1), (0, 0), (0, 0)).is_none());
        assert!(Geometry::new(1, (4, 4), (3, 3), (0, 1), (1, 1), (1, 1)).is_none());
        assert!(Geometry::new(1, (4, 4), (3, 3), (1, 1), (3, 0), (1, 1)).is_none());
        let Some(g) = Geometry::new(1, (4, 4), (3, 3), (1, 1), (1, 1), (1, 1)) else {
            panic!("valid geometry refused")
        };
        let mut out = vec![7.0; 16];
        let mut s = Scratch::default();
        assert!(!depthwise(
            &g,
            &[0.0; 15],
            &[0.0; 9],
            &[0.0],
            &mut out,
            &mut s
        ));
        assert!(!depthwise(
            &g,
            &[0.0; 16],
            &[0.0; 8],
            &[0.0],
            &mut out,
            &mut s
        ));
        assert!(!depthwise(&g, &[0.0; 16], &[0.0; 9], &[], &mut out, &mut s));
        assert!(out.iter().all(|&v| v == 7.0));
    }
}
