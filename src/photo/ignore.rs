//! The user's mask of pixels to ignore (`--ignore-mask FILE`): what the model does not contain —
//! a person, an unmodelled object, a reflection of the photographer — painted over the photo.
//!
//! The file is a PNG (or any format the `image` crate reads here) of the photo's size, of any
//! bit depth, grey or RGB, with or without alpha. The rule, stated once:
//!
//! - with an alpha channel, alpha alone decides: a pixel whose alpha is non-zero is ignored
//!   (paint on a transparent layer; the colour under transparent pixels does not matter);
//! - without one, a pixel any of whose channels is non-zero is ignored (white on black).
//!
//! Ignored pixels are usable for no group (their own reject reason, counted per group), and the
//! registration does not look at them ([`near_ignored`]); exposure calibrations read only usable
//! pixels, so they leave them out too.

use crate::photo::Photo;
use std::path::Path;

/// Reads the mask at `path` for a photo of `width` × `height` pixels: true = ignore the pixel.
pub fn load_ignore_mask(path: &Path, width: u32, height: u32) -> Result<Vec<bool>, String> {
    let bad = |e: String| format!("{}: the ignore mask {e}", path.display());
    crate::io::image::check_image_file(path).map_err(|e| format!("ignore mask: {e}"))?;
    let reader = || {
        image::ImageReader::open(path)
            .and_then(|r| r.with_guessed_format())
            .map_err(|e| bad(format!("cannot be read: {e}")))
    };
    let (w, h) = reader()?
        .into_dimensions()
        .map_err(|e| bad(format!("cannot be decoded: {e}")))?;
    if (w, h) != (width, height) {
        return Err(bad(format!(
            "is {w}×{h} but the photo is {width}×{height}; it must be the photo's size"
        )));
    }
    let img = reader()?
        .decode()
        .map_err(|e| bad(format!("cannot be decoded: {e}")))?;
    Ok(if img.color().has_alpha() {
        img.into_rgba16().pixels().map(|p| p[3] > 0).collect()
    } else {
        img.into_rgb16()
            .pixels()
            .map(|p| p.0.iter().any(|&c| c > 0))
            .collect()
    })
}

/// Pixels within `radius` (chessboard distance) of an ignored pixel of `photo`: an edge filter
/// of that reach sees the unmodelled object there.
pub fn near_ignored(photo: &Photo, radius: usize) -> Vec<bool> {
    let (w, h) = (photo.image.width, photo.image.height);
    let mut out = vec![false; w * h];
    for (i, _) in photo.ignored.iter().enumerate().filter(|(_, &m)| m) {
        let (x, y) = (i % w, i / w);
        for yy in y.saturating_sub(radius)..(y + radius + 1).min(h) {
            for xx in x.saturating_sub(radius)..(x + radius + 1).min(w) {
                out[yy * w + xx] = true;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn save(dir: &Path, name: &str, img: image::DynamicImage) -> std::path::PathBuf {
        let p = dir.join(name);
        img.save(&p).unwrap();
        p
    }

    #[test]
    fn grey_rgb_16_bit_and_alpha_masks_follow_the_rule() {
        let d = tempfile::tempdir().unwrap();
        // 8-bit grey: only the non-zero pixel (1 of 255 counts).
        let mut g = image::GrayImage::new(4, 3);
        g.put_pixel(1, 2, image::Luma([1]));
        let p = save(d.path(), "g.png", g.into());
        let m = load_ignore_mask(&p, 4, 3).unwrap();
        assert_eq!(m.iter().filter(|&&b| b).count(), 1);
        assert!(m[2 * 4 + 1]);
        // 16-bit RGB: one channel non-zero is enough.
        let mut c = image::ImageBuffer::<image::Rgb<u16>, _>::new(4, 3);
        c.put_pixel(3, 0, image::Rgb([0, 0, 7]));
        let p = save(d.path(), "c.png", c.into());
        let m = load_ignore_mask(&p, 4, 3).unwrap();
        assert_eq!(m.iter().filter(|&&b| b).count(), 1);
        assert!(m[3]);
        // RGBA: alpha decides; white but transparent is kept, black but opaque is ignored.
        let mut a = image::RgbaImage::new(4, 3);
        for p in a.pixels_mut() {
            *p = image::Rgba([255, 255, 255, 0]);
        }
        a.put_pixel(0, 1, image::Rgba([0, 0, 0, 255]));
        let p = save(d.path(), "a.png", a.into());
        let m = load_ignore_mask(&p, 4, 3).unwrap();
        assert_eq!(m.iter().filter(|&&b| b).count(), 1);
        assert!(m[4]);
    }

    #[test]
    fn a_mask_of_another_size_or_not_an_image_is_refused_by_name() {
        let d = tempfile::tempdir().unwrap();
        let p = save(d.path(), "m.png", image::GrayImage::new(5, 3).into());
        let e = load_ignore_mask(&p, 4, 3).unwrap_err();
        assert!(
            e.contains("m.png") && e.contains("5×3") && e.contains("4×3"),
            "{e}"
        );
        let t = d.path().join("t.png");
        std::fs::write(&t, "not a png").unwrap();
        let e = load_ignore_mask(&t, 4, 3).unwrap_err();
        assert!(e.contains("t.png") && e.contains("ignore mask"), "{e}");
        let e = load_ignore_mask(&d.path().join("none.png"), 4, 3).unwrap_err();
        assert!(e.contains("none.png"), "{e}");
    }
}
