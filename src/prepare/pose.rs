//! Pose refinement: the small rotation and translation of the camera (6 degrees of freedom)
//! that puts the model's edges where the photo has them.
//!
//! A translation on the film (`register::estimate_shift`) cannot follow a rotation about the
//! view axis nor a move of the camera, and its score — the mean photo gradient under the model's
//! edges — is biased by shading: beside a lit silhouette the object's radiance ramps, and the
//! ramp's gradient pulls the outline onto the object (a real capture with a right camera was
//! moved by a median 0.49 px, along the light). Here each model edge is located, along a pixel
//! row or column, by the same estimator in the photo and in a rendering of the model through the
//! current camera, and the pose is fitted to the *difference*: whatever the estimator makes of
//! the shading at an edge, it makes of the model's shading too, so a right camera measures zero.
//!
//! The estimator: on the scan line across a model edge, the luminance steps d_j = Y_{j+1} − Y_j
//! (located at the pixel boundary j + 1) of the edge's sign, each averaged with the same step on
//! the [`LINES`] lines either side; the run of them above a quarter of the peak (a tenth let in
//! enough noise to move a right camera by 0.2 px); their centroid Σ j d_j / Σ d_j. For a
//! box-filtered step from A to B at e, inside
//! pixel m = ⌊e⌋ (which reads A (e − m) + B (m + 1 − e)), that is e exactly: the only steps are
//! (B − A)(m + 1 − e) at m and (B − A)(e − m) at m + 1, whose centroid is e. Averaged over lines
//! along a straight edge it is the mean of their crossings, which is the middle line's. The
//! average is there for noise: a noisier side lets more of its steps over the quarter, which
//! pulls the centroid toward it by an amount that grows with the noise, and the photo's noise
//! is not the model rendering's.
//!
//! The fit: each edge point X (the foreground surface's point beside the edge) projects to
//! u(δ) under the pose x_cam = exp([ω]×)(R X + t) + τ, δ = (ω, τ). A row crossing moves by
//! (n · Δu) / n_x when the edge, of image normal n, moves by Δu. Gauss–Newton on
//! n_x (e_photo − e_model) = n · J δ, J = ∂u/∂δ by central differences of `Camera::project` (so
//! any lens model and the orthographic projection are covered), with Tukey's biweight on the
//! residuals (scale 1.4826 MAD), silhouettes weighted twice creases, a few renders at most.

use crate::math::{luminance_mean, Mat3, Vec2, Vec3};
use crate::photo::{ignore, Photo};
use crate::prepare::register;
use crate::render::aov::{index_buffers, IndexBuffers};
use crate::render::film::{render_where, RenderOptions};
use crate::scene::{Camera, Scene};

/// Half-width in pixels of the scan across a model edge in the photo.
const REACH: i64 = 4;
/// The same in the model's rendering, whose step lies within a pixel of its id boundary.
const MODEL_REACH: i64 = 1;
/// Lines on either side of an edge's scan line averaged into it (module comment).
const LINES: i64 = 2;
/// Samples per pixel of the model's renderings. Their noise is not the photo's, and the
/// estimator's noise bias cancels only as far as the two agree.
const SPP: u32 = 32;
/// At most this many Gauss–Newton steps (each renders the model once).
const STEPS: usize = 4;
/// Edge points used at most (evenly strided), to bound the cost on large photos.
const MAX_EDGES: usize = 6000;

/// A correction whose image motion is below this (RMS over the model's edge points, pixels) is
/// not applied: the right camera of a side-lit sphere measures 0.007 px, and a camera is better
/// left exactly as calibrated than moved by the estimate's noise.
pub const APPLY_PX: f32 = 0.1;

/// A film shift is applied from this many pixels on either axis: sub-pixel shifts are biased
/// by the shading near edges.
pub const SHIFT_APPLY_PX: f32 = 0.5;

