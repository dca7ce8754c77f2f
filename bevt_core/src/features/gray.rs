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
}
