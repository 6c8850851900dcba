//! Sub-pixel coverage of the index buffer: whether every part of a pixel sees the group its
//! centre sees ("pure"). A pixel on a group boundary mixes two materials' radiance and must not
//! speak for either (a seam between two objects of one group mixes nothing); a pixel inside a thin frame that the band around boundaries would drop is
//! pure and usable. The test is geometric (the model's own outlines), so it costs a few rays
//! per pixel and no photo.

use crate::geometry::packet::LANES;
use crate::geometry::Ray;
use crate::math::sampler::mix64;
use crate::math::{Vec2, Vec3};
use crate::render::aov::IndexBuffers;
use crate::scene::{Camera, Scene};
use rayon::prelude::*;

/// Sub-samples per pixel side: `SUB`² jittered sub-samples, one per stratum, plus the pixel's
/// four corners (the strata alone can miss a boundary that only clips a corner).
pub const SUB: usize = 4;

/// For every pixel, true when its centre sees a group and all of its jittered sub-samples
/// and corners see that same group. The jitter is a hash of the pixel index, so the result is
/// the same on any thread count. The sub-samples of a pixel are nearly one ray, so they are
/// traced as packets of eight (`Scene::intersect8_into`, the same hits as one ray at a time):
/// the strata in two, the corners in a third.
pub fn pure_pixels(scene: &Scene, camera: &Camera, ib: &IndexBuffers) -> Vec<bool> {
    let w = ib.width;
    let g = &*scene.geometry;
    let group_of = |prim: u32| scene.objects[g.tris[prim as usize].object as usize].group as i32;
    (0..ib.width * ib.height)
        .into_par_iter()
        .map(|i| {
            let id = ib.group[i];
            if id < 0 {
                return false;
            }
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let films = sub_samples(i, x, y);
            // Whether every film position of `films` (at most eight) sees group `id`.
            let all_see = |films: &[Vec2]| {
                let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); LANES];
                for (r, &f) in rays.iter_mut().zip(films) {
                    *r = camera.ray(f);
                }
                let mut hits = [None; LANES];
                scene.intersect8_into(rays, (1u32 << films.len()) - 1, &mut hits);
                hits[..films.len()]
                    .iter()
                    .all(|h| h.is_some_and(|h| group_of(h.prim) == id))
            };
            films.chunks(LANES).all(all_see)
        })
        .collect()
}

