//! The exposure factor k (photo value = k × radiance): given, or calibrated
//!
//! - from a **grey card**, a group of known diffuse reflectance ρ: its usable pixels are rendered
//!   with the card at ρ (the rest of the scene with the materials the scene file gives, which
//!   only matter through interreflection), and k = Σ photo / Σ rendering over the card's
//!   inliers ([`estimate::group_ratio`]); a card lit mostly by the known lights makes this
//!   nearly independent of the unknown materials;
//! - from the **visible light sources**, whose emitted radiance the scene gives: k = median over
//!   the emitters' usable, front-facing pixels of photo / emission. In an 8-bit photo lights are
//!   usually clipped; their saturated pixels are invalid, and if none is left the calibration
//!   fails with a message saying so.
//!
//! Both work on the channel mean; the per-channel factors are reported too (they differ when
//! the photo's white balance is not the scene's).

use crate::io::image::Image;
use crate::math::{Rgb, Vec2};
use crate::photo::{robust, Photo};
use crate::prepare::{estimate, UsableMask};
use crate::render::aov::IndexBuffers;
use crate::render::film::render_pixel;
use crate::render::PathTracer;
use crate::scene::{Material, Scene};
use rayon::prelude::*;

/// Where the exposure factor comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum ExposureSource {
    Given(f32),
    GreyCard { group: String, rho: Rgb },
    Lights,
}

/// The outcome of a calibration, for the log and the report.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ExposureCalibration {
    /// k on the channel mean: what the photo is divided by.
    pub factor: f32,
    /// k per channel.
    pub per_channel: [f32; 3],
    /// Pixels that decided it.
    pub pixels: usize,
    pub source: String,
}

/// Paths rendered for a grey card in all: with a fixed count per pixel, a small card's sum
/// would be the noisy part of the exposure.
const CARD_PATHS: usize = 1 << 18;

/// Exposure from a grey card (see the module documentation). At most `max_pixels` of the card's
/// usable pixels are rendered, with 64 to 1024 samples each ([`CARD_PATHS`] in all).
pub fn from_grey_card(
    scene: &Scene,
    photo: &Photo,
    mask: &UsableMask,
    group: &str,
    rho: Rgb,
    max_pixels: usize,
) -> Result<ExposureCalibration, String> {
    let g = scene.group_index(group).ok_or_else(|| {
        let names: Vec<&str> = scene.groups.iter().map(|g| g.name.as_str()).collect();
        format!(
            "grey card: the scene has no group '{group}' (groups: {})",
            names.join(", ")
        )
    })?;
    if !(rho.min_element() > 0.0 && rho.max_element() <= 1.0) {
        return Err(format!(
            "grey card '{group}': its reflectance must be in (0, 1], got {rho}"
        ));
    }
    let px = mask.pixels_of(g);
    if px.is_empty() {
        return Err(format!(
            "grey card '{group}': no usable pixel in the photo ({} visible); cannot calibrate \
             the exposure from it",
            mask.stats[g].visible
        ));
    }
    let mut sc = scene.clone();
    for &o in &scene.groups[g].objects {
        sc.objects[o].material = Material::Diffuse { rho_d: rho };
    }
    let step = px.len().div_ceil(max_pixels.max(1));
    let chosen: Vec<usize> = px.iter().copied().step_by(step).collect();
    let spp = (CARD_PATHS / chosen.len()).clamp(64, 1024) as u32;
    let pt = PathTracer::new(&sc);
    let w = mask.width;
    let values: Vec<Rgb> = chosen
        .par_iter()
        .map(|&i| render_pixel(&pt, &sc.camera, i % w, i / w, spp, sc.render.seed))
        .collect();
    let mut reference = Image::new(w, mask.height);
    for (&i, v) in chosen.iter().zip(values) {
        reference.data[i] = v;
    }
    let mut sub = mask.clone();
    for (i, gi) in sub.group.iter_mut().enumerate() {
        if *gi == g as i32 && reference.data[i] == Rgb::ZERO {
            *gi = -1;
        }
    }
    let r = estimate::group_ratio(photo, &reference, &sub, g).ok_or_else(|| {
        format!("grey card '{group}': the rendering of the card is black (is it lit?)")
    })?;
    check_factor(r.ratio_mean, &format!("grey card '{group}'"))?;
    Ok(ExposureCalibration {
        factor: r.ratio_mean,
        per_channel: r.ratio.to_array(),
        pixels: r.inliers,
        source: format!("grey card '{group}' (ρ {})", fmt_rgb(rho)),
    })
}

/// Exposure from the visible emitters (see the module documentation).
pub fn from_lights(
    scene: &Scene,
    photo: &Photo,
    ib: &IndexBuffers,
    mask: &UsableMask,
) -> Result<ExposureCalibration, String> {
    let w = ib.width;
    let mut visible = 0;
    let mut clipped = 0;
    let mut ratios: [Vec<f32>; 4] = Default::default();
    for i in 0..ib.object.len() {
        let o = ib.object[i];
        if o < 0 || !scene.objects[o as usize].is_emitter() {
            continue;
        }
        let e = scene.objects[o as usize].emission;
        // One-sided lights: the back of a light is black, not a view of its radiance.
        let ray = scene
            .camera
            .ray(Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5));
        match scene.intersect(&ray, f32::INFINITY) {
            Some(h) if h.ng.dot(ray.d) < 0.0 => {}
            _ => continue,
        }
        visible += 1;
        if mask.group[i] < 0 {
            if photo.valid[i] {
                continue; // band or edge: the outline of the light
            }
            clipped += 1;
            continue;
        }
        let p = photo.image.data[i];
        for ch in 0..3 {
            if e[ch] > 0.0 {
                ratios[ch].push(p[ch] / e[ch]);
            }
        }
        ratios[3].push((p.x + p.y + p.z) / (e.x + e.y + e.z));
    }
    if visible == 0 {
        return Err(
            "exposure from the lights: no light source is seen (front side) by the camera; \
             give --exposure or a grey card"
                .into(),
        );
    }
    let n = ratios[3].len();
    if n == 0 {
        return Err(format!(
            "exposure from the lights: the lights cover {visible} pixels but none is usable \
             ({clipped} saturated in the photo, the others on their outline); give --exposure \
             or a grey card, or use an HDR photo"
        ));
    }
    let mut per = [0.0f32; 3];
    for (ch, p) in per.iter_mut().enumerate() {
        *p = robust::median(&mut ratios[ch]).unwrap_or(0.0);
    }
    let factor = robust::median(&mut ratios[3]).unwrap_or(0.0);
    check_factor(factor, "the lights")?;
    Ok(ExposureCalibration {
        factor,
        per_channel: per,
        pixels: n,
        source: format!("{n} pixels of the lights ({clipped} saturated ones left out)"),
    })
}

fn check_factor(k: f32, what: &str) -> Result<(), String> {
    if k > 0.0 && k.is_finite() {
        Ok(())
    } else {
        Err(format!(
            "exposure from {what}: the photo is black there (factor {k}); cannot calibrate"
        ))
    }
}

fn fmt_rgb(c: Rgb) -> String {
    if c.x == c.y && c.y == c.z {
        format!("{}", c.x)
    } else {
        format!("{}, {}, {}", c.x, c.y, c.z)
    }
}
