//! # bevt_core: the BEVT visual object tracker
//!
//! A pure tracking library (no ROS, no files, no threads of its own) implementing BEVT
//! (Fu et al., IROS 2019): correlation filters trained by ADMM with **enhanced background
//! learning** (a large search window, a target-sized cropped filter, a spatial penalty) and
//! **multi-frame consensus verification** of each frame before it is learned.
//!
//! ## Principal types
//! - [`Tracker`]: `init(&frame, bbox)` / `update(&frame) -> TrackOutput`, the interface every
//!   driver uses; [`BevtTracker`] implements it.
//! - [`TrackerConfig`] (serde, strict) → [`TrackerConfig::validate`] → [`TrackerSpec`].
//! - [`Frame`]: a borrowed rgb8/bgr8/rgba8/bgra8/mono8 buffer with a row stride (zero copy).
//! - [`features::FeatureExtractor`]: HOG (+ grayscale) here; CNN features plug in the same way.
//!
//! ## Pipeline of one `update`
//! ```text
//! Frame → patches at S scales → features × Hann → FFT → Σ conj(ĝ)·x̂ → response
//!       → Newton sub-cell peak → best scale → new position/scale
//!       → consensus C = exp(−‖M_ideal − M_curr‖) → skip / learn (η) → ADMM → ĝ
//! ```
//!
//! ## Example
//! ```
//! use bevt_core::{BevtTracker, Frame, PixelFormat, Tracker, TrackerConfig};
//! use bevt_core::eval::synth::SynthParams;
//!
//! let seq = SynthParams { frames: 5, ..SynthParams::default() };
//! let mut tracker = BevtTracker::new(TrackerConfig::default().validate()?);
//! let first = seq.frame(0);
//! tracker.init(&Frame::packed(&first.rgb, seq.width, seq.height, PixelFormat::Rgb8)?, first.truth)?;
//! for t in 1..seq.frames {
//!     let f = seq.frame(t);
//!     let out = tracker.update(&Frame::packed(&f.rgb, seq.width, seq.height, PixelFormat::Rgb8)?)?;
//!     assert!(out.bbox.center().distance(&f.truth.center()) < 5.0);
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]

pub mod box_refine;
pub mod confidence;
pub mod config;
pub mod consensus;
pub mod error;
pub mod eval;
pub mod features;
pub mod fft;
pub mod filter;
pub mod geometry;
pub mod image;
pub mod motion;
pub mod nn;
pub mod redetect;
pub mod scale;
pub mod scale_filter;
pub mod track_state;
pub mod tracker;

#[cfg(test)]
#[cfg(target_arch = "x86_64")]
mod dispatch_tests;

pub use config::{TrackerConfig, TrackerSpec};
pub use error::{ConfigError, TrackError};
pub use geometry::{BBox, GridSize, Point2, Size2};
pub use image::{Frame, PixelFormat};
pub use track_state::{StateReason, TrackState};
pub use tracker::{BevtTracker, Geometry, TrackOutput, Tracker};
