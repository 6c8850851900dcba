//! Pseudo-textures (§5.1 of the notes, "the problem of multiple specular reflections").
//!
//! A mirror's pixels show what it reflects, so its ρs is fitted against a render of those
//! objects. While one of them is still being analysed its material is wrong (a book still at the
//! diffuse level has no texture yet, a second mirror no ρs yet), and the mirror absorbs the error:
//! its ρs is biased or its ε is so high that it is taken for a texture. The notes' remedy: take
//! the analysed object B as a *pseudo-texture*, its radiance read straight from the photo with no
//! illumination computed, fit the mirror A against that, and keep whichever hypothesis fits best.
//!
//! Here, while A's cache is built, each mirror sample whose reflected ray first lands on a group
//! still being analysed is traced twice: rendered through the current scene (B as currently
//! modelled, "both specular with the stored properties" when B is a mirror too) and read from the
//! photo where the camera sees the same point ([`photo_radiance`]). A is fitted at its mirror
//! level against both ([`choose`]); the smaller error ε wins for this iteration and
//! `log.jsonl` records both errors (`hypotheses`). The notes' third hypothesis, "A
//! pseudo-textured and B specular", is B's own fit with A taken from the photo. As in the notes,
//! only the group being fitted is decided: B keeps being analysed. Reading B from the photo is
//! exact for a diffuse B (its radiance does not depend on the direction it is seen from) and
//! wrong for a mirror B (it shows something else to the camera than to A); the comparison of
//! the two hypotheses is what tells them apart. `recover --no-pseudo-textures` turns it off.

use super::cache::GroupCache;
use super::fitter::fit_level;
use super::hierarchy::{Event, GroupState};
use super::level::Level;
use crate::geometry::{Hit, Ray};
use crate::math::{Rgb, Vec2, Vec3};
use crate::scene::Scene;
use crate::scene::WardVariant;

/// Below this share of a cache's mirror samples read from the photo, the two hypotheses cannot
/// differ by more than the noise: the rendered one is kept without comparing.
pub const MIN_SHARE: f32 = 0.01;

/// What a cache reads from the photo: the groups still being analysed (other than the cache's
/// own), and where in the photo each group is seen on a usable pixel.
pub struct PseudoTextures<'a> {
    /// Per group of the scene: taken as a pseudo-texture.
    pub groups: Vec<bool>,
    /// Group of each usable pixel of the photo, −1 elsewhere (`UsableMask::group`).
    pub usable: &'a [i32],
    /// The photo, in the units of the cache (`CachePixel::photo`).
    pub photo: &'a [Rgb],
}

/// A cache's mirror radiance under the pseudo-texture hypothesis.
#[derive(Clone, Debug, Default)]
pub struct PseudoMirror {
    /// Per cached pixel, each half's mirror radiance, the samples landing on a pseudo-textured
    /// group read from the photo (the others as rendered).
    pub half: Vec<[Rgb; 2]>,
    /// Share of the cache's mirror samples read from the photo.
    pub share: f32,
    /// The groups read from the photo (scene group indices, ascending).
    pub groups: Vec<usize>,
}

impl GroupCache {
    /// Exchanges the pixels' mirror radiance with `pseudo`'s (a second call restores it).
    pub fn swap_mirror(&mut self, pseudo: &mut PseudoMirror) {
        for (p, h) in self.pixels.iter_mut().zip(pseudo.half.iter_mut()) {
            std::mem::swap(&mut p.mirror_half, h);
            p.mirror = 0.5 * (p.mirror_half[0] + p.mirror_half[1]);
        }
    }
}

impl PseudoTextures<'_> {
    /// The photo's radiance at `hit`, the first surface `ray` meets, if that surface belongs to
    /// a pseudo-textured group and the camera sees that very point on usable pixels of it (the
    /// group, as the second value).
    pub fn radiance(&self, scene: &Scene, ray: &Ray, hit: &Hit) -> Option<(Rgb, usize)> {
        let hit = scene.surface_hit(ray, hit);
        let group = scene.objects[hit.object as usize].group;
        if !self.groups.get(group).copied().unwrap_or(false) {
            return None;
        }
        photo_radiance(scene, self.photo, self.usable, hit.p, hit.object, group).map(|l| (l, group))
    }
}

