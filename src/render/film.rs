//! Rendering a whole image: every pixel independently, in parallel over rows, each pixel with
//! its own sampler stream keyed by (seed, pixel), so the image is bit-identical whatever the
//! number of threads. Pixels use a box filter (uniform jitter inside the pixel).

use super::{batch, PathTracer};
use crate::io::image::Image;
use crate::io::progress::Bar;
use crate::math::{Rgb, Sampler, Vec2};
use crate::scene::{Camera, Scene};
use rayon::prelude::*;

/// Options of one render.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub spp: u32,
    pub seed: u64,
    /// Report progress to the process's progress sink (`crate::io::progress`).
    pub progress: bool,
}

/// A progress counter over `len` steps, reported to the process's progress sink if `show`
/// (`crate::io::progress`: the library draws nothing itself).
pub fn progress_bar(len: u64, what: &str, show: bool) -> Bar<'static> {
    Bar::new(len, what, show)
}

/// Renders the scene through `camera` (normally `scene.camera`), at least one sample per pixel.
pub fn render(scene: &Scene, camera: &Camera, opts: &RenderOptions) -> Image {
    let bar = progress_bar(camera.height as u64, "render", opts.progress);
    render_marked(&PathTracer::new(scene), camera, opts, None, bar, None)
}

/// [`render`], reporting its progress to `report` (whatever `opts.progress` says) and asking
/// `cancelled` between rows: None when it said stop (the rows not yet started are skipped).
pub fn render_reporting(
    scene: &Scene,
    camera: &Camera,
    opts: &RenderOptions,
    report: impl Fn(&crate::io::progress::Progress) + Send + Sync,
    cancelled: &(dyn Fn() -> bool + Sync),
) -> Option<Image> {
    render_cancellable(&PathTracer::new(scene), camera, opts, report, cancelled)
}

/// [`render_reporting`] with next-event estimation through planar mirrors
/// (`PathTracer::with_mirror_lights`): what `matfit render` draws. Less noise where light
/// arrives by way of a mirror, the same image in expectation; the other renders (a recovery's
/// photo-like renders and final render, composites) keep the plain path tracer, on whose noise
/// the recovery's tests were measured.
pub fn render_image(
    scene: &Scene,
    camera: &Camera,
    opts: &RenderOptions,
    report: impl Fn(&crate::io::progress::Progress) + Send + Sync,
    cancelled: &(dyn Fn() -> bool + Sync),
) -> Option<Image> {
    let pt = PathTracer::new(scene).with_mirror_lights();
    render_cancellable(&pt, camera, opts, report, cancelled)
}

/// The image `pt` traces, its progress told to `report`, `cancelled` asked between rows: None
/// when it said stop.
fn render_cancellable(
    pt: &PathTracer,
    camera: &Camera,
    opts: &RenderOptions,
    report: impl Fn(&crate::io::progress::Progress) + Send + Sync,
    cancelled: &(dyn Fn() -> bool + Sync),
) -> Option<Image> {
    let bar = Bar::to(camera.height as u64, "render", report);
    let stop = std::sync::atomic::AtomicBool::new(false);
    let img = render_marked(pt, camera, opts, None, bar, Some((cancelled, &stop)));
    (!stop.into_inner()).then_some(img)
}

/// Renders only the pixels `wanted` marks (row-major, the camera's size), each to the value
/// [`render`] gives it (the pixel's sampler is keyed by its index, not by what else is
/// rendered); the others stay zero. For callers that read a few pixels of an image.
pub fn render_where(
    scene: &Scene,
    camera: &Camera,
    opts: &RenderOptions,
    wanted: &[bool],
) -> Image {
    let (w, h) = (camera.width as usize, camera.height as usize);
    assert_eq!(
        wanted.len(),
        w * h,
        "render_where: the mask is not the camera's size"
    );
    let bar = progress_bar(camera.height as u64, "render", opts.progress);
    render_marked(&PathTracer::new(scene), camera, opts, Some(wanted), bar, None)
}

/// [`render`] of every pixel, or of those `wanted` marks; with `cancel`, a row starts only
/// while its function says go on, and the flag records that it said stop.
fn render_marked(
    pt: &PathTracer,
    camera: &Camera,
    opts: &RenderOptions,
    wanted: Option<&[bool]>,
    pb: Bar<'_>,
    cancel: Option<(&(dyn Fn() -> bool + Sync), &std::sync::atomic::AtomicBool)>,
) -> Image {
    use std::sync::atomic::Ordering::Relaxed;
    let spp = opts.spp.max(1);
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut img = Image::new(w, h);
    // Pixels go to the batch integrator a run at a time, at most ~2^16 samples per run (the
    // size of its buffer of per-sample values).
    let run = (65_536 / spp as usize).clamp(1, w.max(1));
    img.data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        if let Some((cancelled, stop)) = cancel {
            if stop.load(Relaxed) || cancelled() {
                stop.store(true, Relaxed);
                return;
            }
        }
        let marked = |x: usize| wanted.is_none_or(|m| m[y * w + x]);
        let mut x = 0;
        while x < w {
            if !marked(x) {
                x += 1;
                continue;
            }
            let end = (x..w).find(|&e| !marked(e)).unwrap_or(w).min(x + run);
            batch::render_pixels(pt, camera, y, x, spp, opts.seed, &mut row[x..end]);
            x = end;
        }
        pb.inc(1);
    });
    pb.finish_and_clear();
    img
}

/// The mean of `spp` samples of pixel (x, y), one path at a time (`batch.rs` computes the same
/// value eight paths at a time). Non-finite samples are dropped (and would be a bug).
pub fn render_pixel(
    pt: &PathTracer,
    camera: &Camera,
    x: usize,
    y: usize,
    spp: u32,
    seed: u64,
) -> Rgb {
    let mut sampler = Sampler::new(seed, (y * camera.width as usize + x) as u64);
    let samples = (0..spp).map(|s| {
        sampler.start_sample(s);
        let film = Vec2::new(x as f32, y as f32) + sampler.next_2d();
        pt.li(camera.ray(film), &mut sampler)
    });
    batch::pixel_mean(samples, spp)
}
