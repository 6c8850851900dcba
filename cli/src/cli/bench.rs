//! Benchmarks run by `matfit bench`: figures for the issue notes, measured on the machine at
//! hand, reported as medians of several repetitions.

use super::*;
use matfit::geometry::packet::{Packet, LANES};
use matfit::geometry::{shapes, Bvh, Ray};
use matfit::math::{Vec2, Vec3};
use matfit::scene::{Camera, Scene};
use rayon::prelude::*;
use std::time::Instant;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Traces one primary ray per pixel through `camera` with `trace`, `passes` times over the
/// image; returns Mrays/s (all threads).
fn throughput(camera: &Camera, passes: usize, trace: impl Fn(&Ray) -> bool + Sync) -> (f64, usize) {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let t = Instant::now();
    let hits: usize = (0..h * passes)
        .into_par_iter()
        .map(|row| {
            let y = row % h;
            (0..w)
                .filter(|&x| {
                    let film = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                    trace(&camera.ray(film))
                })
                .count()
        })
        .sum();
    let secs = t.elapsed().as_secs_f64();
    ((w * h * passes) as f64 / secs / 1e6, hits)
}

/// Primary-ray throughput on `scene` and on a sphere tessellated into ≥ `triangles` triangles.
pub fn rays(scene: &Scene, triangles: usize, repeat: usize) {
    let threads = rayon::current_num_threads();
    crate::outln!("primary rays, closest hit, {threads} threads, median of {repeat}");
    let runs: Vec<f64> = (0..repeat)
        .map(|_| {
            throughput(&scene.camera, 8, |r| {
                scene.intersect(r, f32::INFINITY).is_some()
            })
            .0
        })
        .collect();
    crate::outln!(
        "  {:<28} {:>10} tris  {:>7.2} Mrays/s",
        scene.path.display(),
        scene.triangle_count(),
        median(runs)
    );
    // A UV sphere of ≥ `triangles` triangles filling the view of a 1024×768 camera.
    let seg = ((triangles as f64 / 2.0).sqrt().ceil() as u32).max(8);
    let mesh = shapes::sphere(Vec3::ZERO, 1.0, seg * 2);
    let tris: Vec<[Vec3; 3]> = (0..mesh.indices.len()).map(|i| mesh.triangle(i)).collect();
    let t = Instant::now();
    let bvh = Bvh::build(&tris);
    let build = t.elapsed().as_secs_f64();
    let cam = Camera::look_at(
        1024,
        768,
        Vec3::new(0.0, 0.0, 2.6),
        Vec3::ZERO,
        Vec3::Y,
        45.0,
    )
    .unwrap();
    let runs: Vec<(f64, usize)> = (0..repeat)
        .map(|_| throughput(&cam, 2, |r| bvh.intersect(r, f32::INFINITY).is_some()))
        .collect();
    let hit_frac = runs[0].1 as f64 / (2 * 1024 * 768) as f64;
    crate::outln!(
        "  {:<28} {:>10} tris  {:>7.2} Mrays/s  (BVH build {:.2} s, {} nodes, {:.0}% of rays hit)",
        "sphere mesh",
        tris.len(),
        median(runs.iter().map(|r| r.0).collect()),
        build,
        bvh.node_count(),
        100.0 * hit_frac
    );
}

