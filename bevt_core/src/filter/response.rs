//! Detection responses: per-layer correlation and weighted fusion (ALGORITHM.md §5).

use rustfft::num_complex::Complex32;
use std::ops::Range;

/// One layer's filter inside a stacked multi-layer filter: its channel range and weight.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerSlot {
    /// Channels of this layer in the stacked feature map.
    pub channels: Range<usize>,
    /// Weight of this layer's response.
    pub weight: f32,
}

/// `out[k] = Σ_layers w_l · Σ_{d ∈ l} conj(ĝ_d[k]) · x̂_d[k]`, all spectra `bins` long and
/// channel-major.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
pub fn fused_response(
    g_f: &[Complex32],
    x_f: &[Complex32],
    layers: &[LayerSlot],
    bins: usize,
    out: &mut [Complex32],
) {
    out[..bins]
        .iter_mut()
        .for_each(|v| *v = Complex32::default());
    for layer in layers {
        let w = layer.weight;
        for d in layer.channels.clone() {
            let g = &g_f[d * bins..(d + 1) * bins];
            let x = &x_f[d * bins..(d + 1) * bins];
            for ((o, g), x) in out.iter_mut().zip(g).zip(x) {
                *o += g.conj() * x * w;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fusion_weights_each_layer() {
        let bins = 2;
        let g = vec![Complex32::new(1.0, 0.0); 2 * bins];
        let x = vec![Complex32::new(2.0, 1.0); 2 * bins];
        let layers = vec![
            LayerSlot {
                channels: 0..1,
                weight: 1.0,
            },
            LayerSlot {
                channels: 1..2,
                weight: 0.5,
            },
        ];
        let mut out = vec![Complex32::default(); bins];
        fused_response(&g, &x, &layers, bins, &mut out);
        assert_eq!(out[0], Complex32::new(3.0, 1.5));
    }
}
