//! The `matfit` command line: a thin layer of subcommands over the library.

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use matfit::io::atomic::{check_output_file, prepare_output_dir};
use matfit::io::image::Image;
use matfit::render::aov::{aov_image, Aov};
use matfit::render::film::{render, RenderOptions};
use matfit::scene::load_scene;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "matfit",
    version,
    about = "Recover the materials of a scene from one photograph"
)]
struct Cli {
    /// Worker threads (default: all cores). Results do not depend on it.
    #[arg(long, global = true)]
    threads: Option<usize>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene (beauty image or an index buffer / AOV).
    Render {
        scene: PathBuf,
        /// Output image: .exr, .hdr, .pfm or .png (sRGB preview).
        #[arg(short, long)]
        output: PathBuf,
        /// Samples per pixel (default: the scene's [render] spp).
        #[arg(long)]
        spp: Option<u32>,
        /// Random seed (default: the scene's [render] seed).
        #[arg(long)]
        seed: Option<u64>,
        /// What to write.
        #[arg(long, value_enum, default_value = "beauty")]
        aov: Aov,
    },
    /// Recover the materials of a scene's groups from a photograph.
    Recover {
        scene: PathBuf,
        photo: PathBuf,
        /// Output folder (created if needed).
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        fit: FitArgs,
        #[command(flatten)]
        photo_args: matfit::photo::PhotoArgs,
        /// Continue a run in OUT that was interrupted, from its last checkpoint.
        #[arg(long)]
        resume: bool,
    },
    /// Render the figure6 photo, recover its materials blind, print the Figure 6 table.
    Demo {
        /// Another scene to use instead of figure6 (its materials are the truth).
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Output folder; the photo is kept there for the next run.
        #[arg(short, long, default_value = "out/demo")]
        output: PathBuf,
        /// Samples per pixel of the photo.
        #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u32).range(1..))]
        photo_spp: u32,
        /// Add relative Gaussian noise of this standard deviation to the photo (0.01 = 1%).
        #[arg(long, default_value_t = 0.0)]
        noise: f32,
        /// Misregister the model: shift the camera given to the recovery by DX,DY pixels.
        #[arg(long, value_parser = parse_shift, default_value = "0,0")]
        shift: (f32, f32),
        #[command(flatten)]
        fit: FitArgs,
    },
    /// Print a summary of a scene file (groups, objects, triangles, lights, camera).
    Info { scene: PathBuf },
    /// Check a photo against the model before fitting: group outlines over the photo, the
    /// usable-pixel masks, and per-group visible / usable / rejected pixel counts.
    Inspect {
        scene: PathBuf,
        photo: PathBuf,
        /// Output folder (outlines.png, usable.png, edges.png).
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        photo_args: matfit::photo::PhotoArgs,
    },
    /// Export a scene to another renderer: `matfit export mitsuba SCENE -o DIR` writes
    /// DIR/scene.xml (Mitsuba 3) and DIR/meshes/*.ply; approximations are printed as warnings.
    Export {
        format: matfit::export::Format,
        scene: PathBuf,
        /// Output folder (created if needed).
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Benchmarks (figures for the issue notes, not tests).
    Bench {
        #[command(subcommand)]
        which: BenchCommand,
    },
}

/// Options of the fitting engine shared by `recover` and `demo`.
#[derive(clap::Args, Clone)]
struct FitArgs {
    /// Random seed of the caches and the final render.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// At most this many global iterations.
    #[arg(long, default_value_t = 16)]
    max_iterations: u32,
    /// Light samples per cached pixel.
    #[arg(long, default_value_t = 32)]
    light_samples: u32,
    /// Indirect samples per cached pixel.
    #[arg(long, default_value_t = 32)]
    indirect_samples: u32,
    /// At most this many cached pixels per group.
    #[arg(long, default_value_t = 12000)]
    max_pixels: usize,
    /// Cached pixels per group in the first global iteration, doubling each iteration up to
    /// --max-pixels (0: --max-pixels from the start).
    #[arg(long, default_value_t = 1500)]
    first_pixels: usize,
    /// Samples per pixel of the final render.
    #[arg(long, default_value_t = 64)]
    final_spp: u32,
}

impl FitArgs {
    fn options(&self) -> matfit::fit::RecoverOptions {
        let d = matfit::fit::RecoverOptions::default();
        matfit::fit::RecoverOptions {
            seed: self.seed,
            max_iterations: self.max_iterations.max(1),
            final_spp: self.final_spp.max(2),
            first_pixels: self.first_pixels,
            cache: matfit::fit::cache::CacheOptions {
                light_samples: self.light_samples.max(2),
                indirect_samples: self.indirect_samples.max(2),
                max_pixels: self.max_pixels.max(16),
                ..d.cache.clone()
            },
            ..d
        }
    }
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Primary-ray throughput (Mrays/s) on a scene and on a generated mesh of ≥ 1M triangles.
    Rays {
        /// Scene to trace (default: scenes/figure6/scene.toml).
        #[arg(long, default_value = "scenes/figure6/scene.toml")]
        scene: PathBuf,
        /// Triangles of the generated mesh.
        #[arg(long, default_value_t = 1_000_000)]
        triangles: usize,
        /// Repetitions (the median is reported).
        #[arg(long, default_value_t = 5)]
        repeat: usize,
        /// Instead: time one thread's closest-hit and shadow queries on the rays of this file
        /// (little-endian f32 records: origin xyz, direction xyz, shadow-ray length; written
        /// by bench/rays.py, which times Mitsuba 3 on the same rays).
        #[arg(long)]
        ray_file: Option<PathBuf>,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("MATFIT_LOG")
                .unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .without_time()
        .init();
    if let Some(n) = cli.threads {
        if let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global()
        {
            eprintln!("error: cannot set up {n} threads: {e}");
            return ExitCode::from(2);
        }
    }
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Render {
            scene,
            output,
            spp,
            seed,
            aov,
        } => {
            let sc = load_scene(&scene)?;
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
            let img: Image = match aov {
                Aov::Beauty => {
                    let opts = RenderOptions {
                        spp: spp.unwrap_or(sc.render.spp).max(1),
                        seed: seed.unwrap_or(sc.render.seed),
                        progress: true,
                    };
                    let t = std::time::Instant::now();
                    let img = render(&sc, &sc.camera, &opts);
                    tracing::info!("rendered in {:.2} s", t.elapsed().as_secs_f64());
                    img
                }
                other => aov_image(&sc, &sc.camera, other, ext == "png"),
            };
            img.write(&output).map_err(anyhow::Error::msg)?;
            Ok(())
        }
        Command::Recover {
            scene,
            photo,
            output,
            fit,
            photo_args,
            resume,
        } => {
            let mut sc = load_scene(&scene)?;
            // Before any work: the output folder must be usable.
            prepare_output_dir(&output).map_err(anyhow::Error::msg)?;
            let prepared =
                matfit::photo::prepare(&sc, &photo, &photo_args).map_err(anyhow::Error::msg)?;
            // Render through the camera registered to the photo.
            sc.camera = prepared.camera.clone();
            let rec = matfit::cli_recover::run_recover(
                &sc,
                &prepared.photo,
                &prepared.mask,
                &fit.options(),
                &output,
                resume,
            )
            .map_err(anyhow::Error::msg)?;
            for g in &rec.groups {
                println!(
                    "{:<14} {:<17} {:<10} fit ε {:.4} (noise {:.4})",
                    g.name,
                    g.level.name(),
                    format!("{:?}", g.status).to_lowercase(),
                    g.error,
                    g.noise_floor
                );
            }
            println!("outputs in {} ({:.1} s)", output.display(), rec.total_s);
            Ok(())
        }
        Command::Demo {
            scene,
            output,
            photo_spp,
            noise,
            shift,
            fit,
        } => {
            let opts = matfit::demo::DemoOptions {
                scene,
                out: output,
                photo_spp,
                noise,
                shift,
                recover: fit.options(),
            };
            matfit::demo::run(&opts).map_err(anyhow::Error::msg)?;
            Ok(())
        }
        Command::Info { scene } => {
            let sc = load_scene(&scene)?;
            let c = &sc.camera;
            println!("scene {}", scene.display());
            println!(
                "camera {}×{}, fx {:.2} fy {:.2}, fov_y {:.3}°, eye {:?}",
                c.width,
                c.height,
                c.fx,
                c.fy,
                c.fov_y_deg(),
                c.eye()
            );
            println!(
                "triangles {}, ward variant {}",
                sc.triangle_count(),
                sc.render.ward_variant.name()
            );
            for g in &sc.groups {
                let names: Vec<&str> = g
                    .objects
                    .iter()
                    .map(|&o| sc.objects[o].name.as_str())
                    .collect();
                println!(
                    "group {:<14} {}{}",
                    g.name,
                    names.join(", "),
                    if g.fixed { " (fixed)" } else { "" }
                );
            }
            for o in sc.objects.iter().filter(|o| o.is_emitter()) {
                println!(
                    "light {:<14} radiance {:?}, area {:.4}",
                    o.name,
                    o.emission.to_array(),
                    o.area
                );
            }
            Ok(())
        }
        Command::Inspect {
            scene,
            photo,
            output,
            photo_args,
        } => {
            let sc = load_scene(&scene)?;
            prepare_output_dir(&output).map_err(anyhow::Error::msg)?;
            let report = matfit::photo::inspect::inspect(&sc, &photo, &photo_args, &output)
                .map_err(anyhow::Error::msg)?;
            print!("{report}");
            Ok(())
        }
        Command::Export {
            format,
            scene,
            output,
        } => {
            let sc = load_scene(&scene)?;
            prepare_output_dir(&output).map_err(anyhow::Error::msg)?;
            let report = match format {
                matfit::export::Format::Mitsuba => {
                    matfit::export::mitsuba::export(&sc, &output).map_err(anyhow::Error::msg)?
                }
            };
            for w in &report.warnings {
                eprintln!("warning: {w}");
            }
            println!(
                "wrote {} ({} files)",
                report.files[0].display(),
                report.files.len()
            );
            Ok(())
        }
        Command::Bench { which } => match which {
            BenchCommand::Rays {
                scene,
                triangles,
                repeat,
                ray_file,
            } => {
                let sc = load_scene(&scene).with_context(|| "loading the benchmark scene")?;
                match ray_file {
                    Some(f) => matfit::bench::ray_file(&sc, &f, repeat)?,
                    None => matfit::bench::rays(&sc, triangles, repeat),
                }
                Ok(())
            }
        },
    }
}

/// `DX,DY` in pixels.
fn parse_shift(s: &str) -> Result<(f32, f32), String> {
    let bad = || format!("expected DX,DY in pixels (e.g. 2,0), got {s:?}");
    let (a, b) = s.split_once(',').ok_or_else(bad)?;
    let dx: f32 = a.trim().parse().map_err(|_| bad())?;
    let dy: f32 = b.trim().parse().map_err(|_| bad())?;
    if !(dx.is_finite() && dy.is_finite()) {
        return Err(bad());
    }
    Ok((dx, dy))
}
