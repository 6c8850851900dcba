//! `matfit inspect`: a photo checked against the model before fitting.

use super::*;

/// The arguments of `matfit inspect` (see `Command::Inspect`).
#[derive(clap::Args)]
pub struct InspectCli {
    #[arg(help = SCENE_HELP)]
    scene: PathBuf,
    #[arg(help = PHOTO_HELP)]
    photo: PathBuf,
    /// Output folder for outlines.png, usable.png, edges.png.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    photo_args: PhotoCli,
    /// Write into OUTPUT even if it holds files that are not a matfit output.
    #[arg(long)]
    force: bool,
}

/// Runs `matfit inspect`.
pub fn command(args: InspectCli) -> Result<()> {
    let InspectCli {
        scene,
        photo,
        output,
        photo_args,
        force,
    } = args;
    let (sc, lighting) = load(&scene)?;
    let photo_args = PhotoArgs::from(photo_args);
    checks::output_folder(&output, force)?;
    prepare_output_dir(&output).map_err(anyhow::Error::msg)?;
    let report = matfit::prepare::inspect::inspect(&sc, &photo, &photo_args, &output)
        .map_err(anyhow::Error::msg)?;
    out::print(format_args!("{report}"));
    matfit::api::checks::exposure_warning(&photo, &photo_args, &lighting, &out::TERM);
    Ok(())
}