/// The photo's radiance at point `p` of `object` (in `group`): bilinear over the four pixels
/// around its projection when all four are usable pixels of the group, else the nearest pixel if
/// it is; None when the point is outside the image, hidden from the camera by another surface,
/// or on no usable pixel of its group.
pub fn photo_radiance(
    scene: &Scene,
    photo: &[Rgb],
    usable: &[i32],
    p: Vec3,
    object: u32,
    group: usize,
) -> Option<Rgb> {
    let cam = &scene.camera;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let film = cam.project(p)?;
    if !(film.x >= 0.0 && film.y >= 0.0 && film.x < w as f32 && film.y < h as f32) {
        return None;
    }
    // Seen by the camera: its ray through that film point meets the same object at the same
    // distance (to a thousandth), not an occluder in front.
    let ray = cam.ray(film);
    let seen = scene.intersect(&ray, f32::INFINITY)?;
    let dist = (p - ray.o).length();
    if seen.object != object || (seen.t - dist).abs() > 1e-3 * dist {
        return None;
    }
    let ours = |x: usize, y: usize| usable[y * w + x] == group as i32;
    let f = Vec2::new(film.x - 0.5, film.y - 0.5);
    let (x0, y0) = (f.x.floor(), f.y.floor());
    let (tx, ty) = (f.x - x0, f.y - y0);
    if x0 >= 0.0 && y0 >= 0.0 && (x0 as usize) + 1 < w && (y0 as usize) + 1 < h {
        let (x0, y0) = (x0 as usize, y0 as usize);
        if ours(x0, y0) && ours(x0 + 1, y0) && ours(x0, y0 + 1) && ours(x0 + 1, y0 + 1) {
            let at = |x: usize, y: usize| photo[y * w + x];
            let top = at(x0, y0) * (1.0 - tx) + at(x0 + 1, y0) * tx;
            let bottom = at(x0, y0 + 1) * (1.0 - tx) + at(x0 + 1, y0 + 1) * tx;
            return Some(top * (1.0 - ty) + bottom * ty);
        }
    }
    let (x, y) = (film.x as usize, film.y as usize);
    ours(x, y).then(|| photo[y * w + x])
}

