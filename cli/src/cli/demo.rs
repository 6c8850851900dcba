//! `matfit demo`: renders the figure6 photo (kept for the next run), recovers its materials
//! without looking at the true ones, and prints the notes' Figure 6 table.

use super::*;
use matfit::fit::{GroupParams, Level, RecoverOptions};
use matfit::io::image::read_linear;
use matfit::photo::Photo;
use matfit::render::film::{render, RenderOptions};
use matfit::scene::{load_scene, Scene};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Where the bundled figure6 scene is: under the current folder, else next to the sources.
pub fn figure6_path() -> PathBuf {
    let local = PathBuf::from("scenes/figure6/scene.toml");
    if local.exists() {
        local
    } else {
        PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../scenes/figure6/scene.toml"
        ))
    }
}

/// Options of the demo.
pub struct DemoOptions {
    /// The scene whose materials are the truth (default: figure6).
    pub scene: Option<PathBuf>,
    pub out: PathBuf,
    pub photo_spp: u32,
    /// Gaussian noise added to the photo, relative: each channel of each pixel is multiplied by
    /// 1 + σ·n with n ~ N(0, 1) (0: none).
    pub noise: f32,
    /// Misregisters the model: the camera given to the recovery is shifted by this many pixels
    /// (x right, y down) from the one that took the photo.
    pub shift: (f32, f32),
    /// Refine the camera's pose against the photo (`photo::pose`), as `recover` does.
    pub register: bool,
    pub recover: RecoverOptions,
}

/// `img` with relative Gaussian noise of standard deviation `sigma` (Box–Muller on a hashed,
/// seeded stream: the same seed gives the same noise).
pub fn add_noise(
    img: &matfit::io::image::Image,
    sigma: f32,
    seed: u64,
) -> matfit::io::image::Image {
    use matfit::math::sampler::{hash_seed, mix64};
    let uniform =
        |k: u64| ((mix64(hash_seed(&[seed, k])) >> 40) as f64 + 0.5) / (1u64 << 24) as f64;
    let mut out = img.clone();
    for (i, px) in out.data.iter_mut().enumerate() {
        for c in 0..3 {
            let k = 2 * (3 * i as u64 + c as u64);
            let n =
                (-2.0 * uniform(k).ln()).sqrt() * (std::f64::consts::TAU * uniform(k + 1)).cos();
            px[c] *= 1.0 + sigma * n as f32;
        }
    }
    out
}

/// Renders (or reuses) the photo of `scene` at `spp` into `path`; a stamp beside it records
/// what it was rendered from so that a changed scene or sample count renders it anew.
pub fn photo_of(scene: &Scene, spp: u32, path: &Path) -> Result<(Photo, bool), String> {
    let text = std::fs::read_to_string(&scene.path)
        .map_err(|e| format!("{}: {e}", scene.path.display()))?;
    let stamp = format!(
        "{:016x} spp {spp}",
        matfit::math::sampler::hash_seed(&text.bytes().map(u64::from).collect::<Vec<_>>())
    );
    let stamp_path = path.with_extension("stamp");
    if path.exists() && std::fs::read_to_string(&stamp_path).ok().as_deref() == Some(stamp.as_str())
    {
        let img = read_linear(path)?;
        return Ok((Photo::from_linear(img), true));
    }
    let img = render(
        scene,
        &scene.camera,
        &RenderOptions {
            spp,
            seed: scene.render.seed,
            progress: true,
        },
    );
    img.write(path)?;
    matfit::io::atomic::write_atomic(&stamp_path, stamp.as_bytes()).map_err(|e| e.to_string())?;
    Ok((Photo::from_linear(img), false))
}

fn fmt_rgb(c: matfit::math::Rgb) -> String {
    format!("({:.4}, {:.4}, {:.4})", c.x, c.y, c.z)
}

/// The true parameters of a group, as the scene gives them: its first object's, with ρd the
/// mean over its objects (books of one group each have their own texture).
fn truth(scene: &Scene, g: usize) -> GroupParams {
    let objects = &scene.groups[g].objects;
    let mut p = GroupParams::from_material(&scene.objects[objects[0]].material);
    let sum = objects
        .iter()
        .map(|&o| scene.objects[o].material.rho_d())
        .sum::<matfit::math::Rgb>();
    p.rho_d = sum / objects.len().max(1) as f32;
    p
}

