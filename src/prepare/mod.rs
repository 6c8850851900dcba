//! A photograph prepared against the model (§3.3 of the notes): the camera's pose refined to the
//! photo (`pose.rs`, `register.rs`), the model's sub-pixel coverage (`coverage.rs`), the
//! usable-pixel masks that decide which pixels speak for each group (`mask.rs`), the exposure
//! calibrated from a grey card or the lights (`exposure.rs`, `estimate.rs`), how open the scene
//! is (`openness.rs`), and the checks `matfit inspect` draws (`inspect.rs`). It renders the
//! model (index buffers, reference images), so it stands above `render`; the photograph itself
//! (loading, response, brackets, vignetting) is `photo`'s, below it.
//!
//! The fitter reads only [`crate::photo::Photo`] and [`UsableMask`].

pub mod args;
pub mod coverage;
pub mod estimate;
pub mod exposure;
pub mod inspect;
pub mod mask;
pub mod openness;
pub mod pose;
pub mod register;

pub use args::{prepare, prepare_at, prepare_loaded, PhotoArgs, PreparedPhoto};
pub use mask::{usable_pixels, usable_pixels_covered, GroupPixelStats, MaskOptions, UsableMask};
