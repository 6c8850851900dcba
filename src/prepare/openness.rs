//! How open the scene is around what the photo sees: the cosine-weighted share of the usable
//! pixels' hemispheres that sees no geometry. The recovery's caches measure the same share from
//! their own indirect rays (`GroupCache::open`); `matfit inspect` measures it here, before any
//! fit, so that the user can choose `--stray-light` before a recovery rather than after it.
//! Where the share is large and the scene has no environment, light from outside the model (a
//! window, a lamp out of frame, the sky over an open-topped set) can reach the photo, and the
//! model says none does.

use crate::geometry::{offset_origin, Ray};
use crate::math::{warp, Sampler, Vec2};
use crate::prepare::mask::{Reject, UsableMask};
use crate::render::integrator::facing;
use crate::scene::{Camera, Scene};
use rayon::prelude::*;

/// The open share above which a scene with neither an environment nor a stray light is
/// warned about (by `recover` from its caches, by `inspect` from `open_share`).
pub const OPEN_SCENE: f64 = 0.05;

/// Usable pixels looked at, at most (every k-th in scan order).
const PIXELS: usize = 4096;
/// Cosine-distributed rays from each of them.
const RAYS: u32 = 16;

/// The cosine-weighted share of the usable pixels' hemispheres (on the side facing the camera)
/// that sees no geometry: the mean over up to `PIXELS` usable pixels of the share of `RAYS`
/// cosine-distributed rays from the surface point each pixel's centre sees that leave the
/// scene. 0 without usable pixels. Deterministic: each pixel's sampler is seeded by its index.
pub fn open_share(scene: &Scene, camera: &Camera, mask: &UsableMask) -> f64 {
    let usable: Vec<usize> = (0..mask.reason.len())
        .filter(|&i| mask.reason[i] == Reject::None)
        .collect();
    if usable.is_empty() {
        return 0.0;
    }
    let step = usable.len().div_ceil(PIXELS);
    let picked: Vec<usize> = usable.into_iter().step_by(step).collect();
    let w = mask.width;
    let escaped: u64 = picked
        .par_iter()
        .map(|&i| {
            let film = Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
            let ray = camera.ray(film);
            let Some(hit) = scene.intersect(&ray, f32::INFINITY) else {
                return 0;
            };
            let (frame, ng) = facing(hit.frame, hit.ng, -ray.d);
            let mut sampler = Sampler::new(0x0be2_5ca1, i as u64);
            (0..RAYS)
                .filter(|&k| {
                    sampler.start_sample(k);
                    let d = frame.to_world(warp::cosine_hemisphere(sampler.next_2d()));
                    ng.dot(d) > 0.0
                        && !scene.occluded(&Ray::new(offset_origin(hit.p, ng, d), d), f32::INFINITY)
                })
                .count() as u64
        })
        .sum();
    escaped as f64 / (picked.len() as u64 * RAYS as u64) as f64
}

/// What a recovery without `--stray-light` of a scene with no environment assumes, where the
/// open share `open` is above `OPEN_SCENE`: said where the user sees it, with the option that
/// fits the light instead.
pub fn open_scene_warning(open: f64) -> String {
    format!(
        "the scene is open: {:.0}% of what the seen surfaces face is no geometry, and nothing \
         is assumed to shine from there but the scene's lights; if the photo's shadows hold \
         light from outside the model, --stray-light fits it",
        100.0 * open
    )
}