/// Prints the table comparing true and recovered values; returns the worst absolute ρ error
/// over the fitted groups.
pub fn print_table(
    scene: &Scene,
    rec: &matfit::fit::Recovery,
    out: &mut impl Write,
) -> std::io::Result<f32> {
    use matfit::fit::Status;
    let mut worst = 0.0f32;
    // The surface column is as wide as the longest shown name.
    let sw = rec
        .groups
        .iter()
        .filter(|st| st.status != Status::Light)
        .map(|st| st.name.chars().count())
        .max()
        .unwrap_or(0)
        .max("surface".len());
    writeln!(
        out,
        "{:<sw$} {:<9} {:<28} {:<28} level / status",
        "surface", "parameter", "true value", "recovered value"
    )?;
    for (g, st) in rec.groups.iter().enumerate() {
        if st.status == Status::Light {
            continue;
        }
        let t = truth(scene, g);
        let p = st.params;
        let status = format!("{} / {:?}", st.level.name(), st.status).to_lowercase();
        // (parameter, true, recovered) rows; the first names the surface and its level.
        // A texture's ρd is its mean (the truth's over its texels, the fit's over the texels
        // the photo sees); its lobe, if varnished, is its base level's.
        let textured = st.level == Level::Textured;
        let mut rows = vec![
            (
                if textured { "rho_d avg" } else { "rho_d" },
                fmt_rgb(t.rho_d),
                fmt_rgb(p.rho_d),
            ),
            ("rho_s", fmt_rgb(t.rho_s), fmt_rgb(p.rho_s)),
        ];
        if st.params_level().has_lobe() {
            rows.push((
                "alpha_x",
                format!("{:.4}", t.alpha_x),
                format!("{:.4}", p.alpha_x),
            ));
        }
        if matches!(
            st.params_level(),
            Level::Anisotropic | Level::AnisotropicMicrofacet
        ) {
            rows.push((
                "alpha_y",
                format!("{:.4}", t.alpha_y),
                format!("{:.4}", p.alpha_y),
            ));
            let deg = |th: f32| format!("{:.2}°", th.to_degrees());
            rows.push(("theta", deg(t.theta), deg(p.theta)));
        }
        for (i, (param, truth, got)) in rows.iter().enumerate() {
            let surface = if i == 0 { st.name.as_str() } else { "" };
            write!(out, "{surface:<sw$} {param:<9} {truth:<28} {got:<28}")?;
            if i == 0 {
                write!(out, " {status}")?;
            }
            writeln!(out)?;
        }
        if st.is_fitted() {
            if !textured {
                worst = worst.max((p.rho_d - t.rho_d).abs().max_element());
            }
            worst = worst.max((p.rho_s - t.rho_s).abs().max_element());
        }
    }
    Ok(worst)
}

/// What the demo shows of the recovery: not the lines `recover` prints (the demo prints its
/// own), but the registration against the true camera, warnings and progress.
struct DemoTerm<'a> {
    truth: &'a Scene,
}

impl matfit::Observer for DemoTerm<'_> {
    fn warning(&self, text: &str) {
        crate::cli::out::warn(text);
    }
    fn progress(&self, p: &matfit::Progress) {
        crate::cli::out::BARS.show(p);
    }
    fn prepared(&self, _index: usize, prepared: &matfit::prepare::PreparedPhoto) {
        if let Some(r) = &prepared.registration {
            let scene = self.truth;
            let points: Vec<_> = scene
                .camera_grid_hits(64, 48)
                .into_iter()
                .map(|(_, _, h)| h.p)
                .collect();
            let (_, off) = matfit::prepare::pose::motion(&scene.camera, &prepared.camera, &points);
            crate::outln!(
                "registration: {}; the model's camera is now {:.2} px RMS off the photo's",
                r.found(),
                off
            );
        }
    }
}

/// Runs the demo; returns the recovery's worst ρ error.
pub fn run(opts: &DemoOptions) -> Result<f32, String> {
    let t0 = Instant::now();
    if !(opts.noise >= 0.0 && opts.noise.is_finite()) {
        return Err(format!("--noise must be ≥ 0, got {}", opts.noise));
    }
    let path = opts.scene.clone().unwrap_or_else(figure6_path);
    let scene = load_scene(&path).map_err(|e| e.to_string())?;
    let rec_dir = opts.out.join("recovery");
    // Both folders before the photo is rendered (minutes): they must be usable.
    matfit::io::atomic::prepare_output_dir(&opts.out)?;
    matfit::io::atomic::prepare_output_dir(&rec_dir)?;
    let tp = Instant::now();
    let (photo, reused) = photo_of(&scene, opts.photo_spp, &opts.out.join("photo.exr"))?;
    crate::outln!(
        "photo: {} ({})",
        opts.out.join("photo.exr").display(),
        if reused {
            "reused".to_string()
        } else {
            format!(
                "rendered at {} spp in {:.1} s",
                opts.photo_spp,
                tp.elapsed().as_secs_f64()
            )
        }
    );
    // What the recovery sees: the photo (with noise if asked) and the model (misregistered if
    // asked), prepared exactly as `matfit recover` prepares them (validity, registration, masks).
    let mut photo_path = opts.out.join("photo.exr");
    if opts.noise > 0.0 {
        photo_path = opts.out.join(format!("photo-noise{}.exr", opts.noise));
        add_noise(&photo.image, opts.noise, scene.render.seed).write(&photo_path)?;
        crate::outln!(
            "photo with {}% relative Gaussian noise: {}",
            100.0 * opts.noise,
            photo_path.display()
        );
    }
    let mut model = scene.clone();
    if opts.shift != (0.0, 0.0) {
        model.camera = scene.camera.shifted(opts.shift.0, opts.shift.1);
        crate::outln!(
            "model misregistered by ({}, {}) px",
            opts.shift.0,
            opts.shift.1
        );
    }
    let options = matfit::RecoverOptions {
        fit: opts.recover.clone(),
        photo: matfit::prepare::args::PhotoArgs {
            register: opts.register,
            ..Default::default()
        },
        views: Vec::new(),
        output: Some(rec_dir.clone()),
        resume: false,
    };
    let observer = DemoTerm { truth: &scene };
    let full = matfit::recover(&model, &[photo_path.as_path().into()], &options, &observer)
        .map_err(|e| e.to_string())?;
    let rec = &full.fit;
    let mut table = Vec::new();
    let worst = print_table(&scene, rec, &mut table).map_err(|e| e.to_string())?;
    matfit::report::add_to_report(
        &rec_dir,
        &format!("True vs recovered (the demo knows the truth; worst ρ error {worst:.4})"),
        &String::from_utf8_lossy(&table),
    )?;
    crate::outln!();
    crate::cli::out::print(format_args!("{}", String::from_utf8_lossy(&table)));
    crate::outln!(
        "{}",
        matfit::report::verdict::verdict(rec, &full.photo()).text()
    );
    crate::outln!();
    crate::outln!(
        "recovery {:.1} s: fitting {:.1} s ({} global iterations, {} cache builds, {} objective evaluations), then the final render {:.1} s; \
         ratio {:.2} (fitting time / final render time: the inverse problem cost as much as that many renders)",
        rec.total_s,
        rec.fit_s,
        rec.iterations,
        rec.cache_builds,
        rec.objective_evals,
        rec.final_render_s,
        rec.fit_s / rec.final_render_s.max(1e-9)
    );
    crate::outln!(
        "demo total {:.1} s; outputs in {}",
        t0.elapsed().as_secs_f64(),
        rec_dir.display()
    );
    Ok(worst)
}

