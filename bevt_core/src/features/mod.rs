//! Feature extraction behind one trait, so hand-crafted and CNN features are
//! interchangeable.
//!
//! A [`FeatureExtractor`] turns an image [`Patch`] into a [`FeatureMap`]: channel-major
//! `f32` maps on the tracker's cell grid. Channels are grouped into *layers*; each layer
//! gets its own correlation filter and its response is fused with the layer's weight
//! (ALGORITHM.md §2).

#[cfg(feature = "cnn")]
pub mod cnn;
pub mod cnn_config;
pub mod colornames;
pub mod gray;
pub mod hog;

use crate::error::TrackError;
use crate::geometry::GridSize;
use crate::image::Patch;

pub use hog::{Hog, HOG_CHANNELS};

/// One group of channels that gets its own filter.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerInfo {
    /// Name for logs, e.g. `hog+gray`.
    pub name: String,
    /// Number of channels.
    pub channels: usize,
    /// Weight of this layer's response in the fused response.
    pub weight: f32,
}

/// Channel-major feature maps on a `grid`: `data[(d * h + r) * w + c]`.
#[derive(Debug, Clone, Default)]
pub struct FeatureMap {
    /// The cell grid.
    pub grid: GridSize,
    /// Number of channels.
    pub channels: usize,
    /// The values.
    pub data: Vec<f32>,
}

impl FeatureMap {
    /// A zeroed map.
    pub fn new(grid: GridSize, channels: usize) -> Self {
        Self {
            grid,
            channels,
            data: vec![0.0; grid.len() * channels],
        }
    }

    /// One channel.
    pub fn channel(&self, d: usize) -> &[f32] {
        let n = self.grid.len();
        &self.data[d * n..(d + 1) * n]
    }
}

/// Something that maps image patches to feature maps.
pub trait FeatureExtractor: Send {
    /// The channel groups, in channel order; their channel counts sum to the map's.
    fn layers(&self) -> &[LayerInfo];

    /// Total number of channels.
    fn channels(&self) -> usize {
        self.layers().iter().map(|l| l.channels).sum()
    }

    /// The largest cell size (pixels per feature cell) this extractor supports; the
    /// tracker may choose a smaller one for small targets.
    fn cell_size(&self) -> usize;

    /// Whether the tracker may choose a cell smaller than [`Self::cell_size`] for small
    /// targets (ALGORITHM.md §1). CNN features have a fixed stride and answer false.
    fn allows_smaller_cells(&self) -> bool {
        true
    }

    /// Tells the extractor how many colour planes its patches will have (3 for colour
    /// frames, 1 for mono8), before [`Self::layers`] is read for a new track. Groups that
    /// need colour (colour names) are left out for one plane, so the channel count is fixed
    /// for the whole track. The default ignores it.
    fn set_input_planes(&mut self, planes: usize) {
        let _ = planes;
    }

    /// Side of the patch this extractor wants for a search region of `patch_side` pixels
    /// (`grid · cell`); the tracker samples the region straight to this size. Hand-crafted
    /// features take the region as it is; a CNN may want its fixed input size.
    fn input_side(&self, patch_side: usize) -> usize {
        patch_side
    }

    /// Whether the training sample may be the winning scale's detection features shifted
    /// (in the Fourier domain) onto the new position, instead of a fresh extraction at the
    /// new position (as ECO does): saves one extraction per frame.
    fn train_from_detection(&self) -> bool {
        false
    }

    /// Whether [`Self::begin_track`] wants each track's first search patch (the tracker
    /// samples one only then).
    fn learns_per_track(&self) -> bool {
        false
    }

    /// Learns per-track state from the first frame's search patch (side
    /// [`Self::input_side`]), e.g. a channel projection (ECO). The tracker calls it on its
    /// per-track copy before cloning that for its workers, so every worker shares the state.
    ///
    /// # Errors
    /// [`TrackError::Feature`] when the backend fails.
    fn begin_track(&mut self, patch: &Patch) -> Result<(), TrackError> {
        let _ = patch;
        Ok(())
    }

    /// Whether [`Self::extract_scales`] is supported: the tracker then extracts all scales of
    /// a frame from one pass on the largest scale's patch.
    fn single_pass_scales(&self) -> bool {
        false
    }

    /// Features of several concentric regions from one pass on `patch` (the largest
    /// region): `outs[k]` receives the map of the centred fraction `fractions[k]` (in
    /// `(0, 1]`) of the patch, resampled to its grid.
    ///
    /// # Errors
    /// [`TrackError::Feature`] when the backend fails or the extractor does not support it
    /// (see [`Self::single_pass_scales`]).
    fn extract_scales(
        &mut self,
        patch: &Patch,
        fractions: &[f32],
        outs: &mut [&mut FeatureMap],
    ) -> Result<(), TrackError> {
        let _ = (patch, fractions, outs);
        Err(TrackError::Feature(
            "this feature extractor has no single-pass multi-scale extraction".to_string(),
        ))
    }

    /// Extracts features of `patch` (side [`Self::input_side`] of `out.grid.w × cell`
    /// pixels) into `out`, whose grid and channel count are preset by the caller.
    ///
    /// # Errors
    /// [`TrackError::Feature`] when the backend fails.
    fn extract(
        &mut self,
        patch: &Patch,
        cell: usize,
        out: &mut FeatureMap,
    ) -> Result<(), TrackError>;

    /// An independent extractor with the same settings (one per parallel worker).
    fn boxed_clone(&self) -> Box<dyn FeatureExtractor>;
}
