//! Photographs: loading as linear radiance, validity of each pixel, and the usable-pixel masks
//! that decide which pixels speak for each group (§3.3 of the notes).
//!
//! The fitter reads only [`Photo`] and [`UsableMask`]; everything about cameras' responses,
//! exposure and robust pixel selection lives here.

pub mod mask;

pub use mask::{usable_pixels, GroupPixelStats, MaskOptions, UsableMask};

use crate::io::image::{read_raw, srgb_decode, Image};
use crate::math::Rgb;
use std::path::Path;

/// How integer-coded photos are turned into linear values.
#[derive(Clone, Debug, PartialEq, Default)]
pub enum Response {
    /// The sRGB curve (the default for 8/16-bit files).
    #[default]
    Srgb,
    /// v^g.
    Gamma(f32),
    /// Already linear.
    Linear,
}

impl Response {
    pub fn linearize(&self, v: f32) -> f32 {
        match self {
            Response::Srgb => srgb_decode(v),
            Response::Gamma(g) => v.max(0.0).powf(*g),
            Response::Linear => v,
        }
    }
}

#[derive(Clone, Debug, Default)]
pub struct PhotoOptions {
    pub response: Response,
    /// Linear radiance = pixel value / exposure. 1 when not given.
    pub exposure: Option<f32>,
}

/// A photograph as linear radiance, with a per-pixel validity flag.
#[derive(Clone, Debug)]
pub struct Photo {
    pub image: Image,
    /// False for pixels that must not be used: NaN, infinite, negative, or saturated.
    pub valid: Vec<bool>,
    /// Pixels found invalid, by reason, for the report.
    pub invalid_nonfinite: usize,
    pub invalid_negative: usize,
    pub invalid_saturated: usize,
}

impl Photo {
    /// A photo from a linear image (e.g. a rendering), checking every pixel.
    pub fn from_linear(image: Image) -> Photo {
        let mut p = Photo {
            valid: vec![true; image.data.len()],
            image,
            invalid_nonfinite: 0,
            invalid_negative: 0,
            invalid_saturated: 0,
        };
        for (c, v) in p.image.data.iter_mut().zip(p.valid.iter_mut()) {
            if !c.is_finite() {
                *v = false;
                *c = Rgb::ZERO;
                p.invalid_nonfinite += 1;
            } else if c.min_element() < 0.0 {
                *v = false;
                p.invalid_negative += 1;
            }
        }
        p
    }
}

/// Loads a photo (EXR, HDR, PFM as linear; PNG/JPEG through `opts.response`), checks it against
/// the camera's size, and divides by the exposure.
pub fn load_photo(
    path: &Path,
    width: u32,
    height: u32,
    opts: &PhotoOptions,
) -> Result<Photo, String> {
    let raw = read_raw(path)?;
    let (w, h) = (raw.image.width, raw.image.height);
    if (w, h) != (width as usize, height as usize) {
        return Err(format!(
            "{}: the photo is {w}×{h} but the scene's camera is {width}×{height}",
            path.display()
        ));
    }
    let mut image = raw.image;
    let mut saturated = vec![false; image.data.len()];
    if let Some(bits) = raw.bits {
        // A code value at the top of the range is clipped: its radiance is unknown.
        let top = 1.0 - 0.5 / ((1u32 << bits) - 1) as f32;
        for (c, s) in image.data.iter_mut().zip(saturated.iter_mut()) {
            *s = c.max_element() >= top;
            *c = Rgb::new(
                opts.response.linearize(c.x),
                opts.response.linearize(c.y),
                opts.response.linearize(c.z),
            );
        }
    }
    let exposure = opts.exposure.unwrap_or(1.0);
    if !(exposure > 0.0 && exposure.is_finite()) {
        return Err(format!("exposure must be positive, got {exposure}"));
    }
    for c in &mut image.data {
        *c /= exposure;
    }
    let mut photo = Photo::from_linear(image);
    for (v, s) in photo.valid.iter_mut().zip(&saturated) {
        if *s && *v {
            *v = false;
            photo.invalid_saturated += 1;
        }
    }
    let n = photo.valid.len();
    if photo.invalid_nonfinite + photo.invalid_negative > n / 2 {
        return Err(format!(
            "{}: most pixels are NaN, infinite or negative",
            path.display()
        ));
    }
    if photo
        .image
        .data
        .iter()
        .zip(&photo.valid)
        .all(|(c, &v)| !v || c.max_element() <= 0.0)
    {
        return Err(format!("{}: the photo is all black", path.display()));
    }
    if photo.invalid_saturated > n * 9 / 10 {
        return Err(format!(
            "{}: the photo is saturated ({} of {n} pixels clipped)",
            path.display(),
            photo.invalid_saturated
        ));
    }
    Ok(photo)
}
