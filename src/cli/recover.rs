//! The `recover` command's work: run the engine with a JSON-lines log and a checkpoint after
//! every global iteration, then write the outputs. `resume` continues a run that was killed
//! (even by `kill -9`) from its last checkpoint, to exactly the result of an uninterrupted run.

use super::*;
use matfit::fit::recovery::PhotoView;
use matfit::fit::recovery::{fingerprint, CHECKPOINT_VERSION};
use matfit::fit::{recover_resumable, Checkpoint, RecoverOptions, Recovery};
use matfit::io::atomic::write_atomic;
use matfit::photo::Photo;
use matfit::prepare::UsableMask;
use matfit::scene::Scene;
use std::borrow::Cow;
use std::io::{Seek, Write};
use std::path::Path;

/// Recovers `scene`'s materials from `photo`, writing log.jsonl as it goes, checkpoint.json
/// after every global iteration, and every other output at the end into `out` (which must
/// exist). With `resume`, continues from `out/checkpoint.json`. `inputs` go into
/// results.json and report.html. `views`: further photos fitted with the first.
#[allow(clippy::too_many_arguments)]
pub fn run_recover(
    scene: &Scene,
    photo: &Photo,
    mask: &UsableMask,
    views: &[PhotoView],
    opts: &RecoverOptions,
    out: &Path,
    resume: bool,
    inputs: &matfit::report::Inputs,
) -> Result<Recovery, String> {
    let log_path = out.join("log.jsonl");
    let ck_path = out.join("checkpoint.json");
    let scene_text = std::fs::read_to_string(&scene.path).unwrap_or_default();
    let print = views
        .iter()
        .fold(fingerprint(&scene_text, photo, mask, opts), |h, v| {
            matfit::math::sampler::hash_seed(&[h, fingerprint("", v.photo, v.mask, opts)])
        });
    let resume_from: Option<Checkpoint> = if resume {
        let text = std::fs::read_to_string(&ck_path)
            .map_err(|e| format!("cannot resume: {}: {e}", ck_path.display()))?;
        let c: Checkpoint = serde_json::from_str(&text).map_err(|e| {
            format!(
                "cannot resume: {} is not a matfit checkpoint ({e})",
                ck_path.display()
            )
        })?;
        if c.version != CHECKPOINT_VERSION || c.fingerprint != print {
            return Err(format!(
                "cannot resume: {} was written for another scene, photo or set of options",
                ck_path.display()
            ));
        }
        Some(c)
    } else {
        None
    };
    let io = |e: std::io::Error| format!("cannot write {}: {e}", log_path.display());
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .write(true)
        .truncate(resume_from.is_none())
        .open(&log_path)
        .map_err(io)?;
    if let Some(c) = &resume_from {
        // Lines written after the checkpoint belong to the interrupted iteration: drop them.
        f.set_len(c.log_bytes).map_err(io)?;
        f.seek(std::io::SeekFrom::End(0)).map_err(io)?;
    }
    // Both callbacks write to the log (lines; its length at checkpoints) and record errors.
    let log = std::cell::RefCell::new(std::io::BufWriter::new(f));
    let err: std::cell::RefCell<Option<String>> = std::cell::RefCell::new(None);
    let rec = recover_resumable(
        scene,
        photo,
        mask,
        views,
        opts,
        resume_from.as_ref(),
        |line| {
            let s = serde_json::to_string(line).expect("log line serialises");
            if let Err(e) = writeln!(log.borrow_mut(), "{s}") {
                err.borrow_mut().get_or_insert(io(e));
            }
        },
        |c| {
            let mut c = c.clone();
            c.fingerprint = print;
            let mut log = log.borrow_mut();
            let len = log
                .flush()
                .and_then(|_| log.get_ref().sync_data())
                .and_then(|_| log.get_ref().metadata());
            match len {
                Ok(m) => c.log_bytes = m.len(),
                Err(e) => {
                    err.borrow_mut().get_or_insert(io(e));
                    return;
                }
            }
            let json = serde_json::to_string(&c).expect("checkpoint serialises");
            if let Err(e) = write_atomic(&ck_path, json.as_bytes()) {
                err.borrow_mut()
                    .get_or_insert(format!("cannot write {}: {e}", ck_path.display()));
            }
        },
    );
    // The log is kept whole even when the fit diverged: it shows how it got there.
    log.into_inner().flush().map_err(io)?;
    let rec = rec?;
    if let Some(e) = err.into_inner() {
        return Err(e);
    }
    // The photo in the recovered scene's units, its exposure as the fit left it.
    let (photo, inputs) = if rec.exposure_factor != 1.0 {
        let mut inputs = inputs.clone();
        if opts.grey_card.is_some() {
            inputs.exposure *= rec.exposure_factor;
            inputs.exposure_rule =
                "calibrated from the grey card, re-rendered with the recovered materials".into();
        }
        let mut scaled = photo.clone();
        scaled.apply_exposure(rec.exposure_factor);
        (Cow::Owned(scaled), Cow::Owned(inputs))
    } else {
        (Cow::Borrowed(photo), Cow::Borrowed(inputs))
    };
    matfit::report::write_outputs(out, &rec, &photo, Some(&inputs))?;
    Ok(rec)
}

