//! Synthetic scenes of the lost-state tests (issue 8), shared by `lost.rs` and the verifier
//! tests of `cnn.rs` so both exercise exactly the same sequences.

use bevt_core::eval::synth::{Distractor, SynthParams};

/// First hidden frame of the scenes below (hidden frames are `[HIDE, SHOW)`).
pub const HIDE: usize = 30;
/// First frame on which the target is visible again.
pub const SHOW: usize = 50;

/// 480×360, a 48×40 target hidden for frames 30–49, reappearing 140 px right, 70 px down.
pub fn occluded() -> SynthParams {
    SynthParams {
        width: 480,
        height: 360,
        frames: 90,
        target: (48.0, 40.0),
        scale_rate: 1.0,
        path_amplitude: (30.0, 20.0),
        camera_velocity: (0.5, -0.3),
        hidden: Some((HIDE, SHOW)),
        reappear_offset: (140.0, 70.0),
        ..SynthParams::default()
    }
}

/// [`occluded`] with a look-alike (the target's size, rim and colours, another texture) at
/// (120, 250), shown while the target is hidden.
pub fn with_look_alike() -> SynthParams {
    SynthParams {
        distractor: Some(Distractor {
            center: (120.0, 250.0),
            seed: 1234,
        }),
        ..occluded()
    }
}

/// A large frame (960×540), a small target (28×24) that leaves the view and re-enters at
/// the far side (380 px left, 200 px down) after frames 30–49.
pub fn far_reentry() -> SynthParams {
    SynthParams::far_reentry(HIDE, SHOW)
}