/// What the refinement found.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Pose {
    /// The camera refined.
    #[serde(skip)]
    pub camera: Camera,
    /// The rotation from the given camera's orientation to the refined one, degrees.
    pub rotation_deg: f32,
    /// How far the camera centre moved, scene units (world coordinates).
    pub translation: Vec3,
    /// The model's edge points' image motion from the given camera to the refined one: mean
    /// (x, y) and root mean square length, pixels.
    pub mean_px: Vec2,
    pub rms_px: f32,
    /// Edge points in the last step's fit.
    pub edges: usize,
    /// Whether the photo pipeline applied it (an image motion of [`APPLY_PX`] or more).
    pub applied: bool,
    /// Whose materials shaded the model's renderings the edges were located in.
    pub shading: Shading,
    /// How it was found, which also sets the rule for applying it.
    pub method: Method,
    /// The refined camera's world-to-camera R (rows) and t, as `[camera]`'s calibrated form
    /// takes them.
    pub camera_rotation: [[f32; 3]; 3],
    pub camera_translation: [f32; 3],
}

/// The materials of the model the pose was refined against. The edge estimator's shading bias
/// cancels between photo and model only as far as their shading agrees, and placeholder
/// materials (a dark glossy floor rendered as matte grey) do not agree.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Shading {
    /// The scene file's (film-shift registration, or the first refinement).
    SceneFile,
    /// A quick fit of the materials through the first refinement's camera (`recover`).
    QuickFit,
}

/// How a [`Pose`] was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The 6-DoF refinement ([`refine`]), applied from [`APPLY_PX`] RMS on.
    Refinement,
    /// A shift of the film ([`from_shift`]), applied from [`SHIFT_APPLY_PX`] on either axis.
    FilmShift,
}

impl Pose {
    /// What the registration found, in one clause: the camera's turn and move, or the film's
    /// shift, and the model's edges' image motion.
    pub fn found(&self) -> String {
        match self.method {
            Method::Refinement => format!(
                "camera turned by {:.3}° and moved by {:.4} scene units: the model's edges move \
                 by ({:.2}, {:.2}) px, RMS {:.2} px",
                self.rotation_deg,
                self.translation.length(),
                self.mean_px.x,
                self.mean_px.y,
                self.rms_px
            ),
            Method::FilmShift => format!(
                "film shifted by ({:.2}, {:.2}) px",
                self.mean_px.x, self.mean_px.y
            ),
        }
    }

    /// Why a registration that was not applied was left out.
    pub fn not_applied_because(&self) -> String {
        match self.method {
            Method::Refinement => format!("below {APPLY_PX} px RMS, not applied"),
            Method::FilmShift => format!("below {SHIFT_APPLY_PX} px on both axes, not applied"),
        }
    }
}

/// One model edge crossed by a scan line.
struct Edge {
    /// The scan's axis (0: along a row, 1: along a column), the fixed pixel index across it,
    /// and the pixel boundary at which the model's ids step.
    axis: usize,
    line: i64,
    at: i64,
    /// The foreground surface's point beside the edge; the edge's unit image normal.
    p: Vec3,
    n: Vec2,
    weight: f64,
}

impl Edge {
    /// The row-major index, in a `w`-wide image, of pixel `k` along the scan on line `line`.
    fn pixel(&self, line: i64, k: i64, w: i64) -> i64 {
        if self.axis == 0 {
            line * w + k
        } else {
            k * w + line
        }
    }
}

/// The camera moved by δ = (ω, τ): x_cam ↦ exp([ω]×) x_cam + τ.
pub fn perturbed(cam: &Camera, d: [f64; 6]) -> Camera {
    let w = Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32);
    let rot = if w.length() > 0.0 {
        Mat3::from_axis_angle(w.normalize(), w.length())
    } else {
        Mat3::IDENTITY
    };
    Camera {
        r: rot * cam.r,
        t: rot * cam.t + Vec3::new(d[3] as f32, d[4] as f32, d[5] as f32),
        ..cam.clone()
    }
}

/// The film shift's search radius, in pixels, unless the user gives one.
pub const DEFAULT_SHIFT: i32 = 4;

/// The pose refinement's first search radius unless the user gives one: 2% of the image
/// diagonal, at least [`DEFAULT_SHIFT`]. Gauss–Newton from the shift it finds converges within
/// a few pixels; a camera turned by 1° moves a 512×384 image by about 10 px, beyond 4.
pub fn start_search(camera: &Camera) -> i32 {
    let diag = ((camera.width as f32).powi(2) + (camera.height as f32).powi(2)).sqrt();
    ((0.02 * diag).ceil() as i32).max(DEFAULT_SHIFT)
}

