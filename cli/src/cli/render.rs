//! `matfit render`: a path-traced image of a scene, or one of its AOVs (index buffers, normals,
//! depth, UVs).

use super::*;

/// The arguments of `matfit render` (see `Command::Render`).
#[derive(clap::Args)]
pub struct RenderCli {
    #[arg(help = SCENE_HELP)]
    scene: PathBuf,
    /// Output image: .exr, .hdr, .pfm (linear) or .png (sRGB preview).
    #[arg(short, long)]
    output: PathBuf,
    /// Samples per pixel, at least 1 [default: the scene's [render] spp].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    spp: Option<u32>,
    /// Random seed [default: the scene's [render] seed].
    #[arg(long, value_name = "S")]
    seed: Option<u64>,
    /// What to write: the image, or per pixel the group / object seen (directly or through a
    /// mirror), the normal, the depth (scene units) or the UV.
    #[arg(long, value_enum, default_value = "beauty")]
    aov: AovArg,
    /// Render the scene as one of its [[view]]s sees it (its camera and lights): a number
    /// from 1 or a view's name [default: the scene's [camera] and every light].
    #[arg(long, value_name = "VIEW")]
    view: Option<String>,
    #[command(flatten)]
    edits: EditCli,
}

/// Runs `matfit render`.
pub fn command(args: RenderCli) -> Result<()> {
    let RenderCli {
        scene,
        output,
        spp,
        seed,
        aov,
        view,
        edits,
    } = args;
    let edits = edits.edits()?;
    let sc = if edits.is_empty() {
        load(&scene)?.0
    } else {
        let edited = matfit::load_edited(&scene, &edits)?;
        matfit::api::checks::scene_warnings(&edited, &out::TERM);
        edited
    };
    let ext = output
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if !["exr", "hdr", "pfm", "png"].contains(&ext.as_str()) {
        bail!(
            "{}: output must end in .exr, .hdr, .pfm or .png",
            output.display()
        );
    }
    // Before minutes of rendering: the file must be writable.
    check_output_file(&output).map_err(anyhow::Error::msg)?;
    let t = Instant::now();
    let request = matfit::RenderRequest {
        spp,
        seed,
        aov: Aov::from(aov),
        false_colour: ext == "png",
        view,
    };
    let img = matfit::render(&sc, &request, &out::TERM)?;
    let what = match request.aov {
        Aov::Beauty => {
            // bench/ reads this (MATFIT_LOG=info): the render alone, to 10 ms.
            tracing::info!("rendered in {:.2} s", t.elapsed().as_secs_f64());
            let spp = spp.unwrap_or(sc.render.spp).max(1);
            format!("{spp} spp")
        }
        other => format!("{other:?} AOV").to_lowercase(),
    };
    img.write(&output).map_err(anyhow::Error::msg)?;
    outln!(
        "wrote {} ({}×{}, {what}) in {:.1} s",
        output.display(),
        img.width,
        img.height,
        t.elapsed().as_secs_f64()
    );
    Ok(())
}