/// Chooses between the rendered and the pseudo-textured mirror radiance of `cache` for group
/// `group`: both fitted at its mirror level (ideal mirror ρs when it is not at one yet), the
/// smaller error ε kept (the notes' criterion). Leaves the chosen one in `cache` and returns
/// the event to log and whether the photo's was taken, the other radiance left in `pseudo`
/// (swap again to restore the rendered one); None, with the rendered one in `cache`, for a
/// group that is not being taken for a mirror.
pub fn choose(
    cache: &mut GroupCache,
    pseudo: &mut PseudoMirror,
    states: &[GroupState],
    group: usize,
    variant: WardVariant,
) -> Option<(Event, bool)> {
    let state = &states[group];
    let level = if state.level.is_mirror() {
        state.level
    } else {
        Level::Specular
    };
    let rendered = fit_level(cache, level, &state.params, variant);
    cache.swap_mirror(pseudo);
    let read = fit_level(cache, level, &state.params, variant);
    // A group that fits worse as a mirror either way than at its own level is not being taken
    // for one: nothing to decide (its first fit, error 0, has no level to compare with yet).
    if !state.level.is_mirror()
        && state.error > 0.0
        && rendered.error.min(read.error) >= state.error
    {
        cache.swap_mirror(pseudo);
        return None;
    }
    let take = read.error < rendered.error;
    if !take {
        cache.swap_mirror(pseudo);
    }
    let event = Event::Hypotheses {
        level,
        pseudo_textured: pseudo
            .groups
            .iter()
            .map(|&g| states[g].name.clone())
            .collect(),
        share: pseudo.share,
        error_rendered: rendered.error,
        error_pseudo: read.error,
        chose: if take { "pseudo_texture" } else { "rendered" }.to_string(),
    };
    Some((event, take))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::aov::index_buffers;
    use crate::render::film::{render, RenderOptions};
    use crate::scene::load::parse_scene;

    /// A floor and a wall under a lamp; the camera sees both.
    const ROOM: &str = r#"
[render]
spp = 64
seed = 1
[camera]
width = 64
height = 48
eye = [0.0, 1.0, 2.0]
target = [0.0, 0.6, -1.0]
up = [0.0, 1.0, 0.0]
fov_y_deg = 60.0
[[object]]
name = "floor"
group = "floor"
shape = "quad"
corner = [-2.0, 0.0, 3.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 0.0, -5.0]
material = { type = "diffuse", rho_d = [0.6, 0.4, 0.2] }
[[object]]
name = "wall"
group = "wall"
shape = "quad"
corner = [-2.0, 0.0, -2.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 3.0, 0.0]
material = { type = "diffuse", rho_d = 0.5 }
[[object]]
name = "lamp"
group = "lamp"
shape = "quad"
corner = [-0.5, 2.5, -0.5]
edge_u = [1.0, 0.0, 0.0]
edge_v = [0.0, 0.0, 1.0]
emission = 10.0
"#;

    #[test]
    fn a_seen_point_reads_the_photo_where_the_camera_sees_it() {
        let scene = parse_scene(ROOM, std::path::Path::new("room.toml")).unwrap();
        let photo = render(
            &scene,
            &scene.camera,
            &RenderOptions {
                spp: 16,
                seed: 3,
                progress: false,
            },
        );
        let ib = index_buffers(&scene, &scene.camera);
        let w = scene.camera.width as usize;
        let floor = scene.group_index("floor").unwrap();
        // Every pixel of the floor counts as usable here.
        let usable: Vec<i32> = ib.group.clone();
        // A ray from elsewhere (above the lamp's side) onto a floor point the camera sees: the
        // value is the photo's at that point's pixel (interpolated), not a render.
        let (px, py) = (30usize, 40usize);
        assert_eq!(ib.group[py * w + px], floor as i32);
        let cam_ray = scene
            .camera
            .ray(Vec2::new(px as f32 + 0.5, py as f32 + 0.5));
        let p = scene.intersect(&cam_ray, f32::INFINITY).unwrap().p;
        let from = Vec3::new(1.5, 2.0, 1.0);
        let first = |r: &Ray| scene.intersect_hit(r, f32::INFINITY).unwrap();
        let ray = Ray::new(from, (p - from).normalize());
        let pt = PseudoTextures {
            groups: (0..scene.groups.len()).map(|g| g == floor).collect(),
            usable: &usable,
            photo: &photo.data,
        };
        let (l, g) = pt.radiance(&scene, &ray, &first(&ray)).unwrap();
        assert_eq!(g, floor);
        let want = photo.data[py * w + px];
        assert!((l - want).abs().max_element() < 1e-4, "{l:?} vs {want:?}");
        // The wall is not pseudo-textured: a ray onto it reads nothing.
        let wall = Ray::new(from, (Vec3::new(0.0, 1.5, -2.0) - from).normalize());
        assert!(pt.radiance(&scene, &wall, &first(&wall)).is_none());
        // A floor point hidden from the camera (behind it) reads nothing.
        let behind = Vec3::new(0.0, 0.0, 2.8);
        let hidden = Ray::new(from, (behind - from).normalize());
        assert!(pt.radiance(&scene, &hidden, &first(&hidden)).is_none());
        // Nor does a point on a pixel that is not usable.
        let mut none = usable.clone();
        none.iter_mut().for_each(|g| *g = -1);
        let masked = PseudoTextures {
            usable: &none,
            ..pt
        };
        assert!(masked.radiance(&scene, &ray, &first(&ray)).is_none());
    }
}
