//! Benchmarks run by `matfit bench`: figures for the issue notes, measured on the machine at
//! hand, reported as medians of several repetitions.

use crate::geometry::{shapes, Bvh, Ray};
use crate::math::{Vec2, Vec3};
use crate::scene::{Camera, Scene};
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
    println!("primary rays, closest hit, {threads} threads, median of {repeat}");
    let runs: Vec<f64> = (0..repeat)
        .map(|_| {
            throughput(&scene.camera, 8, |r| {
                scene.intersect(r, f32::INFINITY).is_some()
            })
            .0
        })
        .collect();
    println!(
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
    println!(
        "  {:<28} {:>10} tris  {:>7.2} Mrays/s  (BVH build {:.2} s, {} nodes, {:.0}% of rays hit)",
        "sphere mesh",
        tris.len(),
        median(runs.iter().map(|r| r.0).collect()),
        build,
        bvh.node_count(),
        100.0 * hit_frac
    );
}
