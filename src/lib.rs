//! matfit: recovers the reflectance of every surface of a scene from one photograph, a 3D model,
//! the camera and the known lights, by inverse global illumination (Boivin & Gagalowicz 2001).
//!
//! The front door is the handful of calls at the crate's root, one per job of the command
//! line: [`load`] a scene, [`render`] it, [`edit`] it, [`recover`] its materials from photos,
//! [`composite`] an edit into the photo, [`export`] it. What they report goes to an
//! [`Observer`]; what fails is an [`Error`]. These are the library's stable interface.
//!
//! ```
//! use matfit::{PhotoInput, RecoverOptions, RenderRequest, Silent};
//!
//! # fn main() -> Result<(), matfit::Error> {
//! // A grey floor under a lamp, 32 × 24 pixels.
//! let dir = std::env::temp_dir().join(format!("matfit-doctest-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! std::fs::write(
//!     dir.join("scene.toml"),
//!     r#"
//! [camera]
//! width = 32
//! height = 24
//! eye = [0.0, 2.0, 2.0]
//! target = [0.0, 0.0, 0.0]
//! fov_y_deg = 45.0
//!
//! [[object]]
//! name = "floor"
//! group = "floor"
//! shape = "quad"
//! corner = [-1.0, 0.0, 1.0]
//! edge_u = [2.0, 0.0, 0.0]
//! edge_v = [0.0, 0.0, -2.0]
//! material = { type = "diffuse", rho_d = 0.4 }
//!
//! [[object]]
//! name = "lamp"
//! group = "lamp"
//! shape = "quad"
//! corner = [-0.2, 1.5, -0.2]
//! edge_u = [0.4, 0.0, 0.0]
//! edge_v = [0.0, 0.0, 0.4]
//! emission = 5.0
//! "#,
//! )?;
//! let scene = matfit::load(dir.join("scene.toml"))?;
//!
//! // Its "photograph": the scene rendered with its true materials.
//! let request = RenderRequest { spp: Some(256), ..Default::default() };
//! let photo = matfit::render(&scene, &request, &Silent)?;
//!
//! // The floor's material recovered from the photo alone.
//! let mut options = RecoverOptions::default();
//! options.fit.max_iterations = 4;
//! let recovery = matfit::recover(&scene, &[PhotoInput::Linear(photo)], &options, &Silent)?;
//! let floor = &recovery.fit.groups[scene.group_index("floor").unwrap()];
//! assert!((floor.params.rho_d.x - 0.4).abs() < 0.02, "{:?}", floor.params.rho_d);
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok(())
//! # }
//! ```
//!
//! Under the front door, data flows one way: `scene` + `photo` → `render` → `prepare` → `fit`
//! → `report` (docs/DESIGN.md, "Layers"; `tests/layers.rs` checks it).

// `!(x > 0.0)` is how this crate says "not positive, or NaN": keep it.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Physics and camera constructors take their parameters plainly rather than through builders.
#![allow(clippy::too_many_arguments)]
// Numeric kernels index several parallel arrays by channel or axis; iterator chains would hide it.
#![allow(clippy::needless_range_loop)]
// Without `internals`, much of the engine serves only the command line and the tests, and
// clippy judges the engine's names (`Frame::to_world(&self)`) as if they were not public.
#![cfg_attr(
    not(feature = "internals"),
    allow(dead_code, unused_imports, clippy::wrong_self_convention)
)]

/// Declares the engine's modules: public with the `internals` feature (for the command line,
/// the tests and the benchmarks; no stability promised), private to the crate without it.
macro_rules! internal {
    ($($name:ident),* $(,)?) => {$(
        #[cfg(feature = "internals")]
        #[doc(hidden)]
        pub mod $name;
        #[cfg(not(feature = "internals"))]
        mod $name;
    )*};
}

internal!(
    api, export, fit, fuzzing, geometry, import, io, math, photo, prepare, render, report, scene,
);

mod error;

pub use api::{
    composite, edit, edit_from_flags, export, in_view, load, load_edited, parse_grey_card,
    parse_response, read_edit, read_image, recover, render, CompositeOptions, Composited,
    EditFlags, LogLine, Observer, PhotoInput, Progress, RecoverOptions, Recovery, RenderRequest,
    Silent,
};
pub use error::{Error, ErrorKind, Location, Result};
pub use export::{ExportReport, Format};
pub use io::image::Image;
pub use math::Rgb;
pub use photo::Response;
pub use render::aov::Aov;
pub use scene::edit::Edit;
pub use scene::Scene;