/// Refines `camera` against `photo` (module comment). `max_shift`: the film translation search
/// that starts it, in pixels (`register::estimate_shift`; only its whole pixels are taken).
pub fn refine(scene: &Scene, camera: &Camera, photo: &Photo, max_shift: i32) -> Pose {
    let ib = index_buffers(scene, camera);
    let coarse = register::estimate_shift(&ib, photo, max_shift);
    let (sx, sy) = (coarse.dx.round(), coarse.dy.round());
    let start = if sx != 0.0 || sy != 0.0 {
        shifted_by_pose(camera, sx, sy)
    } else {
        camera.clone()
    };
    refine_from(scene, camera, &start, photo, Shading::SceneFile)
}

/// Refines the pose from `start` (Gauss–Newton only, no search), reporting it relative to the
/// `given` camera. `shading`: whose materials `scene` holds.
pub fn refine_from(
    scene: &Scene,
    given: &Camera,
    start: &Camera,
    photo: &Photo,
    shading: Shading,
) -> Pose {
    let (w, h) = (given.width as i64, given.height as i64);
    let y_photo: Vec<f32> = photo
        .image
        .data
        .iter()
        .map(|&c| luminance_mean(c))
        .collect();
    let usable: Vec<bool> = {
        let near = ignore::near_ignored(photo, 1);
        (0..photo.valid.len())
            .map(|i| photo.valid[i] && !near[i])
            .collect()
    };
    let mut cam = start.clone();
    let mut edges_used = 0;
    let mut first_points: Vec<Vec3> = Vec::new();
    for step in 0..STEPS {
        let ib = index_buffers(scene, &cam);
        let edges = model_edges(scene, &cam, &ib);
        // Only the pixels the model's scans read are rendered: a few percent of the image.
        let model = render_where(
            scene,
            &cam,
            &RenderOptions {
                spp: SPP,
                seed: 0x5EED + step as u64,
                progress: false,
            },
            &model_scan_pixels(&edges, w, h),
        );
        let y_model: Vec<f32> = model.data.iter().map(|&c| luminance_mean(c)).collect();
        if first_points.is_empty() {
            first_points = edges.iter().map(|e| e.p).collect();
        }
        // Rows of the linear system: n · J δ = n_a (e_photo − e_model).
        let scale = depth_scale(&cam, &edges);
        let mut rows: Vec<([f64; 6], f64, f64)> = Vec::new();
        for e in &edges {
            let scan = |y: &[f32], ok: &dyn Fn(i64) -> bool, reach: i64, sign: f32| {
                centroid(y, w, h, e, reach, sign, ok)
            };
            let any = |_: i64| true;
            // The model's step sign and location, within a pixel of its id boundary.
            let Some((em, sign)) = scan(&y_model, &any, MODEL_REACH, 0.0) else {
                continue;
            };
            let ok = |i: i64| usable[i as usize];
            let Some((ep, _)) = scan(&y_photo, &ok, REACH, sign) else {
                continue;
            };
            let Some(j) = jacobian(&cam, e.p, scale) else {
                continue;
            };
            let na = e.n[e.axis] as f64;
            let a: [f64; 6] =
                std::array::from_fn(|k| e.n.x as f64 * j[k].x + e.n.y as f64 * j[k].y);
            rows.push((a, na * (ep - em) as f64, e.weight));
        }
        edges_used = rows.len();
        if rows.len() < 12 {
            break;
        }
        let Some(d) = robust_solve(&rows) else {
            break;
        };
        let d = [d[0], d[1], d[2], d[3] * scale, d[4] * scale, d[5] * scale];
        let next = perturbed(&cam, d);
        let moved = motion(&cam, &next, &first_points).1;
        cam = next;
        if moved < 0.01 {
            break;
        }
    }
    // The angle of the relative rotation: cos θ = (tr − 1)/2, sin θ = |axial vector of the
    // antisymmetric part| (atan2 of both keeps small angles, which acos rounds to zero).
    let rel = cam.r * given.r.transpose();
    let axial = Vec3::new(
        rel.y_axis.z - rel.z_axis.y,
        rel.z_axis.x - rel.x_axis.z,
        rel.x_axis.y - rel.y_axis.x,
    );
    let angle =
        (0.5 * axial.length()).atan2(0.5 * (rel.x_axis.x + rel.y_axis.y + rel.z_axis.z - 1.0));
    let (mean_px, rms_px) = motion(given, &cam, &first_points);
    Pose {
        rotation_deg: angle.to_degrees(),
        translation: cam.eye() - given.eye(),
        camera_rotation: [cam.r.row(0), cam.r.row(1), cam.r.row(2)].map(|v| v.to_array()),
        camera_translation: cam.t.to_array(),
        camera: cam,
        mean_px,
        rms_px,
        edges: edges_used,
        applied: rms_px >= APPLY_PX,
        shading,
        method: Method::Refinement,
    }
}

