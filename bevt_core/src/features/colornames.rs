//! Colour names ("CN", Danelljan et al., CVPR 2014; van de Weijer et al., IEEE TIP 2009):
//! the learned RGB → colour-name mapping `w2crs`, 10 channels per pixel, averaged per
//! feature cell.
//!
//! The table (32768 colour bins × 10 channels, little-endian `f32`, row-major) is embedded in
//! the library (`bevt_core/data/colornames/`, provenance and licence in README.md) and decoded
//! once, on first use. Row of an 8-bit pixel `(R, G, B)`:
//! `⌊R/8⌋ + 32·⌊G/8⌋ + 1024·⌊B/8⌋` (MATLAB `im2c`'s index, 0-based).
//!
//! Colour names need colour: a one-plane (mono8) patch has no colour-name channels; the
//! extractor then leaves the group out (see [`super::hog::Hog`]).

use super::hog::floor_small;
use crate::image::Patch;
use std::sync::OnceLock;

/// Number of colour-name channels.
pub const CN_CHANNELS: usize = 10;
/// Number of colour bins (32 levels per RGB component).
pub const CN_BINS: usize = 32 * 32 * 32;
/// Width of one colour bin per component, in 8-bit levels.
const BIN_WIDTH: f32 = 8.0;
/// Largest bin index per component.
const MAX_LEVEL: f32 = 31.0;

/// The embedded table, `CN_BINS × CN_CHANNELS` little-endian `f32`.
static TABLE_BYTES: &[u8] = include_bytes!("../../data/colornames/w2crs_32768x10_f32le.bin");
const _: () = assert!(TABLE_BYTES.len() == CN_BINS * CN_CHANNELS * 4);

static TABLE: OnceLock<Vec<[f32; CN_CHANNELS]>> = OnceLock::new();

/// The decoded table: row `i` holds the 10 channel values of colour bin `i`.
pub fn table() -> &'static [[f32; CN_CHANNELS]] {
    TABLE.get_or_init(|| {
        TABLE_BYTES
            .chunks_exact(CN_CHANNELS * 4)
            .map(|row| {
                let mut v = [0.0f32; CN_CHANNELS];
                for (o, b) in v.iter_mut().zip(row.chunks_exact(4)) {
                    *o = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                }
                v
            })
            .collect()
    })
}

/// Table row of a pixel with components in 0..=255 (non-integer values from resampling are
/// floored into their bin; out-of-range values are clamped).
#[inline]
pub fn bin_index(r: f32, g: f32, b: f32) -> usize {
    bin_code(r, g, b) as usize
}

/// [`bin_index`] as `u32`, through `i32` conversions (which vectorise; the clamped values
/// convert alike).
#[inline(always)]
fn bin_code(r: f32, g: f32, b: f32) -> u32 {
    // `(v / 8).clamp(0, 31) as i32` (NaN → 0) as selects (`NaN > 0` is false), which map to
    // vector max/min; the division by a power of two is the exact product, and the floor of
    // a value in [0, 31] avoids the saturating conversion (see `floor_small`).
    let q = |v: f32| {
        let v = v * (1.0 / BIN_WIDTH);
        let v = if v > 0.0 { v } else { 0.0 };
        floor_small(if v < MAX_LEVEL { v } else { MAX_LEVEL })
    };
    q(r) + 32 * q(g) + 1024 * q(b)
}

/// The table indices of one row (a loop that vectorises).
fn row_codes(pr: &[f32], pg: &[f32], pb: &[f32], codes: &mut [u32]) {
    for (((c, &r), &g), &b) in codes.iter_mut().zip(pr).zip(pg).zip(pb) {
        *c = bin_code(r, g, b);
    }
}

/// Writes the cell-mean colour names of a three-plane `patch` into `out`
/// (`CN_CHANNELS` channel-major maps of `rows × cols` cells, each `cell × cell` pixels).
/// Does nothing for a one-plane patch (the caller does not allocate the group then).
pub fn cell_colornames(patch: &Patch, cell: usize, rows: usize, cols: usize, out: &mut [f32]) {
    cell_colornames_with(patch, cell, rows, cols, out, &mut Scratch::default());
}

