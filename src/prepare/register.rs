//! Registration: how far the model's projection is off the photo, as a translation on the film
//! — the coarse first step of the pose refinement (`photo::pose`), which takes its whole pixels.
//!
//! Why it is needed beyond the band and the edge detector: those keep the pixels of the wrong
//! surface out of a group, but a model off by d pixels also makes *every* pixel of the group
//! compare the photo at one point with the model at its neighbour, d pixels away. On a surface
//! whose brightness varies across the image (a wall lit from one end) that biases the estimate
//! by d × the mean relative gradient — 0.9% per pixel on figure6's back wall — and no choice of
//! pixels removes it. Correcting the camera does.
//!
//! The estimate: the model's edges, shifted by every integer (dx, dy) within `max_shift`, scored
//! by the mean photo edge strength (|∇ ln Y|, [`edges::log_gradient`]) under them; the best
//! integer shift is refined to sub-pixel by a parabola through its neighbours' scores on each
//! axis. Only a translation, and its sub-pixel part biased by shading beside the edges (below):
//! `photo::pose` refines the rotation and translation of the camera from here.
//!
//! The model's edges are its id boundaries *and* its creases: neighbouring pixels of one object
//! whose shading normals differ by more than [`CREASE_DEG`]. A box's faces are one object but
//! are lit differently, so the photo has a strong edge where two faces meet; left out of the
//! model's edges, such a crease a pixel or two inside an outline pulls the outline onto it. On
//! figure6 at 128×96 (the blocks' lit top faces are 2–3 px tall) that found a 1.19-px vertical
//! shift in a photo rendered through the model's own camera, and the "corrected" camera biased
//! the back wall's ρd by −3% (0.63 for 0.65). With the creases: 0.42 px, below the half-pixel
//! at which `prepare` corrects anything.

use crate::photo::{edges, ignore, Photo};
use crate::render::aov::IndexBuffers;

/// Smallest angle between the shading normals of neighbouring pixels of one object that makes
/// a crease (an edge of the model): a box's 90° edges are creases, the few degrees between the
/// facets of a tessellated curved surface are not (and smooth shading normals hide them anyway).
pub const CREASE_DEG: f32 = 30.0;

/// The translation (model → photo) found, in pixels, and how much better it aligns.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Registration {
    pub dx: f32,
    pub dy: f32,
    /// Mean edge strength under the model's boundaries at the best shift / at no shift.
    pub gain: f32,
}

/// Finds the translation of the photo relative to the model's index buffers (see the module
/// documentation). `Camera::shifted(dx, dy)` then renders the model where the photo has it.
pub fn estimate_shift(ib: &IndexBuffers, photo: &Photo, max_shift: i32) -> Registration {
    let (w, h) = (ib.width as i64, ib.height as i64);
    let g = edges::log_gradient(photo);
    let boundary = model_edges(ib);
    // The ignored object's outline is not the model's: no shift may score on it. A model edge
    // that some shift searched (or its refinement, one more) would bring within the 2-px reach
    // of `log_gradient`'s blur and Sobel is left out at every shift, so that all shifts are
    // scored on the same edges.
    let blocked = ignore::near_ignored(photo, 3 + max_shift.max(0) as usize);
    let boundary: Vec<(i64, i64)> = boundary
        .into_iter()
        .filter(|&(x, y)| !blocked[(y * w + x) as usize])
        .collect();
    let score = |dx: i64, dy: i64| -> f64 {
        let (mut s, mut n) = (0.0f64, 0usize);
        for &(x, y) in &boundary {
            let (xx, yy) = (x + dx, y + dy);
            if xx >= 0 && yy >= 0 && xx < w && yy < h {
                s += g[(yy * w + xx) as usize] as f64;
                n += 1;
            }
        }
        if n == 0 {
            0.0
        } else {
            s / n as f64
        }
    };
    let m = max_shift.max(0) as i64;
    // Shifts by increasing length, so that ties go to the smaller shift.
    let mut shifts: Vec<(i64, i64)> = (-m..=m)
        .flat_map(|dy| (-m..=m).map(move |dx| (dx, dy)))
        .collect();
    shifts.sort_by_key(|&(dx, dy)| dx * dx + dy * dy);
    let mut best = (0i64, 0i64, f64::MIN);
    for (dx, dy) in shifts {
        let s = score(dx, dy);
        if s > best.2 + 1e-12 {
            best = (dx, dy, s);
        }
    }
    let (bx, by, bs) = best;
    let s0 = score(0, 0);
    // Parabola through (−1, a), (0, b), (1, c): vertex at (a − c) / (2 (a − 2b + c)).
    let refine = |a: f64, b: f64, c: f64| {
        let den = a - 2.0 * b + c;
        if den < 0.0 {
            (0.5 * (a - c) / den).clamp(-0.5, 0.5)
        } else {
            0.0
        }
    };
    let fx = refine(score(bx - 1, by), bs, score(bx + 1, by));
    let fy = refine(score(bx, by - 1), bs, score(bx, by + 1));
    Registration {
        dx: (bx as f64 + fx) as f32,
        dy: (by as f64 + fy) as f32,
        gain: if s0 > 0.0 { (bs / s0) as f32 } else { 1.0 },
    }
}