/// The film-shift registration (`register::estimate_shift`) as a [`Pose`]: the default while
/// the 6-DoF refinement still moves correct cameras on figure6 at full size. Applied as a shift
/// of the principal point from [`SHIFT_APPLY_PX`] on.
pub fn from_shift(camera: &Camera, index: &IndexBuffers, photo: &Photo, max_shift: i32) -> Pose {
    let r = register::estimate_shift(index, photo, max_shift);
    let applied = r.dx.abs().max(r.dy.abs()) >= SHIFT_APPLY_PX;
    let cam = if applied {
        camera.shifted(r.dx, r.dy)
    } else {
        camera.clone()
    };
    Pose {
        rotation_deg: 0.0,
        translation: Vec3::ZERO,
        camera_rotation: [cam.r.row(0), cam.r.row(1), cam.r.row(2)].map(|v| v.to_array()),
        camera_translation: cam.t.to_array(),
        camera: cam,
        mean_px: Vec2::new(r.dx, r.dy),
        rms_px: Vec2::new(r.dx, r.dy).length(),
        edges: register::model_edges(index).len(),
        applied,
        shading: Shading::SceneFile,
        method: Method::FilmShift,
    }
}

/// The pose change that moves the image centre by (dx, dy) pixels: a rotation about the
/// camera's y and x axes by atan(dx / fx) and −atan(dy / fy) for a pinhole (a point on the axis,
/// rotated by θ about y, lands at fx tan θ); a sideways move by (dx / fx, dy / fy) units for
/// parallel rays.
fn shifted_by_pose(cam: &Camera, dx: f32, dy: f32) -> Camera {
    let d = if cam.is_orthographic() {
        [
            0.0,
            0.0,
            0.0,
            (dx / cam.fx) as f64,
            (dy / cam.fy) as f64,
            0.0,
        ]
    } else {
        [
            -(dy / cam.fy).atan() as f64,
            (dx / cam.fx).atan() as f64,
            0.0,
            0.0,
            0.0,
            0.0,
        ]
    };
    perturbed(cam, d)
}

/// Mean (x, y) and RMS length of the image motion of `points` from camera `a` to `b`.
pub fn motion(a: &Camera, b: &Camera, points: &[Vec3]) -> (Vec2, f32) {
    let (mut sum, mut sq, mut n) = (Vec2::ZERO, 0.0f64, 0usize);
    for &p in points {
        if let (Some(u), Some(v)) = (a.project(p), b.project(p)) {
            sum += v - u;
            sq += (v - u).length_squared() as f64;
            n += 1;
        }
    }
    if n == 0 {
        return (Vec2::ZERO, 0.0);
    }
    (sum / n as f32, (sq / n as f64).sqrt() as f32)
}

/// RMS image motion from camera `a` to `b` of the scene points seen through a 16×12 grid of
/// `a`'s pixels: how far apart two poses of one photo are, in pixels.
pub fn view_motion(scene: &Scene, a: &Camera, b: &Camera) -> f32 {
    let through_a = Scene {
        camera: a.clone(),
        ..scene.clone()
    };
    let points: Vec<Vec3> = through_a
        .camera_grid_hits(16, 12)
        .into_iter()
        .map(|(_, _, h)| h.p)
        .collect();
    motion(a, b, &points).1
}

/// A length that makes translations comparable with rotations: the median depth of the edge
/// points (orthographic: the film's width).
fn depth_scale(cam: &Camera, edges: &[Edge]) -> f64 {
    if let Some(s) = cam.film_size_m() {
        return s.x as f64;
    }
    let mut z: Vec<f32> = edges.iter().map(|e| (cam.r * e.p + cam.t).z).collect();
    crate::photo::robust::median(&mut z).map_or(1.0, |m| m.max(1e-6) as f64)
}