/// Reusable buffers of [`cell_colornames_with`].
#[derive(Debug, Clone, Default)]
pub struct Scratch {
    /// Colour-name table indices of one patch row.
    codes: Vec<u32>,
    /// One row of cells' channel sums, cell-major.
    acc: Vec<[f32; CN_CHANNELS]>,
}

/// [`cell_colornames`] with a caller-owned scratch buffer (no allocation once it has grown
/// to a patch row).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
pub fn cell_colornames_with(
    patch: &Patch,
    cell: usize,
    rows: usize,
    cols: usize,
    out: &mut [f32],
    scratch: &mut Scratch,
) {
    let nb = rows * cols;
    if patch.planes < 3 || out.len() < CN_CHANNELS * nb || cell == 0 {
        return;
    }
    let out = &mut out[..CN_CHANNELS * nb];
    let t = table();
    let side = patch.side;
    let n = side * side;
    let width = (cols * cell).min(side);
    let inv = 1.0 / (cell * cell) as f32;
    // One row of cells' sums, cell-major (`acc[cx][d]`), added to pixel row by pixel row in
    // the order the output maps took them (from +0), then written to the channel-major maps
    // once per row of cells instead of once per pixel row.
    let Scratch { codes, acc } = scratch;
    acc.resize(cols, [0.0; CN_CHANNELS]);
    for cy in 0..rows {
        acc.iter_mut().for_each(|a| *a = [0.0; CN_CHANNELS]);
        for r in cy * cell..((cy + 1) * cell).min(side) {
            let i = r * side;
            let (pr, pg, pb) = (
                &patch.data[i..i + width],
                &patch.data[n + i..n + i + width],
                &patch.data[2 * n + i..2 * n + i + width],
            );
            // The row's table indices first, in one vectorisable pass.
            codes.resize(width, 0);
            row_codes(pr, pg, pb, codes);
            for cx in 0..cols {
                let span = cx * cell..((cx + 1) * cell).min(width);
                let mut sum = [0.0f32; CN_CHANNELS];
                for &code in &codes[span] {
                    let row = &t[code as usize];
                    for (s, v) in sum.iter_mut().zip(row) {
                        *s += v;
                    }
                }
                for (a, s) in acc[cx].iter_mut().zip(&sum) {
                    *a += s * inv;
                }
            }
        }
        for (d, plane) in out.chunks_exact_mut(nb).enumerate() {
            let dst = &mut plane[cy * cols..(cy + 1) * cols];
            for (o, a) in dst.iter_mut().zip(acc.iter()) {
                *o = a[d];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bin_codes_equal_the_clamped_conversion() {
        // The index as it was computed with a clamp and a float-to-int conversion.
        let reference = |r: f32, g: f32, b: f32| {
            let q = |v: f32| (v / BIN_WIDTH).clamp(0.0, MAX_LEVEL) as i32;
            (q(r) + 32 * q(g) + 1024 * q(b)) as u32
        };
        let mut vals: Vec<f32> = (0..=256).map(|i| i as f32).collect();
        vals.extend((0..=256).map(|i| i as f32 - 1e-3));
        vals.extend([
            -1.0,
            -0.0,
            300.0,
            1e9,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ]);
        let mut seed = 5u32;
        for _ in 0..20_000 {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            vals.push((seed >> 8) as f32 / (1u32 << 24) as f32 * 255.0);
        }
        let n = vals.len();
        let (r, g, b): (Vec<f32>, Vec<f32>, Vec<f32>) = (0..n)
            .map(|i| (vals[i], vals[(i * 7 + 3) % n], vals[(i * 13 + 5) % n]))
            .fold((vec![], vec![], vec![]), |mut acc, (x, y, z)| {
                acc.0.push(x);
                acc.1.push(y);
                acc.2.push(z);
                acc
            });
        let mut codes = vec![0u32; n];
        row_codes(&r, &g, &b, &mut codes);
        for i in 0..n {
            assert_eq!(
                codes[i],
                reference(r[i], g[i], b[i]),
                "{} {} {}",
                r[i],
                g[i],
                b[i]
            );
        }
    }

    /// Test values from the table's README (`shared/models/colornames/README.md`).
    const ROWS: [(usize, [f32; CN_CHANNELS]); 5] = [
        (
            0,
            [
                0.459748, 0.014802, 0.044289, -0.028193, 0.001151, -0.005015, 0.345216, 0.018362,
                0.239939, 0.168897,
            ],
        ),
        (
            1,
            [
                0.471574, 0.021424, 0.041444, -0.030215, 0.001900, -0.002926, 0.328748, 0.008206,
                0.250198, 0.170067,
            ],
        ),
        (
            32,
            [
                0.451894, 0.016535, 0.061726, -0.027316, 0.001230, -0.004132, 0.325531, 0.027836,
                0.228676, 0.169587,
            ],
        ),
        (
            1024,
            [
                0.461554, 0.016194, 0.041011, -0.030696, 0.001790, -0.003599, 0.342789, 0.010131,
                0.246446, 0.169749,
            ],
        ),
        (
            32767,
            [
                0.008778, -0.015645, 0.004769, 0.011785, -0.541989, 0.315051, 0.000205, -0.020282,
                0.000212, -0.346748,
            ],
        ),
    ];
    const COLUMN_MEANS: [f32; CN_CHANNELS] = [
        -0.123290, 0.002396, 0.154218, -0.055229, 0.021018, -0.041213, 0.075624, 0.039053,
        -0.112125, 0.072395,
    ];

    #[test]
    fn table_rows_match_the_published_test_values() {
        let t = table();
        assert_eq!(t.len(), CN_BINS);
        for (i, want) in ROWS {
            for (g, w) in t[i].iter().zip(want) {
                assert!((g - w).abs() < 1e-6, "row {i}: {:?}", t[i]);
            }
        }
        for (d, want) in COLUMN_MEANS.iter().enumerate() {
            let m = t.iter().map(|r| r[d] as f64).sum::<f64>() / CN_BINS as f64;
            assert!((m as f32 - want).abs() < 1e-5, "column {d}: {m}");
        }
    }

    #[test]
    fn index_formula_follows_im2c() {
        assert_eq!(bin_index(0.0, 0.0, 0.0), 0);
        assert_eq!(bin_index(8.0, 0.0, 0.0), 1);
        assert_eq!(bin_index(7.9, 0.0, 0.0), 0);
        assert_eq!(bin_index(0.0, 8.0, 0.0), 32);
        assert_eq!(bin_index(0.0, 0.0, 8.0), 1024);
        assert_eq!(bin_index(255.0, 255.0, 255.0), 32767);
        assert_eq!(bin_index(300.0, -4.0, 255.0), 31 + 31 * 1024);
    }

    #[test]
    fn cells_average_the_table_rows_of_their_pixels() {
        // 4×4 patch, cell 2: left half white (row 32767), right half black (row 0); the
        // top-right cell is half white, half black.
        let mut p = Patch::new(4, 3);
        let n = 16;
        for r in 0..4 {
            for c in 0..4 {
                let white = c < 2 || (r < 2 && c == 2);
                for pl in 0..3 {
                    p.data[pl * n + r * 4 + c] = if white { 255.0 } else { 0.0 };
                }
            }
        }
        let mut out = vec![0.0; CN_CHANNELS * 4];
        cell_colornames(&p, 2, 2, 2, &mut out);
        let t = table();
        for d in 0..CN_CHANNELS {
            let (w, b) = (t[32767][d], t[0][d]);
            let want = [w, 0.5 * (w + b), w, b];
            for (k, want) in want.iter().enumerate() {
                assert!((out[d * 4 + k] - want).abs() < 1e-6, "{d} {k}");
            }
        }
    }

    #[test]
    fn a_grey_patch_has_no_colour_names() {
        let mut p = Patch::new(4, 1);
        p.data.iter_mut().for_each(|v| *v = 100.0);
        let mut out = vec![7.0; CN_CHANNELS * 4];
        cell_colornames(&p, 2, 2, 2, &mut out);
        assert!(out.iter().all(|&v| v == 7.0));
    }
}
