//! `matfit export`: a scene written for another renderer (Mitsuba 3, glTF 2.0).

use super::*;

/// The arguments of `matfit export` (see `Command::Export`).
#[derive(clap::Args)]
pub struct ExportCli {
    /// Target renderer.
    format: FormatArg,
    #[arg(help = SCENE_HELP)]
    scene: PathBuf,
    /// Output folder (mitsuba; created if needed) or .glb file (gltf).
    #[arg(short, long)]
    output: PathBuf,
    /// Write into OUTPUT even if it holds files that are not a matfit output (mitsuba).
    #[arg(long)]
    force: bool,
    /// Export the scene as one of its [[view]]s sees it (its camera and lights): a number
    /// from 1 or a view's name [default: the scene's [camera] and every light].
    #[arg(long, value_name = "VIEW")]
    view: Option<String>,
}

/// Runs `matfit export`.
pub fn command(args: ExportCli) -> Result<()> {
    let ExportCli {
        format,
        scene,
        output,
        force,
        view,
    } = args;
    let (mut sc, _) = load(&scene)?;
    if let Some(v) = &view {
        sc = matfit::in_view(&sc, v)?;
    }
    let format = match format {
        FormatArg::Mitsuba => {
            checks::output_folder(&output, force)?;
            matfit::Format::Mitsuba
        }
        FormatArg::Gltf => matfit::Format::Gltf,
    };
    let report = matfit::export(&sc, format, &output)?;
    for w in &report.warnings {
        out::warn(w.clone());
    }
    match report.files.len() {
        1 => outln!("wrote {}", report.files[0].display()),
        n => outln!("wrote {} ({n} files)", report.files[0].display()),
    }
    Ok(())
}
