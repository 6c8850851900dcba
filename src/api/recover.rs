//! The front door's recovery: photos prepared against the scene (registration, masks,
//! exposure), the pose refined again against a quick fit's materials, the recovery run with a
//! JSON-lines log and a checkpoint after every global iteration (`resume` continues a run that
//! was killed, even by `kill -9`, to exactly the result of an uninterrupted run), and the
//! outputs written.

use super::checks;
use crate::error::{Error, ErrorKind, Kind, Result};
use super::{Observer, PhotoInput, RecoverOptions};
use crate::fit::recovery::LogLine;
use crate::fit::recovery::{fingerprint, PhotoView, RecoveryLoop, CHECKPOINT_VERSION};
use crate::fit::Checkpoint;
use crate::io::atomic::write_atomic;
use crate::io::image::Image;
use crate::io::progress::Bar;
use crate::photo::Photo;
use crate::prepare::{PhotoArgs, PreparedPhoto, UsableMask};
use crate::scene::Scene;
use std::borrow::Cow;
use std::io::{Seek, Write};
use std::path::{Path, PathBuf};

/// What [`crate::recover`] gives: the recovery itself, each photo as it was prepared, and the
/// record of the inputs that results.json holds.
pub struct Recovery {
    pub fit: crate::fit::Recovery,
    /// Each photo as the fit saw it: linear, its exposure divided out, registered, masked.
    pub prepared: Vec<PreparedPhoto>,
    pub inputs: crate::report::Inputs,
    /// The output folder, when one was written.
    pub output: Option<PathBuf>,
}

impl Recovery {
    /// The first photo in the recovered scene's units (its exposure as the fit left it).
    pub fn photo(&self) -> Cow<'_, Photo> {
        let photo = &self.prepared[0].photo;
        if self.fit.exposure_factor != 1.0 {
            let mut scaled = photo.clone();
            scaled.apply_exposure(self.fit.exposure_factor);
            Cow::Owned(scaled)
        } else {
            Cow::Borrowed(photo)
        }
    }

    /// The first photo's absolute error against the synthetic image, per pixel (the report's
    /// error map, unscaled).
    pub fn error_image(&self) -> Image {
        crate::report::error_images(&self.fit, &self.photo(), 1.0).0
    }

    /// What results.json holds: per group the model, parameters with 1σ, ε.
    pub fn results(&self) -> crate::report::Results {
        let mut r = crate::report::results(&self.fit);
        r.inputs = Some(self.final_inputs().into_owned());
        r
    }

    /// The inputs as results.json records them, the exposure as the fit left it.
    fn final_inputs(&self) -> Cow<'_, crate::report::Inputs> {
        if self.fit.exposure_factor != 1.0 && self.inputs.options.grey_card.is_some() {
            let mut inputs = self.inputs.clone();
            inputs.exposure *= self.fit.exposure_factor;
            inputs.exposure_rule =
                "calibrated from the grey card, re-rendered with the recovered materials".into();
            Cow::Owned(inputs)
        } else {
            Cow::Borrowed(&self.inputs)
        }
    }
}

/// The name a photo goes by in messages and results.json.
fn photo_name(p: &PhotoInput, k: usize) -> PathBuf {
    match p {
        PhotoInput::Path(p) => p.clone(),
        PhotoInput::Linear(_) => PathBuf::from(format!("<photo {}>", k + 1)),
    }
}

/// Prepares photo `k` against `scene` (its camera as given), at `pose` when already found.
fn prepare(
    scene: &Scene,
    photo: &PhotoInput,
    k: usize,
    args: &PhotoArgs,
    pose: Option<crate::prepare::pose::Pose>,
) -> Result<PreparedPhoto> {
    let name = photo_name(photo, k);
    match photo {
        PhotoInput::Path(p) => crate::prepare::prepare_at(scene, p, args, pose),
        PhotoInput::Linear(img) => {
            let (w, h) = (scene.camera.width, scene.camera.height);
            let raw = crate::io::image::RawImage {
                image: img.clone(),
                bits: None,
            };
            crate::photo::photo_from_raw(raw, &name, w, h, &args.photo_options())
                .and_then(|ph| crate::prepare::prepare_loaded(scene, ph, &name, args, pose))
        }
    }
    .kind(ErrorKind::Photo)
}

