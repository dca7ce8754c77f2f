//! Grayscale cell feature: mean luminance of each cell, scaled to [−0.5, 0.5].

use crate::image::Patch;

/// ITU-R BT.601 luma weights for R, G, B.
const LUMA: [f32; 3] = [0.299, 0.587, 0.114];

/// Writes the mean luminance of each `cell × cell` block of `patch`, `/255 − 0.5`, into
/// `out` (row-major `rows × cols`).
pub fn cell_gray(patch: &Patch, cell: usize, rows: usize, cols: usize, out: &mut [f32]) {
    out[..rows * cols].iter_mut().for_each(|v| *v = 0.0);
    let side = patch.side;
    let n = side * side;
    let inv = 1.0 / (255.0 * (cell * cell) as f32);
    for r in 0..rows * cell {
        let orow = &mut out[(r / cell) * cols..(r / cell + 1) * cols];
        for c in 0..cols * cell {
            let i = r * side + c;
            let v = if patch.planes == 3 {
                LUMA[0] * patch.data[i] + LUMA[1] * patch.data[n + i] + LUMA[2] * patch.data[2 * n + i]
            } else {
                patch.data[i]
            };
            orow[c / cell] += v;
        }
    }
    for v in &mut out[..rows * cols] {
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
}
