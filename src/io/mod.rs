//! Files in and out: images (EXR, Radiance HDR, PFM, PNG/JPEG) and atomic writes.

pub mod atomic;
pub mod image;
pub mod pfm;
