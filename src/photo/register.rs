//! Registration: how far the model's projection is off the photo, as a translation on the film.
//!
//! Why it is needed beyond the band and the edge detector: those keep the pixels of the wrong
//! surface out of a group, but a model off by d pixels also makes *every* pixel of the group
//! compare the photo at one point with the model at its neighbour, d pixels away. On a surface
//! whose brightness varies across the image (a wall lit from one end) that biases the estimate
//! by d × the mean relative gradient — 0.9% per pixel on figure6's back wall — and no choice of
//! pixels removes it. Correcting the camera does.
//!
//! The estimate: the model's id boundaries, shifted by every integer (dx, dy) within
//! `max_shift`, scored by the mean photo edge strength (|∇ ln Y|, [`edges::log_gradient`]) under
//! them; the best integer shift is refined to sub-pixel by a parabola through its neighbours'
//! scores on each axis. Only a translation: a rotation or a wrong focal length shows as a poor
//! `gain` and must be fixed in the calibration.

use crate::photo::{edges, Photo};
use crate::render::aov::IndexBuffers;

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
    let mut boundary = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let id = ib.object[i];
            // Both pixels of a step: the photo's edge response is symmetric about it.
            if x + 1 < w && ib.object[i + 1] != id {
                boundary.push((x, y));
                boundary.push((x + 1, y));
            }
            if y + 1 < h && ib.object[i + w as usize] != id {
                boundary.push((x, y));
                boundary.push((x, y + 1));
            }
        }
    }
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
    let mut best = (0i64, 0i64, f64::MIN);
    for dy in -m..=m {
        for dx in -m..=m {
            let s = score(dx, dy);
            // Ties go to the smaller shift.
            if s > best.2 + 1e-12 {
                best = (dx, dy, s);
            }
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
