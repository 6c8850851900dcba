//! `matfit composite`: an edit of the recovered scene rendered into the photo
//! (`matfit::render::composite`).

use super::*;
use crate::outln;
use anyhow::{bail, Result};
use matfit::api::composite::NOISE_SIGMAS;
use matfit::io::atomic::check_output_file;
use matfit::photo::Response;
use matfit::scene::edit::Edit;
use matfit::scene::load_scene;
use std::path::PathBuf;
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
    check_output_file(&a.output).map_err(anyhow::Error::msg)?;
    let base = load_scene(&a.scene)?;
    let t = Instant::now();
    let options = matfit::CompositeOptions {
        spp: a.spp,
        seed: a.seed,
        response: a.response.clone(),
        exposure: a.exposure,
    };
    let photo = matfit::PhotoInput::from(a.photo.as_path());
    let c = matfit::composite(&base, &photo, &a.edits, &options, &out::TERM)?;
    let out = c.image;
    out.write(&a.output).map_err(anyhow::Error::msg)?;
    outln!(
        "wrote {} ({}×{}, 2 renders of {} spp, one of {} for their noise) in {:.1} s: {} pixels \
         changed beyond the Monte \
         Carlo noise (by more than 1% and {NOISE_SIGMAS}σ of the renders' noise), {:.0} covered \
         by added objects",
        a.output.display(),
        out.width,
        out.height,
        c.spp,
        c.noise_spp,
        t.elapsed().as_secs_f64(),
        c.changed,
        c.covered
    );
    Ok(())
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