/// The model's edges as pixels: both pixels of every step (the photo's edge response is
/// symmetric about it) between neighbours (4-connected) that see different objects, or one
/// object with shading normals more than [`CREASE_DEG`] apart.
pub fn model_edges(ib: &IndexBuffers) -> Vec<(i64, i64)> {
    let (w, h) = (ib.width as i64, ib.height as i64);
    let cos_crease = CREASE_DEG.to_radians().cos();
    let step = |i: usize, j: usize| {
        ib.object[i] != ib.object[j]
            || (ib.object[i] >= 0 && ib.normal[i].dot(ib.normal[j]) < cos_crease)
    };
    let mut boundary = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            if x + 1 < w && step(i, i + 1) {
                boundary.push((x, y));
                boundary.push((x + 1, y));
            }
            if y + 1 < h && step(i, i + w as usize) {
                boundary.push((x, y));
                boundary.push((x, y + 1));
            }
        }
    }
    boundary
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::image::Image;
    use crate::math::{Rgb, Vec3};

    /// A wall (object 0) around a box (object 1, columns 10..30, rows 10..) whose lit top face
    /// is 3 px tall above its dark front face, as figure6's blocks are at 128×96: a strong
    /// photo edge where the box's faces meet, three pixels below the outline. The photo is
    /// exactly where the model is.
    fn box_below_wall() -> (IndexBuffers, Photo) {
        let (w, h) = (40, 30);
        let up = Vec3::new(0.0, 1.0, 0.0);
        let front = Vec3::new(0.0, 0.0, -1.0);
        let mut ib = IndexBuffers {
            width: w,
            height: h,
            object: vec![0; w * h],
            group: vec![0; w * h],
            mirror_object: vec![-1; w * h],
            mirror_group: vec![-1; w * h],
            normal: vec![front; w * h],
        };
        let mut img = Image::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let (obj, n, v) = match (x, y) {
                    (_, 0..=9) | (0..=9 | 30.., _) => (0, front, 0.5),
                    (_, 10..=12) => (1, up, 2.0),
                    _ => (1, front, 0.1),
                };
                (ib.object[i], ib.group[i], ib.normal[i]) = (obj, obj, n);
                img.set(x, y, Rgb::splat(v));
            }
        }
        (ib, Photo::from_linear(img))
    }

    #[test]
    fn creases_are_model_edges_and_background_is_not() {
        let (mut ib, _) = box_below_wall();
        let e = model_edges(&ib);
        // Outline between rows 9 | 10 and crease between rows 12 | 13, both pixels of each.
        for y in [9, 10, 12, 13] {
            assert!(e.contains(&(15, y)), "row {y}");
        }
        assert!(!e.contains(&(15, 11)) && !e.contains(&(15, 20)));
        // Pixels that see nothing (normal zero) are one region, not a crease everywhere.
        for i in 0..ib.object.len() {
            if i / ib.width < 10 {
                (ib.object[i], ib.normal[i]) = (-1, Vec3::ZERO);
            }
        }
        assert!(!model_edges(&ib).contains(&(15, 3)));
    }

    /// With only the id boundaries the outline was pulled onto the crease (a vertical shift of
    /// 3.06 px); with the creases among the model's edges the aligned photo stays aligned.
    #[test]
    fn a_crease_near_an_outline_does_not_pull_the_registration() {
        let (ib, photo) = box_below_wall();
        let r = estimate_shift(&ib, &photo, 4);
        assert!(r.dx.abs() < 0.25 && r.dy.abs() < 0.25, "{r:?}");
    }

    /// Three objects split at columns 10 and 30, the photo's steps there weak (×1.5), and an
    /// unmodelled bright object over columns 33..38: without a mask its outline pulls the model
    /// 3 px right; masked, the edge at 10 alone keeps the model where it is.
    #[test]
    fn an_ignored_object_does_not_pull_the_registration() {
        let (w, h) = (50, 20);
        let object: Vec<i32> = (0..w * h)
            .map(|i| (i % w >= 10) as i32 + (i % w >= 30) as i32)
            .collect();
        let ib = IndexBuffers {
            width: w,
            height: h,
            group: object.clone(),
            object,
            mirror_object: vec![-1; w * h],
            mirror_group: vec![-1; w * h],
            normal: vec![Vec3::new(0.0, 0.0, -1.0); w * h],
        };
        let mut img = Image::new(w, h);
        let unmodelled = |i: usize| (33..38).contains(&(i % w));
        for (i, c) in img.data.iter_mut().enumerate() {
            *c = Rgb::splat(match i % w {
                _ if unmodelled(i) => 3.0,
                x if x < 10 => 0.2,
                x if x < 30 => 0.3,
                _ => 0.45,
            });
        }
        let mut photo = Photo::from_linear(img);
        let r = estimate_shift(&ib, &photo, 4);
        assert!((r.dx - 3.0).abs() < 0.6, "unmasked: {r:?}");
        photo.set_ignored((0..w * h).map(unmodelled).collect());
        let r = estimate_shift(&ib, &photo, 4);
        assert!(r.dx.abs() < 0.1 && r.dy.abs() < 0.1, "masked: {r:?}");
    }
}