/// The front door: see [`crate::recover`].
pub fn recover(
    sc: &Scene,
    photos: &[PhotoInput],
    options: &RecoverOptions,
    obs: &dyn Observer,
) -> Result<Recovery> {
    if photos.is_empty() {
        return Err(Error::options("no photo given: give one photo at least"));
    }
    let lighting = crate::scene::lint::lighting(sc);
    checks::require_light(sc, &lighting, obs)?;
    let photo_args = &options.photo;
    let names: Vec<PathBuf> = (photos.iter().enumerate())
        .map(|(k, p)| photo_name(p, k))
        .collect();
    // Photo k through view k (or `views`); one photo of a scene without views: the scene itself.
    let view_keys = &options.views;
    if !view_keys.is_empty() && view_keys.len() != photos.len() {
        return Err(Error::options(format!(
            "--views names {} view(s) for {} photo(s): give one per photo",
            view_keys.len(),
            photos.len()
        )));
    }
    let chosen: Vec<usize> = if view_keys.is_empty() {
        if photos.len() > sc.views.len().max(1) {
            return Err(Error::options(format!(
                "{} photos given but {} has {} [[view]] table(s): photo K is taken \
                 through view K (its camera and lights), so give a [[view]] for every \
                 photo",
                photos.len(),
                sc.path.display(),
                sc.views.len()
            )));
        }
        (0..photos.len()).collect()
    } else {
        view_keys
            .iter()
            .map(|k| sc.view_index(k))
            .collect::<Result<_>>()?
    };
    let mut scenes: Vec<Scene> = if sc.views.is_empty() {
        vec![sc.clone()]
    } else {
        chosen.iter().map(|&k| sc.in_view(k)).collect()
    };
    // Before any work: the output folder must be usable.
    if let Some(out) = &options.output {
        if options.resume {
            checks::resumable(out)?;
        } else {
            checks::remove_old_results(out)?;
        }
        crate::io::atomic::prepare_output_dir(out).kind(ErrorKind::Io)?;
    } else if options.resume {
        return Err(Error::options(
            "cannot resume without an output folder: the checkpoint is there",
        ));
    }
    let mut prepared = Vec::new();
    for (k, (view, photo)) in scenes.iter().zip(photos).enumerate() {
        prepared.push(prepare(view, photo, k, photo_args, None)?);
        obs.prepared(k, &prepared[k]);
        // Once the photo is known to be readable (an unreadable one gets only its error).
        checks::exposure_warning(&names[k], photo_args, &lighting, obs);
    }
    checks::some_usable(
        &scenes,
        &names,
        &prepared,
        photo_args.ignore_mask.as_deref(),
    )?;
    obs.fitting();
    let mut opts = options.fit.clone();
    if prepared[0].calibration.is_some() {
        opts.grey_card = photo_args
            .grey_card
            .clone()
            .map(|(group, rho)| crate::fit::recovery::GreyCard { group, rho });
    }
    if photo_args.register && photo_args.refine_pose {
        let view_names: Vec<String> = chosen[1..]
            .iter()
            .map(|&k| sc.views[k].name.clone())
            .collect();
        let quick = refine_poses_with_a_quick_fit(
            &scenes,
            photos,
            &mut prepared,
            &view_names,
            photo_args,
            &opts,
            obs,
        )?;
        if let Some((n, s)) = quick {
            obs.message(&format!(
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
            ));
        }
    }
    for ((view, name), p) in scenes.iter_mut().zip(&names).zip(&prepared) {
        checks::exposure_report(view, name, photo_args, p, obs);
        if let Some(m) = &photo_args.ignore_mask {
            obs.message(&checks::masked_summary(view, m, p));
        }
        // Render through the camera registered to the photo.
        view.camera = p.camera.clone();
    }
    let mut inputs = inputs(
        &sc.path,
        &names[0],
        &prepared[0],
        photo_args.exposure.is_some(),
        photo_args.ignore_mask.as_deref(),
        &opts,
    );
    if photos.len() > 1 {
        inputs.photos = names.iter().map(|p| p.display().to_string()).collect();
    }
    let (first, rest) = scenes.split_first().expect("one photo at least");
    let views: Vec<PhotoView> = rest
        .iter()
        .zip(&prepared[1..])
        .enumerate()
        .map(|(k, (s, p))| PhotoView {
            name: sc.views[chosen[k + 1]].name.clone(),
            scene: s,
            photo: &p.photo,
            mask: &p.mask,
        })
        .collect();
    let rec = run_recover(
        first,
        &prepared[0].photo,
        &prepared[0].mask,
        &views,
        &opts,
        options.output.as_deref(),
        options.resume,
        obs,
    )?;
    drop(views);
    let rec = Recovery {
        fit: rec,
        prepared,
        inputs,
        output: options.output.clone(),
    };
    if let Some(out) = &rec.output {
        crate::report::write_outputs(out, &rec.fit, &rec.photo(), Some(&rec.final_inputs()))
            .kind(ErrorKind::Io)?;
    }
    Ok(rec)
}