/// ∂u/∂δ at `p`, δ = (ω, τ / scale), by central differences of `Camera::project`.
fn jacobian(cam: &Camera, p: Vec3, scale: f64) -> Option<[glam::DVec2; 6]> {
    let h = 1e-4;
    let mut j = [glam::DVec2::ZERO; 6];
    for (k, jk) in j.iter_mut().enumerate() {
        let mut d = [0.0; 6];
        d[k] = if k < 3 { h } else { h * scale };
        let a = perturbed(cam, d).project(p)?;
        d[k] = -d[k];
        let b = perturbed(cam, d).project(p)?;
        *jk = (a - b).as_dvec2() / (2.0 * h);
    }
    Some(j)
}

/// The sub-pixel location of the step of sign `sign` (0: the strongest, either sign) on `e`'s
/// scan line within `reach` pixels of its model boundary: the centroid of the run of steps
/// above a quarter of the peak (module comment; an edge crossing less than a fifth of a pixel
/// is placed at the pixel boundary, in photo and model alike), and the sign. None where a pixel it reads is
/// not `ok` or there is no step of that sign.
fn centroid(
    y: &[f32],
    w: i64,
    h: i64,
    e: &Edge,
    reach: i64,
    sign: f32,
    ok: &dyn Fn(i64) -> bool,
) -> Option<(f32, f32)> {
    let (len, across) = if e.axis == 0 { (w, h) } else { (h, w) };
    let (lo, hi) = (e.at - reach, e.at + reach);
    if lo < 1 || hi >= len {
        return None;
    }
    let lines: Vec<i64> = (e.line - LINES..=e.line + LINES)
        .filter(|&l| (0..across).contains(&l))
        .collect();
    // Steps d at boundaries lo..=hi: d(b) = Y[b] − Y[b − 1], averaged over the lines.
    let mut d = Vec::with_capacity((hi - lo + 1) as usize);
    for b in lo..=hi {
        let mut sum = 0.0f32;
        for &l in &lines {
            let (i0, i1) = (e.pixel(l, b - 1, w), e.pixel(l, b, w));
            if !ok(i0) || !ok(i1) {
                return None;
            }
            sum += y[i1 as usize] - y[i0 as usize];
        }
        d.push(sum / lines.len() as f32);
    }
    let sign = if sign != 0.0 {
        sign
    } else {
        // The step at the model's id boundary, or, where that is flat (the edge crosses a pixel
        // beside it), the stronger beside it.
        let c = reach as usize;
        let mid = match d[c] {
            0.0 => d[c - 1..=c + 1]
                .iter()
                .copied()
                .max_by(|a, b| a.abs().total_cmp(&b.abs()))?,
            v => v,
        };
        if mid == 0.0 {
            return None;
        }
        mid.signum()
    };
    let s: Vec<f32> = d.iter().map(|v| v * sign).collect();
    let peak = s.iter().copied().fold(0.0f32, f32::max);
    if !(peak > 0.0) {
        return None;
    }
    // The local maximum above half the peak nearest the model's boundary: a neighbouring edge
    // of the same sign further out is not this one.
    let centre = reach as usize;
    let k = (0..s.len())
        .filter(|&k| {
            s[k] >= 0.5 * peak
                && (k == 0 || s[k] >= s[k - 1])
                && (k + 1 == s.len() || s[k] >= s[k + 1])
        })
        .min_by_key(|&k| k.abs_diff(centre))?;
    let floor = 0.25 * s[k];
    let (mut a, mut b) = (k, k);
    while a > 0 && s[a - 1] >= floor {
        a -= 1;
    }
    while b + 1 < s.len() && s[b + 1] >= floor {
        b += 1;
    }
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (k, &v) in s.iter().enumerate().take(b + 1).skip(a) {
        num += (lo + k as i64) as f64 * v as f64;
        den += v as f64;
    }
    Some(((num / den) as f32, sign))
}

/// The pixels [`centroid`] reads of the model's rendering (reach [`MODEL_REACH`]) for `edges`,
/// marked in a `w`×`h` mask: the steps at boundaries at ± reach read pixels at − reach − 1 to
/// at + reach, on the [`LINES`] lines either side.
fn model_scan_pixels(edges: &[Edge], w: i64, h: i64) -> Vec<bool> {
    let mut marks = vec![false; (w * h) as usize];
    for e in edges {
        let (len, across) = if e.axis == 0 { (w, h) } else { (h, w) };
        for line in (e.line - LINES).max(0)..=(e.line + LINES).min(across - 1) {
            for k in (e.at - MODEL_REACH - 1).max(0)..=(e.at + MODEL_REACH).min(len - 1) {
                marks[e.pixel(line, k, w) as usize] = true;
            }
        }
    }
    marks
}