/// The record of a run's inputs for results.json and report.html.
pub fn inputs(
    scene: &Path,
    photo: &Path,
    prepared: &matfit::prepare::PreparedPhoto,
    exposure_given: bool,
    ignore_mask: Option<&Path>,
    opts: &RecoverOptions,
) -> matfit::report::Inputs {
    matfit::report::Inputs {
        matfit: env!("CARGO_PKG_VERSION").to_string(),
        scene: scene.display().to_string(),
        photo: photo.display().to_string(),
        exposure: prepared.photo.exposure,
        exposure_rule: if prepared.calibration.is_some() {
            "calibrated"
        } else if exposure_given {
            "given"
        } else {
            "default"
        }
        .to_string(),
        registration_px: prepared
            .registration
            .as_ref()
            .map(|r| [r.mean_px.x, r.mean_px.y]),
        registration: prepared.registration.clone(),
        photos: Vec::new(),
        ignore_mask: ignore_mask.map(|m| m.display().to_string()),
        options: opts.clone(),
    }
}

/// Global iterations and cached pixels per group of the quick fit that shades the model for
/// the pose's next refinement: enough for the shading near edges, far less than the fit.
const QUICK_ITERATIONS: u32 = 6;
const QUICK_PIXELS: usize = 3000;
/// At most this many rounds of quick fit and refinement; they stop once a round moves no
/// camera by [`matfit::prepare::pose::APPLY_PX`].
const QUICK_ROUNDS: usize = 3;

/// The formats `recover --exportable` can keep to.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Exportable {
    Mitsuba,
}

/// The pose refinement's second pass (`recover`'s default registration). The first refinement
/// located the model's edges in renderings shaded by the scene file's materials, often
/// placeholders; the estimator's shading bias cancels only as far as that shading is the
/// photo's. Where it moved a camera, a quick fit through the refined cameras (no outputs)
/// gives materials whose shading is; the pose is refined again against them from where the
/// last round left it, and every photo is prepared again through that pose. The main fit starts from the scene file's materials as before.
/// `given`: the scenes through the cameras as given, one per photo; `names`: the further
/// photos' views. Returns the rounds and their seconds, None where no camera moved.
pub fn refine_poses_with_a_quick_fit(
    given: &[Scene],
    photos: &[std::path::PathBuf],
    prepared: &mut [matfit::prepare::PreparedPhoto],
    names: &[String],
    photo_args: &matfit::prepare::PhotoArgs,
    opts: &RecoverOptions,
) -> Result<Option<(usize, f64)>, String> {
    let t = std::time::Instant::now();
    let mut rounds = 0;
    while rounds < QUICK_ROUNDS
        && prepared
            .iter()
            .any(|p| p.registration.as_ref().is_some_and(|r| r.applied))
    {
        if rounds == 0 {
            crate::outln!(
                "refining the pose against a quick fit's materials (at most {QUICK_ROUNDS} \
                 rounds of {QUICK_ITERATIONS} global iterations)"
            );
        }
        rounds += 1;
        // A quick fit that fails keeps the last round's pose: the main fit will say why.
        let poses = match quick_fit_poses(given, prepared, names, opts) {
            Ok(p) => p,
            Err(e) => {
                crate::cli::out::warn(format!(
                    "the pose's quick fit stopped ({e}); keeping the pose found before it"
                ));
                break;
            }
        };
        let mut moved = 0.0f32;
        for (k, p) in poses.into_iter().enumerate() {
            moved = moved.max(matfit::prepare::pose::view_motion(
                &given[k],
                &prepared[k].camera,
                &p.camera,
            ));
            prepared[k] = matfit::prepare::prepare_at(&given[k], &photos[k], photo_args, Some(p))?;
        }
        if moved < matfit::prepare::pose::APPLY_PX {
            break;
        }
    }
    Ok((rounds > 0).then(|| (rounds, t.elapsed().as_secs_f64())))
}

