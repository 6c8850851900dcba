//! The front door's augmented reality: an edit of the recovered scene rendered into the photo
//! by differential rendering (`crate::render::composite`).

use super::checks;
use crate::error::{Error, ErrorKind, Kind, Result};
use super::{Observer, PhotoInput};
use crate::io::image::Image;
use crate::photo::{PhotoOptions, Response};
use crate::render::composite::{coverage, differential};
use crate::render::film::RenderOptions;
use crate::scene::edit::Edit;
use crate::scene::Scene;
use std::collections::HashSet;
use std::path::Path;

/// How to composite.
#[derive(Clone, Debug)]
pub struct CompositeOptions {
    /// Samples per pixel of each of the two renders (None: the scene's `[render]` spp).
    pub spp: Option<u32>,
    /// Random seed of both renders (None: the scene's `[render]` seed).
    pub seed: Option<u64>,
    /// Response curve of an 8/16-bit photo.
    pub response: Response,
    /// Exposure factor k of the photo (None: the one in results.json beside the scene file,
    /// else 1).
    pub exposure: Option<f32>,
}

impl Default for CompositeOptions {
    fn default() -> Self {
        CompositeOptions {
            spp: None,
            seed: None,
            response: Response::Srgb,
            exposure: None,
        }
    }
}

/// What [`super::composite`] made.
#[derive(Clone, Debug)]
pub struct Composited {
    /// The photo with the edit rendered into it, in the photo's units.
    pub image: Image,
    /// Pixels changed beyond the Monte Carlo noise.
    pub changed: usize,
    /// Pixels covered by added objects (sub-pixel coverage summed).
    pub covered: f32,
    /// The exposure used, and the rule that chose it.
    pub exposure: f32,
    pub exposure_rule: String,
    /// Samples per pixel of the two renders, and of the third that measures their noise.
    pub spp: u32,
    pub noise_spp: u32,
}

/// How many standard deviations of the renders' noise a change must exceed to count.
pub const NOISE_SIGMAS: f32 = 4.0;

/// See [`super::composite`].
pub fn composite(
    base: &Scene,
    photo: &PhotoInput,
    edits: &[Edit],
    a: &CompositeOptions,
    obs: &dyn Observer,
) -> Result<Composited> {
    if edits.is_empty() {
        return Err(Error::options("nothing to composite: give an edit (--edit FILE, --add, --remove, --move, --material, --scale-light)"));
    }
    if edits.iter().any(Edit::changes_camera) {
        return Err(Error::options("composite renders through the photo's camera: an edit may not replace it (remove [camera], --look-from, --look-at)"));
    }
    let edited = super::edit(base, edits)?;
    checks::require_light(&edited, &checks::scene_warnings(&edited, obs), obs)?;
    let (k, rule) = exposure(a.exposure, &base.path)?;
    let opts = PhotoOptions {
        response: a.response.clone(),
        exposure: Some(k),
    };
    let (w, h) = (base.camera.width, base.camera.height);
    let photo = match photo {
        PhotoInput::Path(p) => crate::photo::load_photo(p, w, h, &opts),
        PhotoInput::Linear(img) => crate::photo::photo_from_raw(
            crate::io::image::RawImage {
                image: img.clone(),
                bits: None,
            },
            Path::new("<photo>"),
            w,
            h,
            &opts,
        ),
    }
    .kind(ErrorKind::Photo)?;
    obs.message(&format!(
        "exposure {k} ({rule}); the photo's values are divided by it, then multiplied back"
    ));
    let ropts = RenderOptions {
        spp: a.spp.unwrap_or(base.render.spp).max(1),
        seed: a.seed.unwrap_or(base.render.seed),
        progress: true,
    };
    let report = |p: &super::Progress| obs.progress(p);
    let cancelled = || obs.cancelled();
    let render = |sc: &Scene, o: &RenderOptions| {
        crate::render::film::render_reporting(sc, &base.camera, o, report, &cancelled)
            .ok_or_else(super::interrupted_render)
    };
    let without = render(base, &ropts)?;
    let with = render(&edited, &ropts)?;
    let old: HashSet<&str> = base.objects.iter().map(|o| o.name.as_str()).collect();
    let added: Vec<bool> = edited
        .objects
        .iter()
        .map(|o| !old.contains(o.name.as_str()))
        .collect();
    let cover = coverage(&edited, &base.camera, &added);
    let mut out = differential(&photo.image, &with, &without, &cover);
    // The two renders share their seed, so their noise mostly cancels, but not where the
    // edit's light changes the paths: a pixel counts as changed when the change is beyond
    // what a third, independent render says the noise is there, as well as above 1%.
    let noise_opts = RenderOptions {
        spp: (ropts.spp / 4).max(1),
        seed: ropts.seed.wrapping_add(1),
        progress: true,
    };
    let other = render(base, &noise_opts)?;
    let sigma = noise_sigma(&without, &other, ropts.spp, noise_opts.spp);
    let changed = out
        .data
        .iter()
        .zip(&photo.image.data)
        .zip(&sigma)
        .filter(|((o, p), s)| {
            let d = (**o - **p).abs();
            (0..3).any(|c| d[c] > 0.01 * p.max_element().max(1e-3) && d[c] > NOISE_SIGMAS * s[c])
        })
        .count();
    for c in &mut out.data {
        *c *= k;
    }
    Ok(Composited {
        image: out,
        changed,
        covered: cover.iter().sum::<f32>(),
        exposure: k,
        exposure_rule: rule,
        spp: ropts.spp,
        noise_spp: noise_opts.spp,
    })
}