/// The model's edges crossed by rows and columns: id boundaries (silhouettes, weight 2) and
/// creases (`register::CREASE_DEG`, weight 1), each scanned along the axis nearer its normal.
fn model_edges(scene: &Scene, cam: &Camera, ib: &IndexBuffers) -> Vec<Edge> {
    let (w, h) = (ib.width as i64, ib.height as i64);
    let cos_crease = register::CREASE_DEG.to_radians().cos();
    let same = |i: usize, j: usize| {
        ib.object[i] == ib.object[j]
            && (ib.object[i] < 0 || ib.normal[i].dot(ib.normal[j]) >= cos_crease)
    };
    let depth = |x: i64, y: i64| {
        let ray = cam.ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
        scene.intersect(&ray, f32::INFINITY).map(|s| (s.t, s.p))
    };
    let mut out = Vec::new();
    for axis in 0..2 {
        let (len, lines) = if axis == 0 { (w, h) } else { (h, w) };
        for line in 1..lines - 1 {
            for b in 1..len {
                let at = |k: i64, l: i64| {
                    if axis == 0 {
                        (l * w + k) as usize
                    } else {
                        (k * w + l) as usize
                    }
                };
                let (i0, i1) = (at(b - 1, line), at(b, line));
                if same(i0, i1) {
                    continue;
                }
                // The edge's normal from the 2×3 neighbourhood: how the region of pixel i0
                // changes across and along the scan.
                let mut g = [0.0f32; 2];
                for (dl, wt) in [(-1i64, 1.0f32), (0, 2.0), (1, 1.0)] {
                    let (j0, j1) = (at(b - 1, line + dl), at(b, line + dl));
                    g[0] += wt
                        * (f32::from(u8::from(!same(i0, j1))) - f32::from(u8::from(!same(i0, j0))));
                }
                for k in [b - 1, b] {
                    let (a0, a1) = (at(k, line - 1), at(k, line + 1));
                    g[1] += 2.0
                        * (f32::from(u8::from(!same(i0, a1))) - f32::from(u8::from(!same(i0, a0))));
                }
                let (across, along) = (g[0], g[1]);
                let n_len = (across * across + along * along).sqrt();
                if n_len == 0.0 || across.abs() < 0.5 * n_len {
                    continue; // nearer the other axis: scanned there
                }
                let n = if axis == 0 {
                    Vec2::new(across, along) / n_len
                } else {
                    Vec2::new(along, across) / n_len
                };
                let (x0, y0) = if axis == 0 {
                    (b - 1, line)
                } else {
                    (line, b - 1)
                };
                let (x1, y1) = if axis == 0 { (b, line) } else { (line, b) };
                let p = match (depth(x0, y0), depth(x1, y1)) {
                    (Some((t0, p0)), Some((t1, p1))) => {
                        if t0 <= t1 {
                            p0
                        } else {
                            p1
                        }
                    }
                    (Some((_, p)), None) | (None, Some((_, p))) => p,
                    (None, None) => continue,
                };
                let silhouette = ib.object[i0] != ib.object[i1];
                out.push(Edge {
                    axis,
                    line,
                    at: b,
                    p,
                    n,
                    weight: if silhouette { 2.0 } else { 1.0 },
                });
            }
        }
    }
    let stride = out.len().div_ceil(MAX_EDGES).max(1);
    out.into_iter().step_by(stride).collect()
}

/// The ridge on the normal equations, relative to their largest diagonal term. Some pose changes
/// barely move the image — a turn about the vertical against a sideways move, for edges at
/// similar depths; an orthographic camera's depth not at all — and noise would send the fit
/// along them; the ridge keeps every change that moves the image by less than √RIDGE of what
/// the strongest parameter does per unit at zero, and shrinks the others by ~RIDGE per step.
const RIDGE: f64 = 0.01;