/// Runs the recovery of `scene`'s materials from `photo` (and `views`) to its end, reporting
/// every log line and its progress to `obs`; with `out`, writes log.jsonl as it goes and
/// checkpoint.json after every global iteration (with `resume`, continues from it). Stops after
/// a global iteration once `obs` says it is cancelled: the checkpoint is that iteration's.
#[allow(clippy::too_many_arguments)]
pub fn run_recover(
    scene: &Scene,
    photo: &Photo,
    mask: &UsableMask,
    views: &[PhotoView],
    opts: &crate::fit::RecoverOptions,
    out: Option<&Path>,
    resume: bool,
    obs: &dyn Observer,
) -> Result<crate::fit::Recovery> {
    let scene_text = std::fs::read_to_string(&scene.path).unwrap_or_default();
    let print = views
        .iter()
        .fold(fingerprint(&scene_text, photo, mask, opts), |h, v| {
            crate::math::sampler::hash_seed(&[h, fingerprint("", v.photo, v.mask, opts)])
        });
    let mut files = match out {
        Some(out) => Some(RunFiles::open(out, resume, print)?),
        None => None,
    };
    let resume_from = files.as_mut().and_then(|f| f.resume_from.take());
    let mut run = match &resume_from {
        Some(c) => RecoveryLoop::resume(scene, photo, mask, views, opts, c)?,
        None => RecoveryLoop::start(scene, photo, mask, views, opts),
    };
    // The bar advances once per group fitted (the iterations grow longer as the cache's pixel
    // budget doubles, so a bar per iteration stalled and then jumped); its message says which
    // iteration of at most how many, since a run that converges stops before the last.
    let fitted = run.fitted_groups().max(1) as u64;
    let pb = Bar::to(opts.max_iterations as u64 * fitted, "recover", |p| {
        obs.progress(p)
    });
    pb.inc(run.next_iteration() as u64 * fitted);
    // Both the log lines and the checkpoints write to the files.
    let files = std::cell::RefCell::new(files);
    let mut log = |l: &LogLine| {
        obs.log(l);
        if let Some(f) = files.borrow_mut().as_mut() {
            f.line(l);
        }
    };
    let mut result = Ok(());
    while !run.converged() {
        pb.set_message(format!(
            "iteration {}/{}",
            run.next_iteration() + 1,
            opts.max_iterations
        ));
        result = run.iterate(&mut |l: &LogLine| {
            if matches!(l.event, crate::fit::Event::Fit { .. }) {
                pb.inc(1);
            }
            log(l)
        });
        if result.is_err() {
            break;
        }
        if let Some(f) = files.borrow_mut().as_mut() {
            f.checkpoint(run.checkpoint());
        }
        if obs.cancelled() {
            break;
        }
    }
    if result.is_ok() && run.converged() {
        run.decide_the_undecided(&mut log);
    }
    pb.finish_and_clear();
    // The log is kept whole even when the fit diverged: it shows how it got there.
    let write_error = match files.into_inner() {
        Some(f) => f.close()?,
        None => None,
    };
    result?;
    if let Some(e) = write_error {
        return Err(Error::io(e));
    }
    if !run.converged() {
        return Err(Error::new(
            ErrorKind::Interrupted,
            "interrupted: the last finished global iteration is saved",
        ));
    }
    Ok(run.finish())
}

/// A run's log.jsonl and checkpoint.json in its output folder, and the first error writing
/// them (reported at the end: the fit goes on).
struct RunFiles {
    log_path: PathBuf,
    ck_path: PathBuf,
    log: std::io::BufWriter<std::fs::File>,
    print: u64,
    err: Option<String>,
    resume_from: Option<Checkpoint>,
}

impl RunFiles {
    fn open(out: &Path, resume: bool, print: u64) -> Result<RunFiles> {
        let log_path = out.join("log.jsonl");
        let ck_path = out.join("checkpoint.json");
        let resume_from: Option<Checkpoint> = if resume {
            let text = std::fs::read_to_string(&ck_path).map_err(|e| {
                Error::recover(format!("cannot resume: {}: {e}", ck_path.display()))
            })?;
            let c: Checkpoint = serde_json::from_str(&text).map_err(|e| {
                Error::recover(format!(
                    "cannot resume: {} is not a matfit checkpoint ({e})",
                    ck_path.display()
                ))
            })?;
            if c.version != CHECKPOINT_VERSION {
                return Err(Error::recover(format!(
                    "cannot resume: {} was written by another version of matfit (checkpoint \
                     format {}, this one reads {CHECKPOINT_VERSION}); run again without --resume",
                    ck_path.display(),
                    c.version
                )));
            }
            if c.fingerprint != print {
                return Err(Error::recover(format!(
                    "cannot resume: {} was written for another scene, photo or set of options",
                    ck_path.display()
                )));
            }
            Some(c)
        } else {
            None
        };
        let io = |e: std::io::Error| Error::io(format!("cannot write {}: {e}", log_path.display()));
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
        Ok(RunFiles {
            log_path,
            ck_path,
            log: std::io::BufWriter::new(f),
            print,
            err: None,
            resume_from,
        })
    }

