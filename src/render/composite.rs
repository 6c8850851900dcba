//! Augmented reality by differential rendering (Debevec 1998, "Rendering synthetic objects
//! into real scenes", §5; the notes' §7): the photo plus what an edit changes in the rendered
//! scene, so that a new object's shadows and reflections fall on the real surfaces while the
//! photo keeps every detail the model lacks.
//!
//!   out = c · L_with + (1 − c) · (photo + L_with − L_without)
//!
//! with L the renders of the recovered scene with and without the edit, through the photo's
//! camera, and c the fraction of the pixel covered by an added object (where the photo shows
//! nothing of it). A removed object's pixels take the second form as well: the photo's
//! residual against the model stays, the object's own radiance is replaced by what the edited
//! scene shows there. The two renders use the same seed: paths that never meet the edit draw
//! the same random numbers and hit the same surfaces, so they cancel to the bit and the
//! composite equals the photo away from the edit's influence (unless the edit adds or removes a
//! light, which changes every path's light choice).

use crate::io::image::Image;
use crate::math::{Rgb, Vec2};
use crate::scene::{Camera, Scene};
use rayon::prelude::*;

/// Rays per pixel side for [`coverage`] (4 × 4 stratified rays).
const COVERAGE_RAYS: usize = 4;

/// Per pixel, the fraction of its area in which the first surface seen belongs to one of the
/// objects flagged in `objects` (indexed like `scene.objects`).
pub fn coverage(scene: &Scene, camera: &Camera, objects: &[bool]) -> Vec<f32> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let n = COVERAGE_RAYS;
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let mut hits = 0;
            for k in 0..n * n {
                let film = Vec2::new(
                    x + ((k % n) as f32 + 0.5) / n as f32,
                    y + ((k / n) as f32 + 0.5) / n as f32,
                );
                if let Some(hit) = scene.intersect(&camera.ray(film), f32::INFINITY) {
                    hits += objects[hit.object as usize] as u32;
                }
            }
            hits as f32 / (n * n) as f32
        })
        .collect()
}

/// The composite of the module's formula, in the photo's radiance units (its exposure divided
/// out). A channel that would go negative (the edit takes away more light than the photo
/// shows there) is clamped at 0.
pub fn differential(photo: &Image, with: &Image, without: &Image, cover: &[f32]) -> Image {
    assert_eq!(
        (photo.width, photo.height),
        (with.width, with.height),
        "photo and renders share the camera"
    );
    let mut out = Image::new(photo.width, photo.height);
    for (i, o) in out.data.iter_mut().enumerate() {
        let c = cover[i];
        let rest = photo.data[i] + with.data[i] - without.data[i];
        *o = (with.data[i] * c + rest * (1.0 - c)).max(Rgb::ZERO);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(v: &[f32]) -> Image {
        let mut im = Image::new(v.len(), 1);
        for (p, &x) in im.data.iter_mut().zip(v) {
            *p = Rgb::splat(x);
        }
        im
    }

    #[test]
    fn photo_plus_the_change_and_the_object_where_it_covers() {
        let photo = image(&[0.50, 0.50, 0.50, 0.05]);
        let without = image(&[0.40, 0.40, 0.40, 0.40]);
        // Pixel 0 untouched, 1 shadowed to half, 2 half covered by an object of radiance 0.9,
        // 3 darkened by more than the photo has.
        let with = image(&[0.40, 0.20, 0.90, 0.10]);
        let cover = [0.0, 0.0, 0.5, 0.0];
        let out = differential(&photo, &with, &without, &cover);
        let got: Vec<f32> = out.data.iter().map(|c| c.x).collect();
        let want = [0.50, 0.30, 0.5 * 0.9 + 0.5 * 1.0, 0.0];
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "{got:?} vs {want:?}");
        }
    }
}
