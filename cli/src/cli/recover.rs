//! `matfit recover`: the options parsed, `matfit::recover` called, the recovered table printed.

use super::*;
use matfit::PhotoInput;

/// The formats `recover --exportable` can keep to.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Exportable {
    Mitsuba,
}

/// The arguments of `matfit recover` (see `Command::Recover`).
#[derive(clap::Args)]
pub struct RecoverCli {
    #[arg(help = SCENE_HELP)]
    scene: PathBuf,
    /// Photograph of the scene: EXR, HDR or PFM (linear), or PNG/JPEG/TIFF (8/16-bit,
    /// through --response). Several photos are fitted together, photo K through the scene's
    /// [[view]] K (its camera and lights), each with its own fitted exposure factor.
    #[arg(required = true, num_args = 1.., value_name = "PHOTO")]
    photos: Vec<PathBuf>,
    /// The [[view]] each photo is taken through, in the photos' order: numbers from 1 or
    /// names, comma-separated [default: 1, 2, 3, ...].
    #[arg(long, value_name = "V1,V2,...", value_delimiter = ',')]
    views: Vec<String>,
    /// Output folder (created if needed; a folder with other files is refused unless --force).
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    fit: FitArgs,
    #[command(flatten)]
    photo_args: PhotoCli,
    /// Continue a run in OUTPUT that was interrupted, from its last checkpoint.
    #[arg(long)]
    resume: bool,
    /// Write into OUTPUT even if it holds files that are not a matfit output.
    #[arg(long)]
    force: bool,
}

/// Runs `matfit recover`.
pub fn command(args: RecoverCli) -> Result<()> {
    let RecoverCli {
        scene,
        photos,
        views,
        output,
        fit,
        photo_args,
        resume,
        force,
    } = args;
    let (sc, _) = load(&scene)?;
    // Before any work: the output folder must be usable.
    if !resume {
        checks::output_folder(&output, force)?;
    }
    let options = matfit::RecoverOptions {
        fit: fit.options(),
        photo: PhotoArgs::from(photo_args),
        views,
        output: Some(output.clone()),
        resume,
    };
    let inputs: Vec<PhotoInput> = photos
        .iter()
        .map(|p| PhotoInput::from(p.as_path()))
        .collect();
    let term = out::Term {
        resume: Some(resume_command()),
        messages: true,
    };
    let rec = matfit::recover(&sc, &inputs, &options, &term)?;
    print_summary(&rec, &photos, &output);
    Ok(())
}

/// What `recover` prints once done: the recovered table, each photo's exposure factor, the
/// stray light, the grey card's recalibration, where the outputs are, the notes and warnings.
fn print_summary(rec: &matfit::Recovery, photos: &[PathBuf], output: &Path) {
    let fit = &rec.fit;
    outln!();
    out::print(format_args!("{}", table::recovered(fit)));
    outln!(
        "{}",
        matfit::report::verdict::verdict(fit, &rec.photo()).text()
    );
    if !fit.views.is_empty() {
        outln!("photos fitted together (exposure factor k: photo = k × the recovered scene's radiance; geometric mean 1):");
        for (v, p) in fit.views.iter().zip(photos) {
            outln!(
                "  {:<12} {}  k = {:.4}  residual {:.2}% over {} px",
                v.name,
                p.display(),
                v.exposure,
                100.0 * v.residual,
                v.pixels
            );
        }
    }
    if let Some(s) = &fit.stray_light {
        outln!("{}", s.describe());
    }
    if let Some(card) = rec
        .inputs
        .options
        .grey_card
        .as_ref()
        .filter(|_| fit.exposure_factor != 1.0)
    {
        let before = rec.prepared[0].photo.exposure;
        outln!(
            "exposure k = {:.6} recalibrated from grey card '{}' with the recovered \
             materials around it (before the fit: {:.6}, the others' materials unknown)",
            before * fit.exposure_factor,
            card.group,
            before
        );
    }
    outln!(
        "outputs in {} ({:.1} s): recovered.toml, results.json, report.html",
        output.display(),
        fit.total_s
    );
    for g in fit.groups.iter() {
        if let Some(n) = &g.note {
            outln!("note: {}: {n}", g.name);
        }
    }
    out::repeat_warnings();
}
