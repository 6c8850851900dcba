//! Strong edges of the photograph: Sobel on the log-luminance after a 3×3 binomial blur.
//!
//! Log-luminance makes the detector independent of the exposure and of the overall brightness
//! of a region: the response is the relative change of intensity per pixel. The blur keeps
//! sensor (or Monte Carlo) noise from looking like edges. The threshold is relative in two ways:
//! it is a contrast (a step of ln-contrast Δ gives a response Δ/2 on the pixels either side), and
//! it never falls below `noise_factor` × the median response over the image, so a noisy photo
//! does not turn every pixel into an edge.

use crate::photo::robust::median;
use crate::photo::Photo;

/// Log-luminance gradient magnitude per pixel (ln units per pixel).
pub fn log_gradient(photo: &Photo) -> Vec<f32> {
    let img = &photo.image;
    let (w, h) = (img.width, img.height);
    let lum: Vec<f32> = img
        .data
        .iter()
        .zip(&photo.valid)
        .map(|(c, &v)| if v { (c.x + c.y + c.z) / 3.0 } else { f32::NAN })
        .collect();
    // A floor well below the typical level: black regions must not amplify noise in ln.
    let mut pos: Vec<f32> = lum.iter().copied().filter(|v| *v > 0.0).collect();
    let floor = median(&mut pos).unwrap_or(1.0) * 1e-2;
    // Invalid pixels take the median so they do not make edges of their own.
    let fill = (floor * 100.0).ln();
    let ln: Vec<f32> = lum
        .iter()
        .map(|&v| {
            if v.is_nan() {
                fill
            } else {
                (v.max(0.0) + floor).ln()
            }
        })
        .collect();
    let at = |v: &[f32], x: i64, y: i64| {
        v[y.clamp(0, h as i64 - 1) as usize * w + x.clamp(0, w as i64 - 1) as usize]
    };
    let mut blur = vec![0.0f32; w * h];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let mut s = 0.0;
            for (dy, wy) in [(-1, 1.0), (0, 2.0), (1, 1.0)] {
                for (dx, wx) in [(-1, 1.0), (0, 2.0), (1, 1.0)] {
                    s += wx * wy * at(&ln, x + dx, y + dy);
                }
            }
            blur[y as usize * w + x as usize] = s / 16.0;
        }
    }
    let mut g = vec![0.0f32; w * h];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let p = |dx, dy| at(&blur, x + dx, y + dy);
            let gx = (p(1, -1) + 2.0 * p(1, 0) + p(1, 1)) - (p(-1, -1) + 2.0 * p(-1, 0) + p(-1, 1));
            let gy = (p(-1, 1) + 2.0 * p(0, 1) + p(1, 1)) - (p(-1, -1) + 2.0 * p(0, -1) + p(1, -1));
            g[y as usize * w + x as usize] = (gx * gx + gy * gy).sqrt() / 8.0;
        }
    }
    g
}

/// Pixels on a strong edge: response above max(`threshold`, `noise_factor` × median response).
/// Returns the flags and the threshold actually used.
pub fn strong_edges(photo: &Photo, threshold: f32, noise_factor: f32) -> (Vec<bool>, f32) {
    let g = log_gradient(photo);
    let mut all = g.clone();
    let t = threshold.max(noise_factor * median(&mut all).unwrap_or(0.0));
    (g.iter().map(|&v| v > t).collect(), t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::image::Image;
    use crate::math::Rgb;

    #[test]
    fn finds_a_step_and_ignores_gentle_shading() {
        let mut img = Image::new(40, 20);
        for y in 0..20 {
            for x in 0..40 {
                // A 1%-per-pixel gradient, and a ×2 step at x = 20.
                let v = (1.0 + 0.01 * x as f32) * if x >= 20 { 2.0 } else { 1.0 };
                img.set(x, y, Rgb::splat(v));
            }
        }
        let (e, t) = strong_edges(&Photo::from_linear(img), 0.1, 4.0);
        assert!(t >= 0.1);
        for y in 0..20 {
            for x in 0..40 {
                let near = (18..=21).contains(&x);
                if !near {
                    assert!(!e[y * 40 + x], "({x}, {y})");
                }
            }
            assert!(e[y * 40 + 19] && e[y * 40 + 20], "row {y}");
        }
    }
}
