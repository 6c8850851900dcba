//! Photographs: loading as linear radiance (response curves, HDR merging of brackets,
//! vignetting, ignore masks) and the validity of each pixel. Nothing here knows the model: a
//! photo prepared against it (pose, usable-pixel masks, exposure from the lights) is
//! [`crate::prepare`]'s.

pub mod brackets;
pub mod calibrate;
pub mod edges;
pub mod hdr;
pub mod ignore;
pub mod response;
pub mod robust;
pub mod vignetting;

pub use response::{Response, ResponseTable};

use crate::io::image::{decode_raw_checked, Image, RawImage};
use crate::math::Rgb;
use std::path::Path;

/// Largest fraction of NaN/infinite pixels, and separately of negative pixels, that a photo may
/// have: up to it they are masked (never used) and counted; above it the photo is refused.
pub const MAX_BAD_FRACTION: f64 = 0.01;
/// Largest fraction of saturated pixels (8/16-bit photos): above it the photo is refused.
pub const MAX_SATURATED_FRACTION: f64 = 0.5;

#[derive(Clone, Debug, Default)]
pub struct PhotoOptions {
    /// Response curve of 8/16-bit photos (ignored for float formats, which are linear).
    pub response: Response,
    /// Linear radiance = pixel value / exposure. 1 when not given.
    pub exposure: Option<f32>,
}

/// A photograph as linear radiance, with a per-pixel validity flag.
///
/// Validity rule (stated once, applied by [`load_photo`]): a pixel is invalid if any channel is
/// NaN or infinite (the pixel is then zeroed), negative, or — for 8/16-bit files — at the top
/// code value (clipped: its radiance is unknown). Invalid pixels are never used and are counted
/// by reason. A photo is refused when more than [`MAX_BAD_FRACTION`] (1%) of its pixels are
/// non-finite, or more than 1% are negative, when more than [`MAX_SATURATED_FRACTION`] (50%) are
/// saturated, or when no valid pixel is above zero (all black).
#[derive(Clone, Debug)]
pub struct Photo {
    pub image: Image,
    /// False for pixels that must not be used: NaN, infinite, negative, or saturated.
    pub valid: Vec<bool>,
    /// Pixels found invalid, by reason, for the report.
    pub invalid_nonfinite: usize,
    pub invalid_negative: usize,
    pub invalid_saturated: usize,
    /// Bit depth of an integer-coded file (None: float file or rendering).
    pub bits: Option<u32>,
    /// The exposure factor the values have been divided by (1 until one is applied).
    pub exposure: f32,
    /// Pixels the user asked to ignore (`--ignore-mask`, [`ignore`]); all false without one.
    /// Kept apart from `valid`: such a pixel is not broken, the model just does not explain it.
    pub ignored: Vec<bool>,
}