/// Per pixel and channel, the standard deviation of the difference of two renders of `spp`
/// samples whose noise does not cancel, from `a` (`spp` samples) and an independent `b` (`spp_b`):
/// the variance of a − b is σ²(1 + spp/spp_b) for σ² that of one render, and twice σ² is the
/// difference's. Averaged over the 3×3 neighbourhood: one pixel's square is too noisy a guess.
fn noise_sigma(a: &Image, b: &Image, spp: u32, spp_b: u32) -> Vec<crate::math::Rgb> {
    let (w, h) = (a.width, a.height);
    let sq: Vec<crate::math::Rgb> = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (*x - *y) * (*x - *y))
        .collect();
    let ratio = 2.0 / (1.0 + spp as f32 / spp_b.max(1) as f32);
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let mut sum = crate::math::Rgb::ZERO;
            let mut n = 0.0;
            for yy in y.saturating_sub(1)..(y + 2).min(h) {
                for xx in x.saturating_sub(1)..(x + 2).min(w) {
                    sum += sq[yy * w + xx];
                    n += 1.0;
                }
            }
            (sum / n * ratio).map(f32::sqrt)
        })
        .collect()
}

/// The exposure: given, else the one the recovery used (results.json beside the scene), else 1;
/// with the rule that chose it, which the user is told.
fn exposure(given: Option<f32>, scene: &Path) -> Result<(f32, String)> {
    if let Some(k) = given {
        if !(k > 0.0 && k.is_finite()) {
            return Err(Error::options(format!(
                "--exposure must be positive, got {k}"
            )));
        }
        return Ok((k, "given".into()));
    }
    let results = scene.with_file_name("results.json");
    if let Ok(text) = std::fs::read_to_string(&results) {
        let k = serde_json::from_str::<serde_json::Value>(&text)
            .ok()
            .and_then(|v| v["inputs"]["exposure"].as_f64());
        match k {
            Some(k) if k > 0.0 && k.is_finite() => {
                return Ok((
                    k as f32,
                    format!("the recovery's, from {}", results.display()),
                ))
            }
            _ => {
                return Err(Error::recover(format!(
                    "{}: has no positive inputs.exposure; give --exposure",
                    results.display()
                ))
                .at(&results, None))
            }
        }
    }
    Ok((
        1.0,
        "default: no --exposure and no results.json beside the scene".into(),
    ))
}
