//! Robust per-group ratios between the photo and a rendering, over the group's usable pixels.
//!
//! This is the diffuse correction of the notes (§4.1): for a Lambertian group rendered with
//! reflectance ρ_ref, the photo's radiance is ρ/ρ_ref times the rendering's, so
//! ρ ≈ ρ_ref × Σ L_photo / Σ L_ref. Two robustifications:
//!
//! - outliers are found on the local ratio L_photo / L_ref — sums over a (2r+1)² window of the
//!   group's usable pixels, r = [`RATIO_WINDOW`] — with the planar approximation
//!   ([`robust::planar_inliers`]): a plane (not a constant) so that slow drifts of the ratio
//!   (interreflection from surfaces whose reflectance is still wrong) are not taken for
//!   outliers, and far points — an unmodelled object, a strip of a neighbour — are dropped.
//!   The window matters: per-pixel noise (sensor, or a Monte Carlo rendering's heavy-tailed
//!   fireflies) would otherwise be trimmed asymmetrically and bias the estimate (by 15% with an
//!   8-spp rendered photo); over a window it is averaged before the test, while an object
//!   larger than the window still stands out;
//! - the estimate is then a ratio of *sums* over the inliers, which is not biased by noise in
//!   the rendering the way a mean of per-pixel ratios is.
//!
//! The same ratio serves the exposure calibration (a grey card: a group of known ρ).

use crate::io::image::Image;
use crate::math::Rgb;
use crate::photo::{robust, Photo};
use crate::prepare::UsableMask;

/// Outlier threshold in robust σ of the local ratio.
pub const RATIO_OUTLIER_K: f32 = 3.5;
/// Radius of the window of the local ratio, in pixels.
pub const RATIO_WINDOW: usize = 3;

/// The ratio photo / reference of one group.
#[derive(Clone, Debug, PartialEq)]
pub struct RatioEstimate {
    /// Σ photo / Σ reference over the inliers, per channel (0 where the reference is 0).
    pub ratio: Rgb,
    /// The same for the channel mean (the luminance used by the exposure).
    pub ratio_mean: f32,
    pub inliers: usize,
    pub outliers: usize,
}

/// Robust ratio photo / `reference` over the usable pixels of group `g`. `reference` is a
/// rendering of the model through the same camera (only the group's pixels are read). None if
/// the group has no usable pixel with a non-zero reference.
pub fn group_ratio(
    photo: &Photo,
    reference: &Image,
    mask: &UsableMask,
    g: usize,
) -> Option<RatioEstimate> {
    let w = mask.width;
    let px: Vec<usize> = mask
        .pixels_of(g)
        .into_iter()
        .filter(|&i| reference.data[i].is_finite() && reference.data[i].max_element() > 0.0)
        .collect();
    if px.is_empty() {
        return None;
    }
    let mean = |c: Rgb| ((c.x + c.y + c.z) / 3.0) as f64;
    // Summed-area tables of the group's photo and reference luminance.
    let h = mask.height;
    let (mut sat_p, mut sat_r) = (
        vec![0.0f64; (w + 1) * (h + 1)],
        vec![0.0f64; (w + 1) * (h + 1)],
    );
    let mut inside = vec![false; w * h];
    for &i in &px {
        inside[i] = true;
    }
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let (a, b) = if inside[i] {
                (mean(photo.image.data[i]), mean(reference.data[i]))
            } else {
                (0.0, 0.0)
            };
            let j = (y + 1) * (w + 1) + x + 1;
            sat_p[j] = a + sat_p[j - 1] + sat_p[j - w - 1] - sat_p[j - w - 2];
            sat_r[j] = b + sat_r[j - 1] + sat_r[j - w - 1] - sat_r[j - w - 2];
        }
    }
    let rect = |sat: &[f64], x0: usize, y0: usize, x1: usize, y1: usize| {
        sat[y1 * (w + 1) + x1] - sat[y0 * (w + 1) + x1] - sat[y1 * (w + 1) + x0]
            + sat[y0 * (w + 1) + x0]
    };
    let r = RATIO_WINDOW;
    let pts: Vec<(f32, f32, f32)> = px
        .iter()
        .map(|&i| {
            let (x, y) = (i % w, i / w);
            let (x0, y0, x1, y1) = (
                x.saturating_sub(r),
                y.saturating_sub(r),
                (x + r + 1).min(w),
                (y + r + 1).min(h),
            );
            let a = rect(&sat_p, x0, y0, x1, y1);
            let b = rect(&sat_r, x0, y0, x1, y1);
            (x as f32, y as f32, (a / b) as f32)
        })
        .collect();
    let mut rs: Vec<f32> = pts.iter().map(|p| p.2).collect();
    let med = robust::median(&mut rs).unwrap_or(0.0).abs();
    let (_, keep) = robust::planar_inliers(&pts, RATIO_OUTLIER_K, 1e-3 * med.max(1e-12));
    let (mut sp, mut sr) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
    let mut inliers = 0;
    for (&i, &k) in px.iter().zip(&keep) {
        if k {
            sp += photo.image.data[i].as_dvec3();
            sr += reference.data[i].as_dvec3();
            inliers += 1;
        }
    }
    let div = |a: f64, b: f64| if b > 0.0 { (a / b) as f32 } else { 0.0 };
    Some(RatioEstimate {
        ratio: Rgb::new(div(sp.x, sr.x), div(sp.y, sr.y), div(sp.z, sr.z)),
        ratio_mean: div(sp.x + sp.y + sp.z, sr.x + sr.y + sr.z),
        inliers,
        outliers: px.len() - inliers,
    })
}

/// The diffuse estimate of group `g`: ρ_ref × (robust ratio photo / reference), where
/// `reference` was rendered with the group's diffuse reflectance set to `rho_ref`.
pub fn diffuse_estimate(
    photo: &Photo,
    reference: &Image,
    rho_ref: Rgb,
    mask: &UsableMask,
    g: usize,
) -> Option<Rgb> {
    group_ratio(photo, reference, mask, g).map(|r| r.ratio * rho_ref)
}
