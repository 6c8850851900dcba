//! Linear RGB images and their files. Formats by extension: `.exr` (OpenEXR, 32-bit float),
//! `.hdr` (Radiance RGBE), `.pfm` (portable float map), `.png` / `.jpg` (8/16-bit, sRGB-encoded
//! on write; decoded through the sRGB curve by [`read_linear`]). Photos with other response
//! curves are decoded by `photo::response`.

use super::atomic::write_atomic_with;
use crate::math::Rgb;
use std::path::Path;

/// A linear RGB image, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub data: Vec<Rgb>,
}

/// Raw pixel values of a file before any response curve: float formats are linear already;
/// integer formats are code values scaled to [0, 1] with their bit depth.
#[derive(Clone, Debug)]
pub struct RawImage {
    pub image: Image,
    /// None for float formats; Some(8) or Some(16) for integer ones.
    pub bits: Option<u32>,
}

impl Image {
    pub fn new(width: usize, height: usize) -> Image {
        Image {
            width,
            height,
            data: vec![Rgb::ZERO; width * height],
        }
    }

    #[inline]
    pub fn get(&self, x: usize, y: usize) -> Rgb {
        self.data[y * self.width + x]
    }

    #[inline]
    pub fn set(&mut self, x: usize, y: usize, c: Rgb) {
        self.data[y * self.width + x] = c;
    }

    pub fn mean(&self) -> Rgb {
        self.data.iter().copied().sum::<Rgb>() / self.data.len().max(1) as f32
    }

    /// Writes the image, choosing the format by extension, atomically.
    pub fn write(&self, path: &Path) -> Result<(), String> {
        let ext = extension(path);
        let res = match ext.as_str() {
            "pfm" => {
                let bytes = super::pfm::encode(self.width, self.height, &self.data);
                write_atomic_with(path, |w| std::io::Write::write_all(w, &bytes))
            }
            "exr" | "hdr" => {
                let buf = image::Rgb32FImage::from_raw(
                    self.width as u32,
                    self.height as u32,
                    self.data.iter().flat_map(|c| [c.x, c.y, c.z]).collect(),
                )
                .expect("buffer size matches");
                let fmt = if ext == "exr" {
                    image::ImageFormat::OpenExr
                } else {
                    image::ImageFormat::Hdr
                };
                let dynimg = image::DynamicImage::ImageRgb32F(buf);
                let mut bytes = std::io::Cursor::new(Vec::new());
                dynimg
                    .write_to(&mut bytes, fmt)
                    .map_err(|e| e.to_string())?;
                write_atomic_with(path, |w| std::io::Write::write_all(w, bytes.get_ref()))
            }
            "png" | "jpg" | "jpeg" => {
                let bytes = self.encode_8bit(if ext == "png" {
                    image::ImageFormat::Png
                } else {
                    image::ImageFormat::Jpeg
                })?;
                write_atomic_with(path, |w| std::io::Write::write_all(w, &bytes))
            }
            _ => {
                return Err(format!(
                    "{}: unknown image format '.{ext}' (use .exr, .hdr, .pfm or .png)",
                    path.display()
                ))
            }
        };
        res.map_err(|e| format!("cannot write {}: {e}", path.display()))
    }

    /// The sRGB-encoded 8-bit version (values clipped to [0, 1]).
    pub fn to_srgb8(&self) -> image::RgbImage {
        let mut out = image::RgbImage::new(self.width as u32, self.height as u32);
        for (o, c) in out.pixels_mut().zip(&self.data) {
            *o = image::Rgb([srgb_encode8(c.x), srgb_encode8(c.y), srgb_encode8(c.z)]);
        }
        out
    }

    fn encode_8bit(&self, fmt: image::ImageFormat) -> Result<Vec<u8>, String> {
        let mut bytes = std::io::Cursor::new(Vec::new());
        self.to_srgb8()
            .write_to(&mut bytes, fmt)
            .map_err(|e| e.to_string())?;
        Ok(bytes.into_inner())
    }
}

fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default()
}