/// The arguments of `matfit demo` (see `Command::Demo`).
#[derive(clap::Args)]
pub struct DemoCli {
    /// Scene whose materials are the truth [default: scenes/figure6/scene.toml].
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Output folder; the photo is kept there for the next run.
    #[arg(short, long, default_value = "out/demo")]
    output: PathBuf,
    /// Samples per pixel of the photo.
    #[arg(long, value_name = "N", default_value_t = 512, value_parser = clap::value_parser!(u32).range(1..))]
    photo_spp: u32,
    /// Relative Gaussian noise added to the photo, as a standard deviation (0.01 = 1%).
    #[arg(long, value_name = "SIGMA", default_value_t = 0.0)]
    noise: f32,
    /// Misregister the model: shift the camera given to the recovery by DX,DY pixels.
    #[arg(long, value_name = "DX,DY", value_parser = parse_shift, default_value = "0,0")]
    shift: (f32, f32),
    /// Give the recovery the camera as it is, without refining its pose (as `recover
    /// --camera-is-calibrated`).
    #[arg(long)]
    camera_is_calibrated: bool,
    /// Write into OUTPUT even if it holds files that are not a matfit output.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    fit: FitArgs,
}

/// Runs `matfit demo`.
pub fn command(args: DemoCli) -> Result<()> {
    let DemoCli {
        scene,
        output,
        photo_spp,
        noise,
        shift,
        camera_is_calibrated,
        force,
        fit,
    } = args;
    checks::output_folder(&output, force)?;
    let opts = demo::DemoOptions {
        scene,
        out: output,
        photo_spp,
        noise,
        shift,
        register: !camera_is_calibrated,
        recover: fit.options(),
    };
    demo::run(&opts).map_err(anyhow::Error::msg)?;
    out::repeat_warnings();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use matfit::io::image::Image;
    use matfit::math::Rgb;

    #[test]
    fn noise_is_relative_gaussian_and_seeded() {
        let mut img = Image::new(200, 150);
        img.data
            .iter_mut()
            .for_each(|p| *p = Rgb::new(0.5, 2.0, 0.0));
        let a = add_noise(&img, 0.01, 7);
        assert_eq!(
            a.data,
            add_noise(&img, 0.01, 7).data,
            "same seed, same noise"
        );
        assert_ne!(a.data, add_noise(&img, 0.01, 8).data);
        // Per channel the multiplier 1 + σ n has mean 1 and standard deviation σ (30 000
        // draws: standard errors 6e-5 and 0.4% of σ); zero stays zero.
        for (c, v) in [(0usize, 0.5f64), (1, 2.0)] {
            let m: Vec<f64> = a.data.iter().map(|p| p[c] as f64 / v).collect();
            let mean = m.iter().sum::<f64>() / m.len() as f64;
            let sd = (m.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / m.len() as f64).sqrt();
            assert!((mean - 1.0).abs() < 3e-4, "mean {mean}");
            assert!((sd / 0.01 - 1.0).abs() < 0.02, "sd {sd}");
            // Gaussian tails: about 4.6% of draws beyond 2σ.
            let tail = m.iter().filter(|x| (*x - 1.0).abs() > 0.02).count() as f64 / m.len() as f64;
            assert!((tail - 0.0455).abs() < 0.006, "tail {tail}");
        }
        assert!(a.data.iter().all(|p| p.z == 0.0));
    }
}