/// One round: the quick fit through the photos' current cameras, and each photo's pose refined
/// from there against its materials.
fn quick_fit_poses(
    given: &[Scene],
    prepared: &[matfit::prepare::PreparedPhoto],
    names: &[String],
    opts: &RecoverOptions,
) -> Result<Vec<matfit::prepare::pose::Pose>, String> {
    let through: Vec<Scene> = given
        .iter()
        .zip(prepared.iter())
        .map(|(s, p)| Scene {
            camera: p.camera.clone(),
            ..s.clone()
        })
        .collect();
    let views: Vec<PhotoView> = through[1..]
        .iter()
        .zip(&prepared[1..])
        .zip(names)
        .map(|((s, p), name)| PhotoView {
            name: name.clone(),
            scene: s,
            photo: &p.photo,
            mask: &p.mask,
        })
        .collect();
    let mut quick = opts.clone();
    quick.max_iterations = QUICK_ITERATIONS;
    quick.cache.max_pixels = quick.cache.max_pixels.min(QUICK_PIXELS);
    quick.first_pixels = quick.first_pixels.min(QUICK_PIXELS);
    quick.final_spp = Some(2);
    quick.hierarchy.gross_climbs = false;
    let rec = recover_resumable(
        &through[0],
        &prepared[0].photo,
        &prepared[0].mask,
        &views,
        &quick,
        None,
        |_| {},
        |_| {},
    )?;
    Ok(through
        .iter()
        .zip(prepared)
        .enumerate()
        .map(|(k, (scene, p))| {
            // This photo's view (its camera and lights) with the quick fit's materials.
            let mut shaded = scene.clone();
            for (o, r) in shaded.objects.iter_mut().zip(&rec.scene.objects) {
                o.material = r.material.clone();
            }
            shaded.stray_light = rec.scene.stray_light;
            matfit::prepare::pose::refine_from(
                &shaded,
                &given[k].camera,
                &p.camera,
                &p.photo,
                matfit::prepare::pose::Shading::QuickFit,
            )
        })
        .collect())
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
        views: view_keys,
        output,
        fit,
        photo_args,
        resume,
        force,
    } = args;
    let (sc, lighting) = load(&scene)?;
    checks::require_light(&sc, &lighting)?;
    let photo_args = PhotoArgs::from(photo_args);
    // Photo k through view k (or --views); one photo of a scene without views: the
    // scene itself.
    if !view_keys.is_empty() && view_keys.len() != photos.len() {
        bail!(
            "--views names {} view(s) for {} photo(s): give one per photo",
            view_keys.len(),
            photos.len()
        );
    }
    let chosen: Vec<usize> = if view_keys.is_empty() {
        if photos.len() > sc.views.len().max(1) {
            bail!(
                "{} photos given but {} has {} [[view]] table(s): photo K is taken \
                 through view K (its camera and lights), so give a [[view]] for every \
                 photo",
                photos.len(),
                scene.display(),
                sc.views.len()
            );
        }
        (0..photos.len()).collect()
    } else {
        view_keys
            .iter()
            .map(|k| sc.view_index(k))
            .collect::<Result<_, _>>()
            .map_err(anyhow::Error::msg)?
    };
    let mut scenes: Vec<Scene> = if sc.views.is_empty() {
        vec![sc.clone()]
    } else {
        chosen.iter().map(|&k| sc.in_view(k)).collect()
    };
    // Before any work: the output folder must be usable.
    if resume {
        checks::resumable(&output)?;
    } else {
        checks::output_folder(&output, force)?;
        checks::remove_old_results(&output)?;
    }
    prepare_output_dir(&output).map_err(anyhow::Error::msg)?;
    let mut prepared = Vec::new();
    for (view, photo) in scenes.iter().zip(&photos) {
        let p = matfit::prepare::prepare(view, photo, &photo_args).map_err(anyhow::Error::msg)?;
        // Once the photo is known to be readable (an unreadable one gets only its error).
        checks::exposure_warning(photo, &photo_args, &lighting);
        prepared.push(p);
    }
    checks::some_usable(
        &scenes,
        &photos,
        &prepared,
        photo_args.ignore_mask.as_deref(),
    )?;
    checks::on_interrupt_say_resume(resume_command());
    let mut opts = fit.options();
    if prepared[0].calibration.is_some() {
        opts.grey_card = photo_args
            .grey_card
            .clone()
            .map(|(group, rho)| matfit::fit::recovery::GreyCard { group, rho });
    }
    if photo_args.register && photo_args.refine_pose {
        let names: Vec<String> = chosen[1..]
            .iter()
            .map(|&k| sc.views[k].name.clone())
            .collect();
        let quick = recover::refine_poses_with_a_quick_fit(
            &scenes,
            &photos,
            &mut prepared,
            &names,
            &photo_args,
            &opts,
        )
        .map_err(anyhow::Error::msg)?;
        if let Some((n, s)) = quick {
            outln!(
                "pose refined again against a quick fit's materials ({n} round{}, \
                 {s:.1} s): {}",
                if n == 1 { "" } else { "s" },
                prepared
                    .iter()
                    .filter_map(|p| p.registration.as_ref())
                    .map(|r| format!(
                        "turned {:.3}°, moved {:.4} units",
                        r.rotation_deg,
                        r.translation.length()
                    ))
                    .collect::<Vec<_>>()
                    .join("; ")
            );
        }
    }
    for ((view, photo), p) in scenes.iter_mut().zip(&photos).zip(&prepared) {
        checks::exposure_report(view, photo, &photo_args, p);
        if let Some(m) = &photo_args.ignore_mask {
            outln!("{}", checks::masked_summary(view, m, p));
        }
        // Render through the camera registered to the photo.
        view.camera = p.camera.clone();
    }
    let mut inputs = recover::inputs(
        &scene,
        &photos[0],
        &prepared[0],
        photo_args.exposure.is_some(),
        photo_args.ignore_mask.as_deref(),
        &opts,
    );
    if photos.len() > 1 {
        inputs.photos = photos.iter().map(|p| p.display().to_string()).collect();
    }
    let (first, rest) = scenes.split_first().expect("one photo at least");
    let views: Vec<matfit::fit::recovery::PhotoView> = rest
        .iter()
        .zip(&prepared[1..])
        .enumerate()
        .map(|(k, (s, p))| matfit::fit::recovery::PhotoView {
            name: sc.views[chosen[k + 1]].name.clone(),
            scene: s,
            photo: &p.photo,
            mask: &p.mask,
        })
        .collect();
    let rec = recover::run_recover(
        first,
        &prepared[0].photo,
        &prepared[0].mask,
        &views,
        &opts,
        &output,
        resume,
        &inputs,
    )
    .map_err(anyhow::Error::msg)?;
    outln!();
    out::print(format_args!("{}", table::recovered(&rec)));
    outln!(
        "{}",
        matfit::report::verdict::verdict(&rec, &prepared[0].photo).text()
    );
    if !rec.views.is_empty() {
        outln!("photos fitted together (exposure factor k: photo = k × the recovered scene's radiance; geometric mean 1):");
        for (v, p) in rec.views.iter().zip(&photos) {
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
    if let Some(s) = &rec.stray_light {
        outln!("{}", s.describe());
    }
    if let Some(card) = opts
        .grey_card
        .as_ref()
        .filter(|_| rec.exposure_factor != 1.0)
    {
        outln!(
            "exposure k = {:.6} recalibrated from grey card '{}' with the recovered \
             materials around it (before the fit: {:.6}, the others' materials unknown)",
            prepared[0].photo.exposure * rec.exposure_factor,
            card.group,
            prepared[0].photo.exposure
        );
    }
    outln!(
        "outputs in {} ({:.1} s): recovered.toml, results.json, report.html",
        output.display(),
        rec.total_s
    );
    for g in rec.groups.iter() {
        if let Some(n) = &g.note {
            outln!("note: {}: {n}", g.name);
        }
    }
    out::repeat_warnings();
    Ok(())
}
