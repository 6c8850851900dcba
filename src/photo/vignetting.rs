//! Vignetting: a lens passes less light towards the edges of its image, so a real photo of a
//! uniformly lit wall is darker in its corners. Left in, the fall-off looks to the fitter like
//! a shading the model cannot make (a texture, a glossy lobe). It is divided out of the photo
//! before anything reads it, by one of:
//!
//! * a radial polynomial V(r) = 1 + a1 r² + a2 r⁴ + a3 r⁶ (Lensfun's "pa" vignetting model, the
//!   one Lensfun's database and most raw converters give), with r the distance from the
//!   principal point divided by the half-diagonal of the image (r = 1 in a centred image's
//!   corners);
//! * a flat-field image: a photo of a uniform, uniformly lit white target through the same lens
//!   and settings, V = its luminance / its largest luminance. Pixels where V < 5% are too dark
//!   to correct and become invalid.

use super::Photo;
use crate::math::luminance_mean;
use std::path::PathBuf;

#[derive(Clone, Debug, PartialEq)]
pub enum Vignetting {
    Radial([f32; 3]),
    FlatField(PathBuf),
}

/// Parses `a1,a2,a3`.
pub fn parse_radial(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("expected A1,A2,A3 (e.g. -0.3,0.05,0), got {s:?}"))?;
    match v[..] {
        [a, b, c] if v.iter().all(|x| x.is_finite()) => Ok([a, b, c]),
        _ => Err(format!("expected three finite numbers A1,A2,A3, got {s:?}")),
    }
}

/// Divides `photo` by the vignetting V (module comment), the principal point at film position
/// (cx, cy). Returns how many pixels became invalid (flat field too dark there).
pub fn correct(photo: &mut Photo, v: &Vignetting, cx: f32, cy: f32) -> Result<usize, String> {
    let (w, h) = (photo.image.width, photo.image.height);
    let factors: Vec<f32> = match v {
        Vignetting::Radial([a1, a2, a3]) => {
            let half_diag = 0.5 * ((w * w + h * h) as f32).sqrt();
            let f: Vec<f32> = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f32 + 0.5 - cx, (i / w) as f32 + 0.5 - cy);
                    let r2 = (x * x + y * y) / (half_diag * half_diag);
                    1.0 + r2 * (a1 + r2 * (a2 + r2 * a3))
                })
                .collect();
            if let Some(m) = f.iter().copied().reduce(f32::min).filter(|m| !(*m > 0.0)) {
                return Err(format!(
                    "--vignetting {a1},{a2},{a3} falls to {m} inside the image: not a vignetting \
                     (V must stay positive; r is 1 at the half-diagonal)"
                ));
            }
            f
        }
        Vignetting::FlatField(path) => {
            let flat = crate::io::image::read_linear(path)
                .map_err(|e| format!("flat field {}: {e}", path.display()))?;
            if (flat.width, flat.height) != (w, h) {
                return Err(format!(
                    "flat field {} is {}×{}, the photo {w}×{h}: it must be taken with the same \
                     camera and size",
                    path.display(),
                    flat.width,
                    flat.height
                ));
            }
            let lum: Vec<f32> = flat.data.iter().map(|&c| luminance_mean(c)).collect();
            let max = lum.iter().copied().fold(0.0f32, f32::max);
            if !(max > 0.0 && max.is_finite()) {
                return Err(format!("flat field {} is black", path.display()));
            }
            lum.iter().map(|l| l / max).collect()
        }
    };
    let mut dark = 0;
    for ((c, valid), f) in photo
        .image
        .data
        .iter_mut()
        .zip(&mut photo.valid)
        .zip(factors)
    {
        if f < 0.05 {
            dark += usize::from(*valid);
            *valid = false;
        } else {
            *c /= f;
        }
    }
    Ok(dark)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::image::Image;
    use crate::math::Rgb;

    #[test]
    fn radial_vignetting_is_divided_out_and_bad_models_are_refused() {
        let mut img = Image::new(40, 30);
        img.data.fill(Rgb::splat(2.0));
        // Vignette it: corners (r = 1 at the half-diagonal) get 1 − 0.3 + 0.05 = 0.75.
        let a = [-0.3, 0.05, 0.0];
        let hd2 = 0.25 * (40.0f32 * 40.0 + 30.0 * 30.0);
        for (i, c) in img.data.iter_mut().enumerate() {
            let (x, y) = ((i % 40) as f32 + 0.5 - 20.0, (i / 40) as f32 + 0.5 - 15.0);
            let r2 = (x * x + y * y) / hd2;
            *c *= 1.0 + a[0] * r2 + a[1] * r2 * r2;
        }
        assert!(img.get(0, 0).x < 1.6);
        let mut p = Photo::from_linear(img);
        assert_eq!(correct(&mut p, &Vignetting::Radial(a), 20.0, 15.0), Ok(0));
        assert!(p.image.data.iter().all(|c| (c.x - 2.0).abs() < 1e-5));
        let e = correct(&mut p, &Vignetting::Radial([-2.0, 0.0, 0.0]), 20.0, 15.0).unwrap_err();
        assert!(e.contains("positive"), "{e}");
        assert_eq!(parse_radial("-0.3, 0.05,0"), Ok([-0.3, 0.05, 0.0]));
        assert!(parse_radial("-0.3,0.05").is_err());
    }
}