/// sRGB transfer function (IEC 61966-2-1), linear → encoded, both in [0, 1].
#[inline]
pub fn srgb_encode(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB transfer function, encoded → linear.
#[inline]
pub fn srgb_decode(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

#[inline]
fn srgb_encode8(x: f32) -> u8 {
    let x = if x.is_nan() { 0.0 } else { x };
    (srgb_encode(x) * 255.0 + 0.5) as u8
}

/// Reads an image file's values without applying a response curve.
pub fn read_raw(path: &Path) -> Result<RawImage, String> {
    let bad = |e: String| format!("{}: {e}", path.display());
    let bytes = std::fs::read(path).map_err(|e| bad(format!("cannot read: {e}")))?;
    if extension(path) == "pfm" {
        let (width, height, data) = super::pfm::decode(&bytes).map_err(bad)?;
        return Ok(RawImage {
            image: Image {
                width,
                height,
                data,
            },
            bits: None,
        });
    }
    let reader = image::ImageReader::new(std::io::Cursor::new(&bytes))
        .with_guessed_format()
        .map_err(|e| bad(e.to_string()))?;
    if reader.format().is_none() {
        return Err(bad(
            "not an image file matfit can read (EXR, HDR, PFM, PNG, JPEG)".into(),
        ));
    }
    let img = reader
        .decode()
        .map_err(|e| bad(format!("cannot decode (truncated or corrupt file?): {e}")))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w == 0 || h == 0 {
        return Err(bad(format!("the image is {w}×{h}")));
    }
    use image::DynamicImage as D;
    let bits = match &img {
        D::ImageRgb32F(_) | D::ImageRgba32F(_) => None,
        D::ImageLuma16(_) | D::ImageLumaA16(_) | D::ImageRgb16(_) | D::ImageRgba16(_) => Some(16),
        _ => Some(8),
    };
    let f = img.into_rgb32f();
    let data = f.pixels().map(|p| Rgb::new(p[0], p[1], p[2])).collect();
    Ok(RawImage {
        image: Image {
            width: w,
            height: h,
            data,
        },
        bits,
    })
}

/// Reads an image as linear RGB: float formats as they are, integer formats through sRGB.
pub fn read_linear(path: &Path) -> Result<Image, String> {
    let mut raw = read_raw(path)?;
    if raw.bits.is_some() {
        for c in &mut raw.image.data {
            *c = Rgb::new(srgb_decode(c.x), srgb_decode(c.y), srgb_decode(c.z));
        }
    }
    Ok(raw.image)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn float_formats_round_trip() {
        let d = tempfile::tempdir().unwrap();
        let mut img = Image::new(5, 3);
        for (i, c) in img.data.iter_mut().enumerate() {
            *c = Rgb::new(i as f32 * 0.1, 1.0 / (1.0 + i as f32), 2.5);
        }
        for ext in ["exr", "pfm"] {
            let p = d.path().join(format!("a.{ext}"));
            img.write(&p).unwrap();
            let back = read_linear(&p).unwrap();
            assert_eq!(back, img, "{ext}");
        }
        // RGBE keeps about 1% relative precision on the largest channel.
        let p = d.path().join("a.hdr");
        img.write(&p).unwrap();
        let back = read_linear(&p).unwrap();
        for (a, b) in back.data.iter().zip(&img.data) {
            assert!((*a - *b).abs().max_element() <= 0.01 * b.max_element() + 1e-6);
        }
    }

    #[test]
    fn png_round_trip_within_quantisation() {
        let d = tempfile::tempdir().unwrap();
        let mut img = Image::new(4, 4);
        for (i, c) in img.data.iter_mut().enumerate() {
            *c = Rgb::splat(i as f32 / 16.0);
        }
        let p = d.path().join("a.png");
        img.write(&p).unwrap();
        let back = read_linear(&p).unwrap();
        for (a, b) in back.data.iter().zip(&img.data) {
            // One 8-bit code step of the sRGB curve is at most ~0.0055 in linear terms near 1.
            assert!((*a - *b).abs().max_element() < 0.006, "{a} vs {b}");
        }
        for v in [0.0, 0.002, 0.01, 0.2, 0.5, 1.0] {
            assert!((srgb_decode(srgb_encode(v)) - v).abs() < 1e-5);
        }
    }
}
