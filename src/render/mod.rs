//! The renderer: BSDFs, lights, the path tracer, images and index buffers.

pub mod aov;
pub mod batch;
pub mod bsdf;
pub mod composite;
pub mod film;
pub mod incident;
pub mod integrator;
pub mod lights;
pub mod mirror_lights;
pub mod replay;

pub use integrator::PathTracer;
