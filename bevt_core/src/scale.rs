//! Scale search: the scale factors tried each frame and the limits of the scale state
//! (ALGORITHM.md §5).

/// Scale factors `step^e` for exponents `−⌊n/2⌋ … ⌈n/2⌉−1` (−2..2 for n = 5).
pub fn scale_factors(n: usize, step: f32) -> Vec<f32> {
    let lo = -((n / 2) as i32);
    (0..n as i32).map(|i| step.powi(lo + i)).collect()
}

/// `[step^⌈log(max(5/sz))/log step⌉, step^⌊log(min(image/base_target))/log step⌋]`:
/// the smallest and largest allowed scale state. `patch_side` is the patch side in base
/// pixels; sizes are (w, h).
pub fn scale_limits(
    patch_side: f32,
    image: (f32, f32),
    base_target: (f32, f32),
    step: f32,
) -> (f32, f32) {
    let ls = step.ln();
    let min = step.powf(((5.0 / patch_side).ln() / ls).ceil());
    let ratio = (image.0 / base_target.0).min(image.1 / base_target.1);
    let max = step.powf((ratio.ln() / ls).floor());
    (min, max.max(min))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn five_scales_are_symmetric_around_one() {
        let s = scale_factors(5, 1.01);
        assert_eq!(s.len(), 5);
        assert!((s[2] - 1.0).abs() < 1e-7);
        assert!((s[0] * s[4] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn limits_bracket_one_for_a_normal_target() {
        let (lo, hi) = scale_limits(240.0, (1280.0, 720.0), (40.0, 40.0), 1.01);
        assert!(lo < 0.03 && hi > 17.0 && hi <= 18.0, "{lo} {hi}");
    }
}
