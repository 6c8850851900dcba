//! What a cache reads from the photo for §5.1's pseudo-textures (`fit/pseudo.rs` chooses between
//! the hypotheses): the groups taken as pseudo-textures, and per cached pixel the mirror radiance
//! with their samples read from the photo.

use super::GroupCache;
use crate::geometry::{Hit, Ray};
use crate::math::{Rgb, Vec2, Vec3};
use crate::scene::Scene;

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
