//! Arbitrary output variables at pixel centres: the paper's *index buffers* (the group and the
//! object each pixel sees, and those it sees through a mirror reflection, §5.1 of the notes),
//! and normals, depth and UVs for inspection.

use super::integrator::{facing, mirror_ray};
use crate::io::image::Image;
use crate::math::{Rgb, Vec2, Vec3};
use crate::scene::{Camera, Scene};
use rayon::prelude::*;

/// Per-pixel ids; −1 where the pixel sees nothing.
#[derive(Clone, Debug, PartialEq)]
pub struct IndexBuffers {
    pub width: usize,
    pub height: usize,
    pub object: Vec<i32>,
    pub group: Vec<i32>,
    /// What the pixel's ray hits after one mirror reflection about the shading normal.
    pub mirror_object: Vec<i32>,
    pub mirror_group: Vec<i32>,
    /// The shading normal on the viewer's side (zero where the pixel sees nothing): where it
    /// turns sharply inside one object (a box's edges) the photo has an edge the ids do not
    /// show (`photo::register`).
    pub normal: Vec<Vec3>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Aov {
    Beauty,
    Group,
    Object,
    MirrorGroup,
    MirrorObject,
    Normal,
    Depth,
    Uv,
}

/// Renders the index buffers through `camera`: one ray through each pixel centre.
pub fn index_buffers(scene: &Scene, camera: &Camera) -> IndexBuffers {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let ids: Vec<([i32; 4], Vec3)> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let film = Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
            let ray = camera.ray(film);
            let Some(hit) = scene.intersect(&ray, f32::INFINITY) else {
                return ([-1; 4], Vec3::ZERO);
            };
            let obj = hit.object as i32;
            let grp = scene.objects[hit.object as usize].group as i32;
            let (mo, mg) =
                match mirror_ray(&ray, &hit).and_then(|r| scene.intersect(&r, f32::INFINITY)) {
                    Some(m) => (
                        m.object as i32,
                        scene.objects[m.object as usize].group as i32,
                    ),
                    None => (-1, -1),
                };
            ([obj, grp, mo, mg], facing(hit.frame, hit.ng, -ray.d).0.n)
        })
        .collect();
    IndexBuffers {
        width: w,
        height: h,
        object: ids.iter().map(|v| v.0[0]).collect(),
        group: ids.iter().map(|v| v.0[1]).collect(),
        mirror_object: ids.iter().map(|v| v.0[2]).collect(),
        mirror_group: ids.iter().map(|v| v.0[3]).collect(),
        normal: ids.iter().map(|v| v.1).collect(),
    }
}

/// A distinct, stable colour for an id (black for −1), for previews of index buffers.
pub fn id_color(id: i32) -> Rgb {
    if id < 0 {
        return Rgb::ZERO;
    }
    let h = crate::math::sampler::mix64(id as u64 + 1);
    let c = |k: u32| 0.15 + 0.85 * (((h >> (k * 16)) & 0xffff) as f32 / 65535.0);
    Rgb::new(c(0), c(1), c(2)).powf(2.2)
}

/// A geometric AOV as an image: ids as numbers (for EXR/PFM) or colours (`as_colors`, for PNG).
pub fn aov_image(scene: &Scene, camera: &Camera, aov: Aov, as_colors: bool) -> Image {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut img = Image::new(w, h);
    let ids = match aov {
        Aov::Group | Aov::Object | Aov::MirrorGroup | Aov::MirrorObject => {
            Some(index_buffers(scene, camera))
        }
        _ => None,
    };
    if let Some(ib) = ids {
        let v = match aov {
            Aov::Group => &ib.group,
            Aov::Object => &ib.object,
            Aov::MirrorGroup => &ib.mirror_group,
            _ => &ib.mirror_object,
        };
        for (o, &id) in img.data.iter_mut().zip(v) {
            *o = if as_colors {
                id_color(id)
            } else {
                Rgb::splat(id as f32)
            };
        }
        return img;
    }
    img.data.par_iter_mut().enumerate().for_each(|(i, o)| {
        let film = Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
        let ray = camera.ray(film);
        if let Some(hit) = scene.intersect(&ray, f32::INFINITY) {
            *o = match aov {
                Aov::Normal => {
                    let n = facing(hit.frame, hit.ng, -ray.d).0.n;
                    if as_colors {
                        0.5 * (n + Rgb::ONE)
                    } else {
                        n
                    }
                }
                Aov::Depth => Rgb::splat(hit.t),
                Aov::Uv => Rgb::new(hit.uv.x, hit.uv.y, 0.0),
                _ => Rgb::ZERO,
            };
        }
    });
    img
}
