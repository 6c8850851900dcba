//! The incident-radiance cache (docs/DESIGN.md, "Making it fast" 1): what it holds
//! (`pixels.rs`), how it is traced (`build.rs`, with the defensive mixture of `mixture.rs` and
//! the mirror images of `mirror_images.rs`), the smoothed irradiance of a textured group's
//! texels (`irradiance.rs`), and what it reads from the photo for §5.1 (`pseudo_textures.rs`).

pub mod build;
pub mod irradiance;
pub mod mirror_images;
pub mod mixture;
pub mod pixels;
pub mod pseudo_textures;

pub use build::{
    build, build_kept, choose_pixels, rebuild, shows_in_mirror, CacheRequest, KeptCache, Primary,
};
pub use pixels::*;
pub use pseudo_textures::{photo_radiance, PseudoMirror, PseudoTextures};