/// Weighted least squares with Tukey's biweight (c = 4.685 σ, σ = 1.4826 MAD, at least 0.05
/// px), iterated, with the [`RIDGE`].
fn robust_solve(rows: &[([f64; 6], f64, f64)]) -> Option<[f64; 6]> {
    let mut wts: Vec<f64> = rows.iter().map(|r| r.2).collect();
    let mut x = [0.0; 6];
    for _ in 0..6 {
        let mut m = [[0.0f64; 6]; 6];
        let mut v = [0.0f64; 6];
        for ((a, b, _), &wt) in rows.iter().zip(&wts) {
            for i in 0..6 {
                v[i] += wt * a[i] * b;
                for j in 0..6 {
                    m[i][j] += wt * a[i] * a[j];
                }
            }
        }
        let top = (0..6).map(|i| m[i][i]).fold(0.0, f64::max);
        for (i, row) in m.iter_mut().enumerate() {
            row[i] += RIDGE * top + 1e-300;
        }
        x = solve6(m, v)?;
        let mut res: Vec<f32> = rows
            .iter()
            .map(|(a, b, _)| (b - (0..6).map(|k| a[k] * x[k]).sum::<f64>()).abs() as f32)
            .collect();
        let sigma = (1.4826 * crate::photo::robust::median(&mut res.clone())? as f64).max(0.05);
        let c = 4.685 * sigma;
        for ((r, wt), row) in res.iter_mut().zip(wts.iter_mut()).zip(rows) {
            let u = *r as f64 / c;
            *wt = row.2 * if u < 1.0 { (1.0 - u * u).powi(2) } else { 0.0 };
        }
    }
    Some(x)
}

/// Solves the 6×6 system by Gaussian elimination with partial pivoting.
fn solve6(mut m: [[f64; 6]; 6], mut v: [f64; 6]) -> Option<[f64; 6]> {
    for c in 0..6 {
        let p = (c..6).max_by(|&a, &b| m[a][c].abs().total_cmp(&m[b][c].abs()))?;
        if m[p][c].abs() < 1e-300 {
            return None;
        }
        m.swap(c, p);
        v.swap(c, p);
        for r in c + 1..6 {
            let f = m[r][c] / m[c][c];
            for k in c..6 {
                m[r][k] -= f * m[c][k];
            }
            v[r] -= f * v[c];
        }
    }
    let mut x = [0.0; 6];
    for r in (0..6).rev() {
        let s: f64 = (r + 1..6).map(|k| m[r][k] * x[k]).sum();
        x[r] = (v[r] - s) / m[r][r];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row crossing a box-filtered step from A to B at e, with a shading ramp of slope s per
    /// pixel on B's side (a lit limb): the centroid finds e exactly without the ramp, and the
    /// ramp moves it by the same amount in the photo and in the model's rendering, so their
    /// difference is the edges' true offset.
    #[test]
    fn the_centroid_of_the_steps_is_the_edge_and_a_ramp_cancels() {
        let w = 16i64;
        let row = |e: f32, ramp: f32| -> Vec<f32> {
            (0..w)
                .map(|k| {
                    let (a, b) = (0.05, 1.0 + ramp * (k as f32 + 0.5 - e));
                    let k = k as f32;
                    let cover = (e - k).clamp(0.0, 1.0); // of A, left of e
                    a * cover + b * (1.0 - cover)
                })
                .collect()
        };
        let edge = |at: i64| Edge {
            axis: 0,
            line: 0,
            at,
            p: Vec3::ZERO,
            n: Vec2::X,
            weight: 1.0,
        };
        let all = |_: i64| true;
        for e in [7.0f32, 7.3, 7.5, 7.7] {
            let (c, sign) = centroid(&row(e, 0.0), w, 1, &edge(8), REACH, 0.0, &all).unwrap();
            assert_eq!(sign, 1.0);
            assert!((c - e).abs() < 1e-5, "{c} vs {e}");
        }
        // With a ramp of 8% per pixel the centroid is off, by the same at any sub-pixel offset
        // of the same phase: photo (e + 1) minus model (e) is 1.
        let (model, _) = centroid(&row(7.3, -0.08), w, 1, &edge(8), REACH, 0.0, &all).unwrap();
        let (photo, _) = centroid(&row(8.3, -0.08), w, 1, &edge(8), REACH, 1.0, &all).unwrap();
        assert!((model - 7.3).abs() > 1e-3, "the ramp biases each: {model}");
        assert!((photo - model - 1.0).abs() < 1e-4, "{photo} − {model}");
    }
}