impl Photo {
    /// A photo from a linear image (e.g. a rendering), checking every pixel.
    pub fn from_linear(image: Image) -> Photo {
        let n = image.data.len();
        let mut p = Photo {
            valid: vec![true; n],
            image,
            invalid_nonfinite: 0,
            invalid_negative: 0,
            invalid_saturated: 0,
            bits: None,
            exposure: 1.0,
            ignored: vec![false; n],
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

    /// Divides every pixel by `factor` more (a calibrated exposure), recording it.
    pub fn apply_exposure(&mut self, factor: f32) {
        for c in &mut self.image.data {
            *c /= factor;
        }
        self.exposure *= factor;
    }

    /// Sets the pixels to ignore (one flag per pixel) and returns how many there are.
    pub fn set_ignored(&mut self, ignored: Vec<bool>) -> usize {
        assert_eq!(ignored.len(), self.valid.len(), "one flag per pixel");
        self.ignored = ignored;
        self.ignored.iter().filter(|&&m| m).count()
    }

    /// Number of invalid pixels.
    pub fn invalid(&self) -> usize {
        self.invalid_nonfinite + self.invalid_negative + self.invalid_saturated
    }
}

/// The message for a photo whose size is not the camera's: same aspect ratio at another
/// resolution, a rotated photo, or another aspect ratio altogether.
fn size_mismatch(path: &Path, w: usize, h: usize, cw: usize, ch: usize) -> String {
    let head = format!(
        "{}: the photo is {w}×{h} but the scene's camera is {cw}×{ch}",
        path.display()
    );
    if (w, h) == (ch, cw) && w != h {
        return format!(
            "{head}: the photo is rotated by 90° (portrait vs landscape); rotate it or fix the camera"
        );
    }
    let (a, ca) = (w as f64 / h as f64, cw as f64 / ch as f64);
    if (a / ca - 1.0).abs() < 2e-3 {
        format!(
            "{head}: same aspect ratio ({a:.4}), different resolution; resize the photo to \
             {cw}×{ch}, or scale the camera (width, height and fx, fy, cx, cy) by {:.4}",
            w as f64 / cw as f64
        )
    } else {
        format!(
            "{head}: different aspect ratio ({a:.4} vs {ca:.4}); the photo does not fit this \
             camera (cropped? wrong calibration?)"
        )
    }
}

/// The exposure of `opts` (1 when not given), which must be positive and finite.
fn exposure(opts: &PhotoOptions) -> Result<f32, String> {
    let exposure = opts.exposure.unwrap_or(1.0);
    if !(exposure > 0.0 && exposure.is_finite()) {
        return Err(format!("exposure must be positive, got {exposure}"));
    }
    Ok(exposure)
}

fn empty_photo(path: &Path) -> String {
    format!("{}: the photo file is empty (0 bytes)", path.display())
}

/// Loads a photo (EXR, HDR, PFM as linear; PNG/JPEG through `opts.response`), checks it against
/// the camera's size and the validity rule of [`Photo`], and divides by the exposure.
pub fn load_photo(
    path: &Path,
    width: u32,
    height: u32,
    opts: &PhotoOptions,
) -> Result<Photo, String> {
    // Checked before reading, so that a bad --exposure is reported ahead of decoding errors.
    exposure(opts)?;
    match std::fs::metadata(path) {
        Ok(m) if m.len() == 0 => return Err(empty_photo(path)),
        Ok(m) if m.is_dir() => return Err(format!("{}: is a folder, not a photo", path.display())),
        Ok(_) => crate::io::image::check_image_file(path)?,
        Err(e) => return Err(format!("{}: cannot read the photo: {e}", path.display())),
    }
    let bytes = std::fs::read(path)
        .map_err(|e| format!("{}: cannot read the photo: {e}", path.display()))?;
    photo_from_bytes(&bytes, path, width, height, opts)
}

/// [`load_photo`] on a file's bytes already in memory (`path` names it in messages and its
/// extension tells PFM apart).
pub fn photo_from_bytes(
    bytes: &[u8],
    path: &Path,
    width: u32,
    height: u32,
    opts: &PhotoOptions,
) -> Result<Photo, String> {
    if bytes.is_empty() {
        return Err(empty_photo(path));
    }
    // The size is checked from the header, before the pixels are decoded.
    let raw = decode_raw_checked(bytes, path, |w, h| {
        if (w, h) != (width as usize, height as usize) {
            return Err(size_mismatch(path, w, h, width as usize, height as usize));
        }
        Ok(())
    })?;
    photo_from_raw(raw, path, width, height, opts)
}

/// The checks of [`load_photo`] on decoded pixel values: size, response curve, exposure and the
/// validity rule of [`Photo`].
pub fn photo_from_raw(
    raw: RawImage,
    path: &Path,
    width: u32,
    height: u32,
    opts: &PhotoOptions,
) -> Result<Photo, String> {
    let exposure = exposure(opts)?;
    let (w, h) = (raw.image.width, raw.image.height);
    if (w, h) != (width as usize, height as usize) {
        return Err(size_mismatch(path, w, h, width as usize, height as usize));
    }
    let mut image = raw.image;
    let mut saturated = vec![false; image.data.len()];
    if let Some(bits) = raw.bits {
        // A code value at the top of the range is clipped: its radiance is unknown.
        let top = 1.0 - 0.5 / ((1u32 << bits) - 1) as f32;
        for (c, s) in image.data.iter_mut().zip(saturated.iter_mut()) {
            *s = c.max_element() >= top;
            *c = Rgb::new(
                opts.response.linearize_channel(c.x, 0),
                opts.response.linearize_channel(c.y, 1),
                opts.response.linearize_channel(c.z, 2),
            );
        }
    }
    for c in &mut image.data {
        *c /= exposure;
    }
    let mut photo = Photo::from_linear(image);
    photo.bits = raw.bits;
    photo.exposure = exposure;
    for (v, s) in photo.valid.iter_mut().zip(&saturated) {
        if *s && *v {
            *v = false;
            photo.invalid_saturated += 1;
        }
    }
    let n = photo.valid.len();
    let pct = |k: usize| 100.0 * k as f64 / n as f64;
    let limit = (MAX_BAD_FRACTION * n as f64) as usize;
    if photo.invalid_nonfinite > limit {
        return Err(format!(
            "{}: {} of {n} pixels ({:.1}%) are NaN or infinite; matfit masks up to {}% of them \
             and refuses more",
            path.display(),
            photo.invalid_nonfinite,
            pct(photo.invalid_nonfinite),
            MAX_BAD_FRACTION * 100.0
        ));
    }
    if photo.invalid_negative > limit {
        return Err(format!(
            "{}: {} of {n} pixels ({:.1}%) have negative values, which radiance cannot have; \
             matfit masks up to {}% of them and refuses more",
            path.display(),
            photo.invalid_negative,
            pct(photo.invalid_negative),
            MAX_BAD_FRACTION * 100.0
        ));
    }
    if photo.invalid_saturated as f64 > MAX_SATURATED_FRACTION * n as f64 {
        return Err(format!(
            "{}: the photo is saturated: {} of {n} pixels ({:.1}%) are at the top code value, \
             their radiance is unknown (over-exposed; take it with a shorter exposure or as HDR)",
            path.display(),
            photo.invalid_saturated,
            pct(photo.invalid_saturated)
        ));
    }
    if photo
        .image
        .data
        .iter()
        .zip(&photo.valid)
        .all(|(c, &v)| !v || c.max_element() <= 0.0)
    {
        return Err(format!(
            "{}: the photo is all black (no valid pixel above zero{})",
            path.display(),
            if photo.invalid_saturated > 0 {
                format!("; {} saturated pixels", photo.invalid_saturated)
            } else {
                String::new()
            }
        ));
    }
    if photo.invalid() > 0 {
        tracing::warn!(
            "{}: {} NaN/infinite, {} negative, {} saturated pixels masked",
            path.display(),
            photo.invalid_nonfinite,
            photo.invalid_negative,
            photo.invalid_saturated
        );
    }
    Ok(photo)
}
