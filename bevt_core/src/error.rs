//! Error types of the tracking core.

use thiserror::Error;

/// A configuration value that cannot be used.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum ConfigError {
    /// A numeric field is outside its allowed range.
    #[error("config field `{field}` = {value} is out of range: {expected}")]
    OutOfRange {
        /// Dotted name of the field, e.g. `admm.iterations`.
        field: &'static str,
        /// The offending value, formatted.
        value: String,
        /// The allowed range, in words.
        expected: String,
    },
    /// Two fields contradict each other.
    #[error("config fields are inconsistent: {0}")]
    Inconsistent(String),
    /// A running tracker was given a configuration that differs in a field which only
    /// takes effect when a tracker is built (see [`crate::config::keys::live_keys`]).
    #[error("config field(s) {0} cannot change while tracking (they shape the tracker built at initialisation)")]
    NotLive(String),
}

/// An error from [`crate::Tracker::init`] or [`crate::Tracker::update`]: bad input.
///
/// A frame on which the tracker merely loses confidence is *not* an error: it is a
/// [`crate::TrackOutput`] with `learned == false`.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum TrackError {
    /// The frame buffer does not match the declared geometry.
    #[error("invalid frame: {0}")]
    InvalidFrame(String),
    /// The initial box has a non-finite, zero or negative component.
    #[error("invalid box {x}, {y}, {w}, {h}: {reason}")]
    InvalidBox {
        /// Left edge, pixels.
        x: f32,
        /// Top edge, pixels.
        y: f32,
        /// Width, pixels.
        w: f32,
        /// Height, pixels.
        h: f32,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The initial box is smaller than the smallest trackable target.
    #[error("target {w}x{h} px is smaller than the minimum of {min} px per side")]
    TargetTooSmall {
        /// Width, pixels.
        w: f32,
        /// Height, pixels.
        h: f32,
        /// Minimum side, pixels.
        min: f32,
    },
    /// The initial box does not overlap the frame enough to learn from.
    #[error("box {x}, {y}, {w}, {h} lies outside the {frame_w}x{frame_h} frame")]
    BoxOutsideFrame {
        /// Left edge, pixels.
        x: f32,
        /// Top edge, pixels.
        y: f32,
        /// Width, pixels.
        w: f32,
        /// Height, pixels.
        h: f32,
        /// Frame width, pixels.
        frame_w: usize,
        /// Frame height, pixels.
        frame_h: usize,
    },
    /// The initial box is larger than the frame.
    #[error("target {w}x{h} px is larger than the {frame_w}x{frame_h} frame")]
    TargetLargerThanFrame {
        /// Width, pixels.
        w: f32,
        /// Height, pixels.
        h: f32,
        /// Frame width, pixels.
        frame_w: usize,
        /// Frame height, pixels.
        frame_h: usize,
    },
    /// `update` was called before a successful `init`.
    #[error("update called before init")]
    NotInitialized,
    /// The frame differs in size or pixel format from the one used at `init`.
    #[error("frame changed from {expected} to {got}; re-initialise the tracker")]
    FrameMismatch {
        /// Geometry/format at init, e.g. `1280x720 rgb8`.
        expected: String,
        /// Geometry/format of this frame.
        got: String,
    },
    /// The feature extractor failed (e.g. a CNN backend error).
    #[error("feature extraction failed: {0}")]
    Feature(String),
}
