//! matfit: recovers the reflectance of every surface of a scene from one photograph, a 3D model,
//! the camera and the known lights, by inverse global illumination (Boivin & Gagalowicz 2001).
//!
//! Data flows one way: [`scene`] + [`photo`] → [`render`] → [`prepare`] → [`fit`] →
//! [`report`] (docs/DESIGN.md, "Layers"; `tests/layers.rs` checks it).

// `!(x > 0.0)` is how this crate says "not positive, or NaN": keep it.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Physics and camera constructors take their parameters plainly rather than through builders.
#![allow(clippy::too_many_arguments)]
// Numeric kernels index several parallel arrays by channel or axis; iterator chains would hide it.
#![allow(clippy::needless_range_loop)]

pub mod export;
pub mod fit;
#[doc(hidden)]
pub mod fuzzing;
pub mod geometry;
pub mod import;
pub mod io;
pub mod math;
pub mod photo;
pub mod prepare;
pub mod render;
pub mod report;
pub mod scene;
