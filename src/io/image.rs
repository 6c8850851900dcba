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

    /// Writes the image, choosing the format by extension (.exr, .hdr, .pfm, .png, .jpg),
    /// atomically.
    pub fn write(&self, path: &Path) -> Result<(), crate::error::Error> {
        self.write_file(path).map_err(crate::error::Error::io)
    }

    fn write_file(&self, path: &Path) -> Result<(), String> {
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

/// Whether the file holds floating-point (linear) values by its extension: EXR, Radiance HDR
/// and PFM, as matfit reads and writes them.
pub fn is_float_format(path: &Path) -> bool {
    matches!(extension(path).as_str(), "exr" | "hdr" | "pfm")
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

pub use super::MAX_PIXELS;

/// Reads an image file's values without applying a response curve.
pub fn read_raw(path: &Path) -> Result<RawImage, String> {
    check_image_file(path)?;
    let bytes = std::fs::read(path).map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    decode_raw(&bytes, path)
}

/// Largest image file read: room for [`MAX_PIXELS`] pixels as 32-bit float RGBA, and a margin.
pub const MAX_FILE_BYTES: u64 = MAX_PIXELS as u64 * 16 + (1 << 20);

/// Checks, before reading it, that `path` is a regular file no larger than [`MAX_FILE_BYTES`]
/// (not a folder, a device or a pipe that would never end).
pub fn check_image_file(path: &Path) -> Result<(), String> {
    let m = std::fs::metadata(path).map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    if m.is_dir() {
        return Err(format!("{}: is a folder, not an image", path.display()));
    }
    if !m.is_file() {
        return Err(format!("{}: is not a regular file", path.display()));
    }
    if m.len() == 0 {
        return Err(format!("{}: the file is empty (0 bytes)", path.display()));
    }
    if m.len() > MAX_FILE_BYTES {
        return Err(format!(
            "{}: the file is {} MB, more than any image matfit reads ({} megapixels at most); \
             downsample it",
            path.display(),
            m.len() >> 20,
            MAX_PIXELS >> 20
        ));
    }
    Ok(())
}

/// Decodes an image file's bytes without applying a response curve. `path` names the file in
/// messages; its extension chooses PFM (the other formats are recognised by their content).
pub fn decode_raw(bytes: &[u8], path: &Path) -> Result<RawImage, String> {
    decode_raw_checked(bytes, path, |_, _| Ok(()))
}

/// [`decode_raw`], calling `check(width, height)` as soon as the header gives the size and
/// before the pixels are decoded (its error is returned as it is): a photo of the wrong size is
/// refused without decoding it.
pub fn decode_raw_checked(
    bytes: &[u8],
    path: &Path,
    check: impl Fn(usize, usize) -> Result<(), String>,
) -> Result<RawImage, String> {
    let bad = |e: String| format!("{}: {e}", path.display());
    let too_big = |w: u64, h: u64| {
        bad(format!(
            "the image is {w}×{h}, more than matfit's limit of {} megapixels; downsample it \
             (and scale the camera: width, height and fx, fy, cx, cy)",
            MAX_PIXELS >> 20
        ))
    };
    if bytes.is_empty() {
        return Err(bad("the file is empty (0 bytes)".into()));
    }
    if extension(path) == "pfm" {
        // (The PFM decoder allocates only once the file is known to hold every pixel.)
        let (width, height, data) = super::pfm::decode(bytes).map_err(bad)?;
        check(width, height)?;
        return Ok(RawImage {
            image: Image {
                width,
                height,
                data,
            },
            bits: None,
        });
    }
    // The EXR decoder allocates by the header's data window before it reads the header's end:
    // check the windows first.
    if let Some((w, h)) = exr_data_windows(bytes)
        .into_iter()
        .flatten()
        .find(|&(w, h)| w.saturating_mul(h) > MAX_PIXELS as u64)
    {
        return Err(too_big(w, h));
    }
    let reader = || -> Result<image::ImageReader<std::io::Cursor<&[u8]>>, String> {
        let mut r = image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| bad(e.to_string()))?;
        if r.format().is_none() {
            return Err(bad(
                "not an image file matfit can read (EXR, HDR, PFM, PNG, JPEG)".into(),
            ));
        }
        // Room for the largest allowed image as 32-bit float RGBA, the widest layout decoded.
        let mut limits = image::Limits::default();
        limits.max_alloc = Some(MAX_PIXELS as u64 * 16 + (64 << 20));
        r.limits(limits);
        Ok(r)
    };
    // The header first: refuse giant images before the decoder allocates for them.
    let (w, h) = reader()?
        .into_dimensions()
        .map_err(|e| bad(format!("cannot decode (truncated or corrupt file?): {e}")))?;
    if w == 0 || h == 0 {
        return Err(bad(format!("the image is {w}×{h}")));
    }
    if w as u64 * h as u64 > MAX_PIXELS as u64 {
        return Err(too_big(w as u64, h as u64));
    }
    check(w as usize, h as usize)?;
    let img = reader()?
        .decode()
        .map_err(|e| bad(format!("cannot decode (truncated or corrupt file?): {e}")))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w == 0 || h == 0 {
        return Err(bad(format!("the image is {w}×{h}")));
    }
    if w * h > MAX_PIXELS {
        return Err(too_big(w as u64, h as u64));
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

/// The data windows' sizes (width, height) of every header of an OpenExr file, None if `bytes`
/// are not an EXR file or its headers do not parse (the decoder then says what is wrong).
/// Layout: magic, version + flags, then per part a list of attributes (name NUL, type NUL, i32
/// size, value) closed by a NUL; a multi-part file closes the list of headers with another NUL.
fn exr_data_windows(bytes: &[u8]) -> Option<Vec<(u64, u64)>> {
    if !bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) || bytes.len() < 8 {
        return None;
    }
    let multipart = bytes[5] & 0x10 != 0;
    let mut pos = 8;
    let cstr = |pos: &mut usize| -> Option<&[u8]> {
        let len = bytes.get(*pos..)?.iter().position(|&b| b == 0)?;
        let s = &bytes[*pos..*pos + len];
        *pos += len + 1;
        Some(s)
    };
    let mut windows = Vec::new();
    loop {
        let mut attrs = 0;
        loop {
            let name = cstr(&mut pos)?;
            if name.is_empty() {
                break;
            }
            let kind = cstr(&mut pos)?;
            let size = i32::from_le_bytes(bytes.get(pos..pos + 4)?.try_into().ok()?);
            pos += 4;
            let size = usize::try_from(size).ok()?;
            let value = bytes.get(pos..pos.checked_add(size)?)?;
            pos += size;
            attrs += 1;
            if name == b"dataWindow" && kind == b"box2i" && size == 16 {
                let v = |i: usize| i32::from_le_bytes(value[4 * i..4 * i + 4].try_into().unwrap());
                let (w, h) = (v(2) as i64 - v(0) as i64 + 1, v(3) as i64 - v(1) as i64 + 1);
                if w > 0 && h > 0 {
                    windows.push((w as u64, h as u64));
                }
            }
        }
        // A single-part file has one header; a multi-part one ends with an empty header.
        if !multipart || attrs == 0 || bytes.get(pos) == Some(&0) {
            break;
        }
    }
    Some(windows)
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
