//! `matfit composite`: an edit of the recovered scene rendered into the photo
//! (`matfit::render::composite`).

use super::checks;
use super::*;
use crate::outln;
use anyhow::{bail, Result};
use matfit::io::atomic::check_output_file;
use matfit::photo::{load_photo, PhotoOptions, Response};
use matfit::render::composite::{coverage, differential};
use matfit::render::film::{render, RenderOptions};
use matfit::scene::edit::{load_edited, Edit};
use matfit::scene::load_scene;
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub struct CompositeArgs {
    pub scene: PathBuf,
    pub photo: PathBuf,
    pub output: PathBuf,
    pub edits: Vec<Edit>,
    pub spp: Option<u32>,
    pub seed: Option<u64>,
    pub response: Response,
    pub exposure: Option<f32>,
}

pub fn run(a: &CompositeArgs) -> Result<()> {
    let ext = a
        .output
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if !["exr", "hdr", "pfm", "png"].contains(&ext.as_str()) {
        bail!(
            "{}: output must end in .png, .exr, .hdr or .pfm",
            a.output.display()
        );
    }
    if a.edits.is_empty() {
        bail!("nothing to composite: give an edit (--edit FILE, --add, --remove, --move, --material, --scale-light)");
    }
    if a.edits.iter().any(Edit::changes_camera) {
        bail!("composite renders through the photo's camera: an edit may not replace it (remove [camera], --look-from, --look-at)");
    }
    let base = load_scene(&a.scene)?;
    let edited = load_edited(&a.scene, &a.edits)?;
    checks::require_light(&edited, &checks::scene_warnings(&edited))?;
    let (k, rule) = exposure(a.exposure, &a.scene)?;
    let opts = PhotoOptions {
        response: a.response.clone(),
        exposure: Some(k),
    };
    let photo = load_photo(&a.photo, base.camera.width, base.camera.height, &opts)
        .map_err(anyhow::Error::msg)?;
    check_output_file(&a.output).map_err(anyhow::Error::msg)?;
    outln!("exposure {k} ({rule}); the photo's values are divided by it, then multiplied back");

    let t = Instant::now();
    let ropts = RenderOptions {
        spp: a.spp.unwrap_or(base.render.spp).max(1),
        seed: a.seed.unwrap_or(base.render.seed),
        progress: true,
    };
    let without = render(&base, &base.camera, &ropts);
    let with = render(&edited, &base.camera, &ropts);
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
    let other = render(&base, &base.camera, &noise_opts);
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
    out.write(&a.output).map_err(anyhow::Error::msg)?;
    outln!(
        "wrote {} ({}×{}, 2 renders of {} spp, one of {} for their noise) in {:.1} s: {} pixels \
         changed beyond the Monte \
         Carlo noise (by more than 1% and {NOISE_SIGMAS}σ of the renders' noise), {:.0} covered \
         by added objects",
        a.output.display(),
        out.width,
        out.height,
        ropts.spp,
        noise_opts.spp,
        t.elapsed().as_secs_f64(),
        changed,
        cover.iter().sum::<f32>()
    );
    Ok(())
}

/// How many standard deviations of the renders' noise a change must exceed to count.
const NOISE_SIGMAS: f32 = 4.0;

/// Per pixel and channel, the standard deviation of the difference of two renders of `spp`
/// samples whose noise does not cancel, from `a` (`spp` samples) and an independent `b` (`spp_b`):
/// the variance of a − b is σ²(1 + spp/spp_b) for σ² that of one render, and twice σ² is the
/// difference's. Averaged over the 3×3 neighbourhood: one pixel's square is too noisy a guess.
fn noise_sigma(
    a: &matfit::io::image::Image,
    b: &matfit::io::image::Image,
    spp: u32,
    spp_b: u32,
) -> Vec<matfit::math::Rgb> {
    let (w, h) = (a.width, a.height);
    let sq: Vec<matfit::math::Rgb> = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (*x - *y) * (*x - *y))
        .collect();
    let ratio = 2.0 / (1.0 + spp as f32 / spp_b.max(1) as f32);
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let mut sum = matfit::math::Rgb::ZERO;
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
            bail!("--exposure must be positive, got {k}");
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
            _ => bail!(
                "{}: has no positive inputs.exposure; give --exposure",
                results.display()
            ),
        }
    }
    Ok((
        1.0,
        "default: no --exposure and no results.json beside the scene".into(),
    ))
}

/// The arguments of `matfit composite` (see `Command::Composite`).
#[derive(clap::Args)]
pub struct CompositeCli {
    /// The recovered scene (`recover`'s recovered.toml), whose camera is the photo's.
    #[arg(
        help = "Scene file (TOML): the recovered scene (recover's recovered.toml), whose camera is the photo's"
    )]
    scene: PathBuf,
    #[arg(help = PHOTO_HELP)]
    photo: PathBuf,
    /// Output image: .png (sRGB), or .exr, .hdr, .pfm (linear, the photo's units).
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    edits: EditCli,
    /// Samples per pixel of each of the two renders [default: the scene's [render] spp].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    spp: Option<u32>,
    /// Random seed of both renders [default: the scene's [render] seed].
    #[arg(long, value_name = "S")]
    seed: Option<u64>,
    /// Response curve of an 8/16-bit photo: srgb, linear, gamma:G (linear = code^G) or
    /// table:FILE.
    #[arg(long, default_value = "srgb", value_parser = Response::parse)]
    response: Response,
    /// Exposure factor k of the photo (its linear values = k × radiance) [default: the one
    /// in results.json beside SCENE, else 1].
    #[arg(long, value_name = "K")]
    exposure: Option<f32>,
}

/// Runs `matfit composite`.
pub fn command(args: CompositeCli) -> Result<()> {
    let CompositeCli {
        scene,
        photo,
        output,
        edits,
        spp,
        seed,
        response,
        exposure,
    } = args;
    composite::run(&composite::CompositeArgs {
        scene,
        photo,
        output,
        edits: edits.edits()?,
        spp,
        seed,
        response,
        exposure,
    })
}