/// Pixel `i`'s (at (x, y)) film positions that must all see its object: `SUB`² jittered
/// sub-samples, one per stratum, then the four corners nudged inside the pixel, so that a
/// neighbour's boundary exactly on the pixel's edge does not count.
fn sub_samples(i: usize, x: f32, y: f32) -> [Vec2; SUB * SUB + 4] {
    let mut films = [Vec2::ZERO; SUB * SUB + 4];
    let mut h = mix64(i as u64 ^ 0x9e37_79b9_7f4a_7c15);
    for (k, f) in films.iter_mut().take(SUB * SUB).enumerate() {
        h = mix64(h);
        let jx = (h & 0xffff) as f32 / 65536.0;
        let jy = ((h >> 16) & 0xffff) as f32 / 65536.0;
        *f = Vec2::new(
            x + ((k % SUB) as f32 + jx) / SUB as f32,
            y + ((k / SUB) as f32 + jy) / SUB as f32,
        );
    }
    let e = 1e-3;
    for (f, (dx, dy)) in
        films[SUB * SUB..]
            .iter_mut()
            .zip([(e, e), (1.0 - e, e), (e, 1.0 - e), (1.0 - e, 1.0 - e)])
    {
        *f = Vec2::new(x + dx, y + dy);
    }
    films
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photo::Photo;
    use crate::prepare::{usable_pixels, usable_pixels_covered, MaskOptions};
    use crate::render::aov::index_buffers;
    use crate::render::film::{render, RenderOptions};

    /// A wall with a picture frame whose strips are ~4 px wide, a painting inside it and a
    /// small ball (~130 px).
    pub const FRAME_SCENE: &str = r#"
[camera]
width = 160
height = 120
eye = [0.0, 1.5, 3.0]
target = [0.0, 1.5, 0.0]
fov_y_deg = 50.0

[[object]]
name = "wall"
group = "wall"
shape = "quad"
corner = [-3.0, 0.0, 0.0]
edge_u = [6.0, 0.0, 0.0]
edge_v = [0.0, 3.0, 0.0]
material = { type = "diffuse", rho_d = 0.7 }

[[object]]
name = "floor"
group = "floor"
shape = "quad"
corner = [-3.0, 0.0, 0.0]
edge_u = [0.0, 0.0, 4.0]
edge_v = [6.0, 0.0, 0.0]
material = { type = "diffuse", rho_d = 0.4 }

[[object]]
name = "frame_top"
group = "frame"
shape = "quad"
corner = [-0.6, 1.9, 0.01]
edge_u = [1.2, 0.0, 0.0]
edge_v = [0.0, 0.1, 0.0]
material = { type = "diffuse", rho_d = 0.15 }

[[object]]
name = "frame_bottom"
group = "frame"
shape = "quad"
corner = [-0.6, 1.0, 0.01]
edge_u = [1.2, 0.0, 0.0]
edge_v = [0.0, 0.1, 0.0]
material = { type = "diffuse", rho_d = 0.15 }

[[object]]
name = "frame_left"
group = "frame"
shape = "quad"
corner = [-0.6, 1.1, 0.01]
edge_u = [0.1, 0.0, 0.0]
edge_v = [0.0, 0.8, 0.0]
material = { type = "diffuse", rho_d = 0.15 }

[[object]]
name = "frame_right"
group = "frame"
shape = "quad"
corner = [0.5, 1.1, 0.01]
edge_u = [0.1, 0.0, 0.0]
edge_v = [0.0, 0.8, 0.0]
material = { type = "diffuse", rho_d = 0.15 }

[[object]]
name = "painting"
group = "painting"
shape = "quad"
corner = [-0.5, 1.1, 0.005]
edge_u = [1.0, 0.0, 0.0]
edge_v = [0.0, 0.8, 0.0]
material = { type = "diffuse", rho_d = [0.6, 0.3, 0.2] }

[[object]]
name = "ball"
group = "ball"
shape = "sphere"
center = [1.0, 0.6, 0.5]
radius = 0.15
material = { type = "diffuse", rho_d = 0.5 }

[[object]]
name = "lamp"
group = "lamp"
shape = "quad"
corner = [-0.5, 2.99, 0.5]
edge_u = [1.0, 0.0, 0.0]
edge_v = [0.0, 0.0, 1.0]
emission = 20.0
"#;

    /// The packets give what one ray at a time gives (the full hit record's group), on a
    /// scene with both answers in quantity: thin frames, a ball, a floor meeting a wall.
    #[test]
    fn packets_answer_as_one_ray_at_a_time() {
        let scene =
            crate::scene::load::parse_scene(FRAME_SCENE, std::path::Path::new("t/scene.toml"))
                .unwrap();
        let cam = &scene.camera;
        let ib = index_buffers(&scene, cam);
        let w = ib.width;
        let one_by_one: Vec<bool> = (0..w * ib.height)
            .map(|i| {
                let id = ib.group[i];
                id >= 0
                    && sub_samples(i, (i % w) as f32, (i / w) as f32)
                        .iter()
                        .all(|&f| {
                            scene
                                .intersect(&cam.ray(f), f32::INFINITY)
                                .is_some_and(|h| {
                                    scene.objects[h.object as usize].group as i32 == id
                                })
                        })
            })
            .collect();
        let pure = pure_pixels(&scene, cam, &ib);
        let impure = ib
            .group
            .iter()
            .zip(&one_by_one)
            .filter(|(&o, &p)| o >= 0 && !p);
        let (impure, n_pure) = (impure.count(), one_by_one.iter().filter(|&&p| p).count());
        assert!(
            impure > 300 && n_pure > 5000,
            "{impure} impure, {n_pure} pure"
        );
        assert_eq!(pure, one_by_one);
    }

    /// No group with ≥ 100 visible pixels loses them all and the thin frame keeps ≥ 50% with
    /// the adaptive band, where the fixed 2-px band and edge test leave it < 1%; the wall's mask
    /// (a large group) is the fixed band's.
    #[test]
    fn thin_frames_and_small_objects_keep_their_interior() {
        let scene =
            crate::scene::load::parse_scene(FRAME_SCENE, std::path::Path::new("t/scene.toml"))
                .unwrap();
        let ib = index_buffers(&scene, &scene.camera);
        let photo = Photo::from_linear(render(
            &scene,
            &scene.camera,
            &RenderOptions {
                spp: 16,
                seed: 3,
                progress: false,
            },
        ));
        let pure = pure_pixels(&scene, &scene.camera, &ib);
        let n = scene.groups.len();
        let opts = MaskOptions::default();
        let m = usable_pixels_covered(&ib, Some(&pure), &photo, n, &opts);
        let fixed = usable_pixels_covered(
            &ib,
            Some(&pure),
            &photo,
            n,
            &MaskOptions {
                min_usable: 0,
                ..Default::default()
            },
        );
        let frame = scene.group_index("frame").unwrap();
        let wall = scene.group_index("wall").unwrap();
        let table: String = (0..n)
            .map(|g| {
                format!(
                    "{:<10} {:?} | fixed band: usable {}\n",
                    scene.groups[g].name, m.stats[g], fixed.stats[g].usable
                )
            })
            .collect();
        assert!(
            100 * fixed.stats[frame].usable < fixed.stats[frame].visible,
            "{table}"
        );
        for (g, s) in m.stats.iter().enumerate() {
            assert_eq!(s.usable + s.rejected, s.visible);
            if s.visible >= 100
                && !scene.groups[g]
                    .objects
                    .iter()
                    .all(|&o| scene.objects[o].is_emitter())
            {
                assert!(s.usable > 0, "{}: {table}", scene.groups[g].name);
            }
        }
        let f = &m.stats[frame];
        assert!(f.visible > 300, "{table}");
        assert!(2 * f.usable >= f.visible, "{table}");
        assert_eq!(m.stats[wall], fixed.stats[wall], "{table}");
        // Without coverage the narrowest band is 1 px: the frame keeps less, but not nothing.
        let blind = usable_pixels(&ib, &photo, n, &opts);
        assert!(blind.stats[frame].usable > 0, "{table}");
        // A usable pixel is always pure.
        for (i, &g) in m.group.iter().enumerate() {
            assert!(g < 0 || pure[i], "pixel {i}");
        }
        eprintln!("{table}");
    }
}
