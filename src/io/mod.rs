//! Files in and out: images (EXR, Radiance HDR, PFM, PNG/JPEG) and atomic writes.

pub mod atomic;
pub mod image;
pub mod pfm;
pub mod progress;

/// Largest image matfit reads or renders, in pixels (2^26, e.g. 8192 × 8192): bigger photos are
/// refused with a message (downsample them and scale the camera) rather than exhausting memory.
pub const MAX_PIXELS: usize = 1 << 26;
