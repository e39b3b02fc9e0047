//! The answer to "what does a renderer use for this scan", above `fit`, `render` and `wave`: what light
//! sees of the surface first, then the simplest material a viewer cannot tell from it.
//!
//! - [`optics`]: the regime (`geometric`, `mixed`, `wave`) from the wave module's mirror share on the
//!   scan's coherence patches, and for a mirror its haze lobe;
//! - [`choice`]: the render choice among the ladder's lobes and the scan's table, where geometric optics
//!   holds;
//! - [`answer_mirror`]: the answer and the verdict where it does not (`mirror`, `mirror+ggx`);
//! - [`blend_render_error`]: what a renderer's blend of a mirror answer costs in the render.

mod blend;
pub mod choice;
mod optics;

pub use blend::{blend_render_error, BlendError};
pub use optics::{
    add_haze, answer_mirror, haze, haze_visible, optics, optics_and_heights, optics_with_haze, Regime, GEOMETRIC_SHARE, HAZE_VISIBLE,
    MIRROR_SHARE, TILT_RATIO, UNRESOLVED,
};