/// One thread's cost per ray (ns, median of `repeat` passes) of closest-hit queries with the
/// hit record (`Scene::intersect`), of the BVH query alone, and of shadow queries, on the rays
/// of `path`: little-endian f32 records (origin xyz, direction xyz, shadow-ray length).
/// `bench/rays.py` writes such a file and times Mitsuba 3 on the same rays.
pub fn ray_file(scene: &Scene, path: &std::path::Path, repeat: usize) -> anyhow::Result<()> {
    let bytes = std::fs::read(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    if bytes.is_empty() || bytes.len() % 28 != 0 {
        anyhow::bail!(
            "{}: {} bytes is not a whole number of 28-byte ray records",
            path.display(),
            bytes.len()
        );
    }
    let f: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let rays: Vec<(Ray, f32)> = f
        .chunks_exact(7)
        .map(|r| {
            let ray = Ray::new(Vec3::new(r[0], r[1], r[2]), Vec3::new(r[3], r[4], r[5]));
            (ray, r[6])
        })
        .collect();
    // ns per ray of one pass over all the rays (`pass` returns a count, kept from the optimiser).
    let per_ray = |pass: &dyn Fn() -> u32| {
        let runs = (0..repeat.max(1))
            .map(|_| {
                let t = Instant::now();
                std::hint::black_box(pass());
                t.elapsed().as_secs_f64() * 1e9 / rays.len() as f64
            })
            .collect();
        median(runs)
    };
    let time =
        |f: &dyn Fn(&Ray, f32) -> u32| per_ray(&|| rays.iter().map(|(r, len)| f(r, *len)).sum());
    let closest = time(&|r, _| u32::from(scene.intersect(r, f32::INFINITY).is_some()));
    let bvh_one = time(&|r, _| u32::from(scene.geometry.bvh.intersect(r, f32::INFINITY).is_some()));
    let shadow = time(&|r, len| u32::from(scene.occluded(r, len)));
    // The same queries eight rays at a time (`geometry::packet`), in the file's order.
    let packets = |shadow: bool| -> Vec<Packet> {
        rays.chunks(LANES)
            .map(|c| {
                let idle = (Ray::new(Vec3::ZERO, Vec3::Z), 0.0);
                let lane = |i: usize| c.get(i).copied().unwrap_or(idle);
                Packet::new(
                    std::array::from_fn(|i| lane(i).0),
                    std::array::from_fn(|i| if shadow { lane(i).1 } else { f32::INFINITY }),
                    (1u32 << c.len()) - 1,
                )
            })
            .collect()
    };
    let time8 =
        |packets: &[Packet], f: &dyn Fn(&Packet) -> u32| per_ray(&|| packets.iter().map(f).sum());
    let tree = &scene.geometry.bvh;
    let bvh8 = time8(&packets(false), &|p| {
        tree.intersect8(p).iter().flatten().count() as u32
    });
    let shadow8 = time8(&packets(true), &|p| tree.occluded8(p).count_ones());
    let hits = rays
        .iter()
        .filter(|(r, _)| scene.intersect(r, f32::INFINITY).is_some())
        .count();
    crate::outln!(
        "{} rays from {}, 1 thread, median of {repeat}: closest hit with hit record {closest:.1} ns, \
         BVH query alone {bvh_one:.1} ns, shadow {shadow:.1} ns ({:.1}% hit); packets of 8: \
         BVH query {bvh8:.1} ns, shadow {shadow8:.1} ns",
        rays.len(),
        path.display(),
        100.0 * hits as f64 / rays.len() as f64
    );
    Ok(())
}

#[derive(Subcommand)]
pub enum BenchCommand {
    /// Primary rays per second on a scene and on a generated mesh of ≥ 1M triangles.
    Rays {
        /// Scene to trace.
        #[arg(long, default_value = "scenes/figure6/scene.toml")]
        scene: PathBuf,
        /// Triangles of the generated mesh.
        #[arg(long, value_name = "N", default_value_t = 1_000_000)]
        triangles: usize,
        /// Repetitions (the median is reported).
        #[arg(long, value_name = "N", default_value_t = 5)]
        repeat: usize,
        /// Instead: time one thread's closest-hit and shadow queries on the rays of this file
        /// (little-endian f32 records: origin xyz, direction xyz, shadow-ray length; written
        /// by bench/rays.py, which times Mitsuba 3 on the same rays).
        #[arg(long)]
        ray_file: Option<PathBuf>,
    },
}

/// The arguments of `matfit bench` (see `Command::Bench`).
#[derive(clap::Args)]
pub struct BenchCli {
    #[command(subcommand)]
    which: BenchCommand,
}

/// Runs `matfit bench`.
pub fn command(args: BenchCli) -> Result<()> {
    let BenchCli { which } = args;
    match which {
        BenchCommand::Rays {
            scene,
            triangles,
            repeat,
            ray_file,
        } => {
            let sc = load_scene(&scene).with_context(|| "loading the benchmark scene")?;
            match ray_file {
                Some(f) => bench::ray_file(&sc, &f, repeat)?,
                None => bench::rays(&sc, triangles, repeat),
            }
            Ok(())
        }
    }
}
