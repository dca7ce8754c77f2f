//! Grayscale cell feature: mean luminance of each cell, scaled to [−0.5, 0.5].

use crate::image::Patch;

/// ITU-R BT.601 luma weights for R, G, B.
const LUMA: [f32; 3] = [0.299, 0.587, 0.114];

/// Writes the mean luminance of each `cell × cell` block of `patch`, `/255 − 0.5`, into
/// `out` (row-major `rows × cols`).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
pub fn cell_gray(patch: &Patch, cell: usize, rows: usize, cols: usize, out: &mut [f32]) {
    let out = &mut out[..rows * cols];
    out.iter_mut().for_each(|v| *v = 0.0);
    let side = patch.side;
    let n = side * side;
    let width = cols * cell;
    let inv = 1.0 / (255.0 * (cell * cell) as f32);
    for r in 0..rows * cell {
        let orow = &mut out[(r / cell) * cols..(r / cell + 1) * cols];
        let i = r * side;
        if patch.planes == 3 {
            let (pr, pg, pb) = (
                &patch.data[i..i + width],
                &patch.data[n + i..n + i + width],
                &patch.data[2 * n + i..2 * n + i + width],
            );
            if cell == 4 {
                // The default cell as a constant: the same sums, which then vectorise
                // across the cells.
                luma_row::<4>(orow, [pr, pg, pb]);
                continue;
            }
            for (k, o) in orow.iter_mut().enumerate() {
                let span = k * cell..(k + 1) * cell;
                let (sr, sg, sb): (f32, f32, f32) = (
                    pr[span.clone()].iter().sum(),
                    pg[span.clone()].iter().sum(),
                    pb[span].iter().sum(),
                );
                *o += LUMA[0] * sr + LUMA[1] * sg + LUMA[2] * sb;
            }
        } else {
            for (o, chunk) in orow
                .iter_mut()
                .zip(patch.data[i..i + width].chunks_exact(cell))
            {
                *o += chunk.iter().sum::<f32>();
            }
        }
    }
    for v in out.iter_mut() {
        *v = *v * inv - 0.5;
    }
}

/// One pixel row's luma sums added into its row of cells, for cells of `C` pixels: per cell
/// each plane's `C` values summed as `Iterator::sum` does, then `+= Σ luma · sum`, as the
/// loop over any cell size does.
#[inline(always)] // into each clone of `cell_gray`
fn luma_row<const C: usize>(orow: &mut [f32], planes: [&[f32]; 3]) {
    let [pr, pg, pb] = planes.map(|p| p.chunks_exact(C));
    for (((o, r), g), b) in orow.iter_mut().zip(pr).zip(pg).zip(pb) {
        let (sr, sg, sb): (f32, f32, f32) = (r.iter().sum(), g.iter().sum(), b.iter().sum());
        *o += LUMA[0] * sr + LUMA[1] * sg + LUMA[2] * sb;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn white_patch_gives_half_and_black_gives_minus_half() {
        let mut p = Patch::new(8, 1);
        p.data.iter_mut().for_each(|v| *v = 255.0);
        let mut out = vec![0.0; 4];
        cell_gray(&p, 4, 2, 2, &mut out);
        assert!(out.iter().all(|v| (v - 0.5).abs() < 1e-5));
        let p = Patch::new(8, 3);
        cell_gray(&p, 4, 2, 2, &mut out);
        assert!(out.iter().all(|v| (v + 0.5).abs() < 1e-5));
    }

    #[test]
    fn each_cell_averages_its_own_pixels() {
        let mut p = Patch::new(4, 3);
        // Left half red 255 (luma 76.2), right half black; cell 2 → 2x2 cells.
        for r in 0..4 {
            for c in 0..2 {
                p.data[r * 4 + c] = 255.0;
            }
        }
        let mut out = vec![0.0; 4];
        cell_gray(&p, 2, 2, 2, &mut out);
        let red = 0.299 - 0.5;
        for (v, want) in out.iter().zip([red, -0.5, red, -0.5]) {
            assert!((v - want).abs() < 1e-5, "{out:?}");
        }
    }

    #[test]
    fn cells_of_four_give_the_any_size_loops_bits() {
        // A patch with fractional values (a bilinear crop's) and a margin past the cells.
        let (side, cell, rows, cols) = (27, 4, 6, 5);
        let mut p = Patch::new(side, 3);
        for (i, v) in p.data.iter_mut().enumerate() {
            *v = ((i * 7919) % 2551) as f32 / 10.0 + 0.013 * (i % 7) as f32;
        }
        let mut got = vec![0.0; rows * cols];
        cell_gray(&p, cell, rows, cols, &mut got);
        // The loop for any cell size, as written before cells of 4 had their own.
        let n = side * side;
        let mut want = vec![0.0f32; rows * cols];
        for r in 0..rows * cell {
            for k in 0..cols {
                let span = r * side + k * cell..r * side + (k + 1) * cell;
                let sum =
                    |q: usize| -> f32 { p.data[q * n + span.start..q * n + span.end].iter().sum() };
                want[(r / cell) * cols + k] +=
                    LUMA[0] * sum(0) + LUMA[1] * sum(1) + LUMA[2] * sum(2);
            }
        }
        let inv = 1.0 / (255.0 * (cell * cell) as f32);
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.to_bits(), (w * inv - 0.5).to_bits());
        }
    }
}
