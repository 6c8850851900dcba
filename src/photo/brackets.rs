//! Exposure brackets: several 8- or 16-bit photos of one static scene from one viewpoint, each
//! with its exposure time, read and checked together for `matfit hdr` ([`super::hdr`]).

use crate::io::image::{read_raw, Image};
use std::path::{Path, PathBuf};

/// The brackets, their code values scaled to [0, 1] (no response applied).
#[derive(Clone, Debug)]
pub struct Brackets {
    pub paths: Vec<PathBuf>,
    pub images: Vec<Image>,
    /// Exposure time of each image (any unit: the merged radiance is per that unit).
    pub times: Vec<f32>,
    /// Bit depth, the same for every image.
    pub bits: u32,
}

impl Brackets {
    pub fn width(&self) -> usize {
        self.images[0].width
    }

    pub fn height(&self) -> usize {
        self.images[0].height
    }
}

/// Parses one exposure time: a decimal (`0.25`, `2`) or a fraction (`1/60`), finite and > 0.
pub fn parse_time(s: &str) -> Result<f32, String> {
    let bad = || format!("'{s}' is not an exposure time (e.g. 1/60, 0.25 or 2)");
    let t = match s.trim().split_once('/') {
        Some((a, b)) => {
            let a: f64 = a.trim().parse().map_err(|_| bad())?;
            let b: f64 = b.trim().parse().map_err(|_| bad())?;
            a / b
        }
        None => s.trim().parse::<f64>().map_err(|_| bad())?,
    };
    if !(t.is_finite() && t > 0.0) {
        return Err(format!("'{s}': an exposure time must be finite and > 0"));
    }
    Ok(t as f32)
}

/// Parses a comma-separated list of exposure times.
pub fn parse_times(s: &str) -> Result<Vec<f32>, String> {
    s.split(',').map(parse_time).collect()
}

/// Reads the brackets at `paths`, exposed for `times`: at least two, as many times as images,
/// all 8- or 16-bit and all of one size and depth.
pub fn load_brackets(paths: &[PathBuf], times: &[f32]) -> Result<Brackets, String> {
    if paths.len() < 2 {
        return Err(format!(
            "{} image(s) given: merging needs at least two exposures",
            paths.len()
        ));
    }
    if paths.len() != times.len() {
        return Err(format!(
            "{} images but {} exposure times (--times): give one time per image, in order",
            paths.len(),
            times.len()
        ));
    }
    let mut images: Vec<Image> = Vec::new();
    let mut bits = 0;
    for (k, p) in paths.iter().enumerate() {
        let raw = read_raw(p)?;
        let b = raw.bits.ok_or_else(|| {
            format!(
                "{}: a float image (linear already); brackets are 8- or 16-bit PNG/JPEG",
                p.display()
            )
        })?;
        let img = raw.image;
        if k == 0 {
            bits = b;
        } else {
            let first = &images[0];
            if (img.width, img.height) != (first.width, first.height) {
                return Err(size_mismatch(&paths[0], first, p, &img));
            }
            if b != bits {
                return Err(format!(
                    "{}: {b}-bit, but {} is {bits}-bit; give brackets of one depth",
                    p.display(),
                    paths[0].display()
                ));
            }
        }
        images.push(img);
    }
    Ok(Brackets {
        paths: paths.to_vec(),
        images,
        times: times.to_vec(),
        bits,
    })
}

fn size_mismatch(a: &Path, ia: &Image, b: &Path, ib: &Image) -> String {
    format!(
        "{} is {}×{} but {} is {}×{}: brackets must be one size (same camera, same framing)",
        b.display(),
        ib.width,
        ib.height,
        a.display(),
        ia.width,
        ia.height
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_take_fractions_and_decimals() {
        assert_eq!(parse_times("1/60,1/15, 0.25,2").unwrap().len(), 4);
        assert!((parse_time("1/60").unwrap() - 1.0 / 60.0).abs() < 1e-9);
        assert_eq!(parse_time("0.25").unwrap(), 0.25);
        for bad in ["", "x", "1/0", "-1", "0", "1/x", "inf"] {
            assert!(parse_time(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn mismatched_brackets_are_refused_by_name() {
        let d = tempfile::tempdir().unwrap();
        let a = d.path().join("a.png");
        let b = d.path().join("b.png");
        let c = d.path().join("c.png");
        image::GrayImage::new(4, 3).save(&a).unwrap();
        image::GrayImage::new(3, 4).save(&b).unwrap();
        image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::new(4, 3)
            .save(&c)
            .unwrap();
        let e = load_brackets(&[a.clone(), b.clone()], &[1.0, 2.0]).unwrap_err();
        assert!(
            e.contains("b.png is 3×4 but") && e.contains("a.png is 4×3"),
            "{e}"
        );
        let e = load_brackets(&[a.clone(), c.clone()], &[1.0, 2.0]).unwrap_err();
        assert!(e.contains("16-bit") && e.contains("8-bit"), "{e}");
        let e = load_brackets(&[a.clone(), a.clone()], &[1.0]).unwrap_err();
        assert!(e.contains("2 images but 1 exposure times"), "{e}");
        let e = load_brackets(&[a.clone(), d.path().join("none.png")], &[1.0, 2.0]).unwrap_err();
        assert!(e.contains("none.png"), "{e}");
        let ok = load_brackets(&[a.clone(), a], &[1.0, 2.0]).unwrap();
        assert_eq!((ok.width(), ok.height(), ok.bits), (4, 3, 8));
    }
}