    fn io_error(&mut self, e: std::io::Error) {
        let m = format!("cannot write {}: {e}", self.log_path.display());
        self.err.get_or_insert(m);
    }

    fn line(&mut self, line: &LogLine) {
        let s = serde_json::to_string(line).expect("log line serialises");
        if let Err(e) = writeln!(self.log, "{s}") {
            self.io_error(e);
        }
    }

    fn checkpoint(&mut self, mut c: Checkpoint) {
        c.fingerprint = self.print;
        let len = self
            .log
            .flush()
            .and_then(|_| self.log.get_ref().sync_data())
            .and_then(|_| self.log.get_ref().metadata());
        match len {
            Ok(m) => c.log_bytes = m.len(),
            Err(e) => return self.io_error(e),
        }
        let json = serde_json::to_string(&c).expect("checkpoint serialises");
        if let Err(e) = write_atomic(&self.ck_path, json.as_bytes()) {
            let m = format!("cannot write {}: {e}", self.ck_path.display());
            self.err.get_or_insert(m);
        }
    }

    /// Flushes the log (its error at once); returns the first error met before.
    fn close(mut self) -> Result<Option<String>> {
        if let Err(e) = self.log.flush() {
            return Err(Error::io(format!(
                "cannot write {}: {e}",
                self.log_path.display()
            )));
        }
        Ok(self.err)
    }
}

/// The record of a run's inputs for results.json and report.html.
pub fn inputs(
    scene: &Path,
    photo: &Path,
    prepared: &PreparedPhoto,
    exposure_given: bool,
    ignore_mask: Option<&Path>,
    opts: &crate::fit::RecoverOptions,
) -> crate::report::Inputs {
    crate::report::Inputs {
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
/// camera by [`crate::prepare::pose::APPLY_PX`].
const QUICK_ROUNDS: usize = 3;

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
    photos: &[PhotoInput],
    prepared: &mut [PreparedPhoto],
    names: &[String],
    photo_args: &PhotoArgs,
    opts: &crate::fit::RecoverOptions,
    obs: &dyn Observer,
) -> Result<Option<(usize, f64)>> {
    let t = std::time::Instant::now();
    let mut rounds = 0;
    while rounds < QUICK_ROUNDS
        && prepared
            .iter()
            .any(|p| p.registration.as_ref().is_some_and(|r| r.applied))
    {
        if rounds == 0 {
            obs.message(&format!(
                "refining the pose against a quick fit's materials (at most {QUICK_ROUNDS} \
                 rounds of {QUICK_ITERATIONS} global iterations)"
            ));
        }
        rounds += 1;
        // A quick fit that fails keeps the last round's pose: the main fit will say why.
        let poses = match quick_fit_poses(given, prepared, names, opts) {
            Ok(p) => p,
            Err(e) => {
                obs.warning(&format!(
                    "the pose's quick fit stopped ({e}); keeping the pose found before it"
                ));
                break;
            }
        };
        let mut moved = 0.0f32;
        for (k, p) in poses.into_iter().enumerate() {
            moved = moved.max(crate::prepare::pose::view_motion(
                &given[k],
                &prepared[k].camera,
                &p.camera,
            ));
            prepared[k] = prepare(&given[k], &photos[k], k, photo_args, Some(p))?;
        }
        if moved < crate::prepare::pose::APPLY_PX {
            break;
        }
    }
    Ok((rounds > 0).then(|| (rounds, t.elapsed().as_secs_f64())))
}

/// One round: the quick fit through the photos' current cameras, and each photo's pose refined
/// from there against its materials.
fn quick_fit_poses(
    given: &[Scene],
    prepared: &[PreparedPhoto],
    names: &[String],
    opts: &crate::fit::RecoverOptions,
) -> std::result::Result<Vec<crate::prepare::pose::Pose>, crate::fit::RecoverError> {
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
    quick.closing = 0;
    let rec = crate::fit::recover_resumable(
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
            crate::prepare::pose::refine_from(
                &shaded,
                &given[k].camera,
                &p.camera,
                &p.photo,
                crate::prepare::pose::Shading::QuickFit,
            )
        })
        .collect())
}
