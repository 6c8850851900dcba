//! Pinhole cameras, given either by look-at + vertical field of view or by calibrated intrinsics
//! and extrinsics in the OpenCV convention, and converted to one model:
//!
//!   x_cam = R x_world + t            (camera x right, y down, z forward: OpenCV)
//!   u = fx x_cam / z_cam + cx,  v = fy y_cam / z_cam + cy
//!
//! Or orthographic cameras (`Projection::Orthographic`), the same without the perspective
//! divide: u = fx x_cam + cx, v = fy y_cam + cy, fx and fy in pixels per scene unit (the affine
//! camera of Hartley & Zisserman, "Multiple View Geometry", 2nd ed., §6.3.1, with its image
//! plane at z_cam = 0). Every primary ray travels along the camera's z from its film point on
//! that plane, so the "eye" −Rᵀ t is the film's centre for cx, cy at the image centre, and
//! points with z_cam < 0, behind the film plane where the rays start, are not seen.
//!
//! In OpenCV's convention integer (u, v) are pixel *centres*. Internally matfit uses continuous
//! film coordinates in which pixel (i, j) covers [i, i+1) × [j, j+1) (its centre at i + ½, as
//! Mitsuba and pbrt do), so `cx_film = cx_opencv + ½`. A look-at camera is centred:
//! cx_opencv = (width − 1)/2, fy = (height/2) / tan(fov_y/2), fx = fy (square pixels).
//!
//! Lens distortion, optional, is OpenCV's standard (Brown–Conrady) model on the normalised
//! coordinates (x, y) = (x_cam / z_cam, y_cam / z_cam), with r² = x² + y²:
//!
//!   x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2x²)
//!   y_d = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2y²) + 2 p2 x y
//!
//! and u = fx x_d + cx (OpenCV's `projectPoints`). `project` applies it; a primary ray inverts
//! it by the fixed-point iteration of OpenCV's `undistortPoints`, run to convergence, so that
//! the rendered image and the index buffers are the distorted photo's.
//!
//! Or OpenCV's fisheye model (`cv::fisheye`, Kannala–Brandt): with θ = atan r the angle off the
//! axis, θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸) and (x_d, y_d) = (θ_d / r) (x, y); a ray
//! inverts θ_d → θ by Newton's method, as `cv::fisheye::undistortPoints` does.

use crate::geometry::Ray;
use crate::math::{Mat3, Vec2, Vec3};
use wide::f32x8;

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    /// Principal point in continuous film coordinates (see the module comment).
    pub cx: f32,
    pub cy: f32,
    /// World-to-camera rotation (rows: right, down, forward in world coordinates).
    pub r: Mat3,
    /// World-to-camera translation.
    pub t: Vec3,
    /// The lens's distortion, if any (module comment); always None for an orthographic camera.
    pub distortion: Option<Lens>,
    pub projection: Projection,
}

/// How camera coordinates reach the film (module comment).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Projection {
    /// A pinhole at the camera centre: u = fx x/z + cx.
    #[default]
    Perspective,
    /// Parallel rays along the camera's z: u = fx x + cx, fx in pixels per scene unit.
    Orthographic,
}

/// OpenCV's two distortion models.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lens {
    /// (k1, k2, p1, p2, k3): `cv::projectPoints`.
    Brown([f32; 5]),
    /// (k1, k2, k3, k4): `cv::fisheye::projectPoints`.
    Fisheye([f32; 4]),
}

impl Lens {
    /// Distorted normalised coordinates of undistorted (x, y).
    fn distort(&self, x: f32, y: f32) -> (f32, f32) {
        match self {
            Lens::Brown(k) => distort(k, x, y),
            Lens::Fisheye(k) => {
                let r = (x * x + y * y).sqrt();
                if r == 0.0 {
                    return (x, y);
                }
                let t = r.atan();
                let s = fisheye_theta_d(k, t) / r;
                (x * s, y * s)
            }
        }
    }

    /// The camera-frame direction (not normalised) whose image is distorted (xd, yd).
    fn undistort(&self, xd: f32, yd: f32) -> Vec3 {
        match self {
            Lens::Brown(k) => {
                let (x, y) = undistort(k, xd, yd);
                Vec3::new(x, y, 1.0)
            }
            Lens::Fisheye(k) => {
                let rd = (xd * xd + yd * yd).sqrt();
                if rd == 0.0 {
                    return Vec3::Z;
                }
                // Newton on θ_d(θ) = rd from θ = rd.
                let mut t = rd;
                for _ in 0..20 {
                    let (t2, [k1, k2, k3, k4]) = (t * t, *k);
                    let f = fisheye_theta_d(k, t) - rd;
                    let df =
                        1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)));
                    let step = f / df;
                    t -= step;
                    if step.abs() < 1e-7 {
                        break;
                    }
                }
                let s = t.sin() / rd;
                Vec3::new(xd * s, yd * s, t.cos())
            }
        }
    }
}

/// θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸).
fn fisheye_theta_d(k: &[f32; 4], t: f32) -> f32 {
    let t2 = t * t;
    t * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))
}

impl Camera {
    /// A camera at `eye` looking at `target`, `up` roughly up, vertical field of view in degrees.
    /// Returns None if the view direction is zero or parallel to `up`, or the fov is not in (0, 180).
    pub fn look_at(
        width: u32,
        height: u32,
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        fov_y_deg: f32,
    ) -> Option<Camera> {
        if !(fov_y_deg > 0.0 && fov_y_deg < 180.0) {
            return None;
        }
        let fy = 0.5 * height as f32 / (0.5 * fov_y_deg.to_radians()).tan();
        Self::centred(width, height, eye, target, up, fy, Projection::Perspective)
    }

    /// An orthographic camera whose film plane is centred on `eye`, looking towards `target`,
    /// its film `width_m` scene units wide (square pixels: as tall as the aspect makes it).
    /// Returns None if the view direction is zero or parallel to `up`, or the width is not > 0.
    pub fn orthographic_look_at(
        width: u32,
        height: u32,
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        width_m: f32,
    ) -> Option<Camera> {
        if !(width_m > 0.0 && width_m.is_finite()) {
            return None;
        }
        let f = width as f32 / width_m;
        Self::centred(width, height, eye, target, up, f, Projection::Orthographic)
    }

    /// A camera at `eye` looking at `target` with square pixels, `f` = fx = fy, and the
    /// principal point at the film's centre.
    fn centred(
        width: u32,
        height: u32,
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        f: f32,
        projection: Projection,
    ) -> Option<Camera> {
        let fwd = (target - eye).normalize_or_zero();
        let right = fwd.cross(up).normalize_or_zero();
        if fwd == Vec3::ZERO || right == Vec3::ZERO {
            return None;
        }
        let down = fwd.cross(right);
        let r = Mat3::from_cols(right, down, fwd).transpose();
        Some(Camera {
            width,
            height,
            fx: f,
            fy: f,
            cx: 0.5 * width as f32,
            cy: 0.5 * height as f32,
            r,
            t: -(r * eye),
            distortion: None,
            projection,
        })
    }

    /// A calibrated camera: OpenCV intrinsics (pixel centres at integers) and world-to-camera
    /// R | t. Returns None if R is not a rotation (orthonormal, det +1, within 1e-3).
    pub fn calibrated(
        width: u32,
        height: u32,
        fx: f32,
        fy: f32,
        cx: f32,
        cy: f32,
        r: Mat3,
        t: Vec3,
    ) -> Option<Camera> {
        let should_be_identity = r * r.transpose();
        let err = (should_be_identity - Mat3::IDENTITY)
            .to_cols_array()
            .iter()
            .fold(0.0f32, |m, x| m.max(x.abs()));
        if err > 1e-3 || (r.determinant() - 1.0).abs() > 1e-3 || !(fx > 0.0 && fy > 0.0) {
            return None;
        }
        Some(Camera {
            width,
            height,
            fx,
            fy,
            cx: cx + 0.5,
            cy: cy + 0.5,
            r,
            t,
            distortion: None,
            projection: Projection::Perspective,
        })
    }

    /// The same camera, orthographic: fx and fy are then pixels per scene unit.
    pub fn orthographic(self) -> Camera {
        Camera {
            projection: Projection::Orthographic,
            distortion: None,
            ..self
        }
    }

    pub fn is_orthographic(&self) -> bool {
        self.projection == Projection::Orthographic
    }

    /// Camera centre in world coordinates: −Rᵀ t. For an orthographic camera, the point of
    /// the film plane whose ray projects to (cx, cy); the rays of other pixels start beside it.
    pub fn eye(&self) -> Vec3 {
        -(self.r.transpose() * self.t)
    }

    /// The primary ray through continuous film position (x, y); direction normalised.
    pub fn ray(&self, film: Vec2) -> Ray {
        let (x, y) = ((film.x - self.cx) / self.fx, (film.y - self.cy) / self.fy);
        if self.is_orthographic() {
            let m = self.r.transpose();
            return Ray::new(self.eye() + m * Vec3::new(x, y, 0.0), m.z_axis.normalize());
        }
        let d_cam = match &self.distortion {
            None => Vec3::new(x, y, 1.0),
            Some(lens) => lens.undistort(x, y),
        };
        Ray::new(self.eye(), (self.r.transpose() * d_cam).normalize())
    }

    /// The directions of [`Camera::ray`] through eight film positions (x[i], y[i]) at once,
    /// the same to the bit: the same operations in the same order on eight lanes (glam's
    /// `Mat3 * Vec3` is x_axis·x + y_axis·y + z_axis·z; `normalize` multiplies by
    /// 1 / √(x² + y² + z²)).
    pub fn directions8(&self, x: f32x8, y: f32x8) -> [f32x8; 3] {
        if self.is_orthographic() {
            let d = self.r.transpose().z_axis.normalize();
            return [d.x, d.y, d.z].map(f32x8::splat);
        }
        if self.distortion.is_some() {
            // Lane by lane through `ray`: the undistortion iterates.
            let (x, y) = (x.to_array(), y.to_array());
            let d: [Vec3; 8] = std::array::from_fn(|i| self.ray(Vec2::new(x[i], y[i])).d);
            return std::array::from_fn(|k| f32x8::from(d.map(|v| v[k])));
        }
        let m = self.r.transpose();
        let dx = (x - f32x8::splat(self.cx)) / f32x8::splat(self.fx);
        let dy = (y - f32x8::splat(self.cy)) / f32x8::splat(self.fy);
        let (a, b, c) = (
            m.x_axis.to_array(),
            m.y_axis.to_array(),
            m.z_axis.to_array(),
        );
        let d: [f32x8; 3] = std::array::from_fn(|k| {
            f32x8::splat(a[k]) * dx + f32x8::splat(b[k]) * dy + f32x8::splat(c[k]) * f32x8::ONE
        });
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let recip = f32x8::ONE / len;
        d.map(|c| c * recip)
    }

    /// Continuous film position of a world point, or None if it is behind the camera (for an
    /// orthographic camera: behind its film plane, z_cam < 0).
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        let c = self.r * p + self.t;
        if self.is_orthographic() {
            return (c.z >= 0.0)
                .then(|| Vec2::new(self.fx * c.x + self.cx, self.fy * c.y + self.cy));
        }
        if c.z <= 0.0 {
            return None;
        }
        let (x, y) = (c.x / c.z, c.y / c.z);
        let (x, y) = match &self.distortion {
            None => (x, y),
            Some(lens) => lens.distort(x, y),
        };
        Some(Vec2::new(self.fx * x + self.cx, self.fy * y + self.cy))
    }

    /// The same camera shifted by (dx, dy) pixels on the film: a misregistered model, for tests.
    /// (An orthographic camera's rays move sideways by (dx / fx, dy / fy) scene units.)
    pub fn shifted(&self, dx: f32, dy: f32) -> Camera {
        Camera {
            cx: self.cx + dx,
            cy: self.cy + dy,
            ..self.clone()
        }
    }

    /// Vertical field of view in degrees; None for an orthographic camera, which has none.
    pub fn fov_y_deg(&self) -> Option<f32> {
        (!self.is_orthographic())
            .then(|| (2.0 * (0.5 * self.height as f32 / self.fy).atan()).to_degrees())
    }

    /// An orthographic camera's film size in scene units (width, height); None for a pinhole.
    pub fn film_size_m(&self) -> Option<Vec2> {
        self.is_orthographic()
            .then(|| Vec2::new(self.width as f32 / self.fx, self.height as f32 / self.fy))
    }
}

/// OpenCV's distortion of normalised coordinates (module comment).
fn distort(k: &[f32; 5], x: f32, y: f32) -> (f32, f32) {
    let [k1, k2, p1, p2, k3] = *k;
    let r2 = x * x + y * y;
    let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    (
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    )
}

/// The normalised coordinates that `distort` takes to (xd, yd): OpenCV's fixed-point
/// iteration x ← (x_d − tangential(x)) / radial(x), until it moves less than 1e-7 (at most 50
/// steps; strong distortion near the image corners converges slowest).
fn undistort(k: &[f32; 5], xd: f32, yd: f32) -> (f32, f32) {
    let [k1, k2, p1, p2, k3] = *k;
    let (mut x, mut y) = (xd, yd);
    for _ in 0..50 {
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        let (nx, ny) = ((xd - dx) / radial, (yd - dy) / radial);
        let moved = (nx - x).abs().max((ny - y).abs());
        (x, y) = (nx, ny);
        if moved < 1e-7 {
            break;
        }
    }
    (x, y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distortion_follows_opencv_and_rays_invert_it() {
        // A calibration of the size a phone or DSLR lens gives (barrel, slight decentring).
        let r = Mat3::IDENTITY;
        let mut cam =
            Camera::calibrated(640, 480, 500.0, 505.0, 321.0, 238.0, r, Vec3::ZERO).unwrap();
        cam.distortion = Some(Lens::Brown([-0.28, 0.09, 0.0012, -0.0008, -0.012]));
        // A point at normalised (0.4, −0.3): r² = 0.25, radial = 1 − 0.07 + 0.005625 −
        // 0.0001875 = 0.9354375; x_d = 0.374175 + 2·0.0012·0.4·(−0.3) − 0.0008·(0.25 + 0.32)
        // = 0.373431, y_d = −0.28063125 + 0.0012·(0.25 + 0.18) + 2·(−0.0008)·0.4·(−0.3)
        // = −0.279923 (worked by hand from OpenCV's documented model).
        let p = cam.project(Vec3::new(0.4, -0.3, 1.0)).unwrap();
        assert!((p.x - (500.0 * 0.373431 + 321.5)).abs() < 1e-3, "{p}");
        assert!((p.y - (505.0 * -0.279923 + 238.5)).abs() < 1e-3, "{p}");
        // Every pixel's ray projects back onto the pixel.
        for j in (0..=480).step_by(40) {
            for i in (0..=640).step_by(40) {
                let film = Vec2::new(i as f32, j as f32);
                let ray = cam.ray(film);
                let back = cam.project(ray.o + ray.d * 3.0).unwrap();
                assert!((back - film).length() < 2e-3, "{film} → {back}");
            }
        }
        // The same for a fisheye lens (a 150° field of view; OpenCV's fisheye model), whose
        // θ_d at θ = 0.5: 0.5 (1 + 0.03·0.25 − 0.01·0.0625 + 0 + 0.001·0.00390625) = 0.5034394.
        let mut fish = cam.clone();
        fish.fx = 300.0;
        fish.fy = 300.0;
        let k = [0.03, -0.01, 0.0, 0.001];
        fish.distortion = Some(Lens::Fisheye(k));
        let p = fish.project(Vec3::new(0.5f32.tan(), 0.0, 1.0)).unwrap();
        assert!((p.x - (300.0 * 0.5034394 + 321.5)).abs() < 1e-3, "{p}");
        for j in (0..=480).step_by(40) {
            for i in (0..=640).step_by(40) {
                let film = Vec2::new(i as f32, j as f32);
                let ray = fish.ray(film);
                let back = fish.project(ray.o + ray.d * 3.0).unwrap();
                assert!((back - film).length() < 2e-3, "{film} → {back}");
            }
        }
        // The eight-lane directions are the rays' to the bit.
        let xs = f32x8::from([0.5, 100.0, 639.5, 320.0, 1.0, 200.25, 600.0, 7.0]);
        let ys = f32x8::from([0.5, 50.0, 479.5, 240.0, 470.0, 10.75, 300.0, 400.0]);
        let d = cam.directions8(xs, ys);
        for i in 0..8 {
            let r = cam.ray(Vec2::new(xs.to_array()[i], ys.to_array()[i]));
            assert_eq!(
                [d[0].to_array()[i], d[1].to_array()[i], d[2].to_array()[i]],
                r.d.to_array()
            );
        }
    }

    #[test]
    fn look_at_projects_known_points_analytically() {
        // Camera at the origin looking down −z, 90° vertical fov on a 200×100 film:
        // fy = 50 px per unit of y/z; the point (0.5, 0.25, −1) is 0.5·50 = 25 px right of centre
        // and 0.25·50 = 12.5 px above it.
        let cam = Camera::look_at(200, 100, Vec3::ZERO, -Vec3::Z, Vec3::Y, 90.0).unwrap();
        let p = cam.project(Vec3::new(0.5, 0.25, -1.0)).unwrap();
        assert!(
            (p - Vec2::new(100.0 + 25.0, 50.0 - 12.5)).length() < 1e-4,
            "{p}"
        );
        assert!(cam.project(Vec3::new(0.0, 0.0, 1.0)).is_none());
        // The ray through a film position passes through the point that projects there.
        let r = cam.ray(p);
        let q = r.o + r.d * (Vec3::new(0.5, 0.25, -1.0).length());
        assert!((q - Vec3::new(0.5, 0.25, -1.0)).length() < 1e-4);
    }

    #[test]
    fn calibrated_and_look_at_forms_agree() {
        let eye = Vec3::new(1.0, 2.0, 5.0);
        let la = Camera::look_at(640, 480, eye, Vec3::new(0.0, 1.0, 0.0), Vec3::Y, 50.0).unwrap();
        // The same camera written as OpenCV intrinsics (integer pixel centres) and R | t.
        let cal =
            Camera::calibrated(640, 480, la.fx, la.fy, 319.5, 239.5, la.r, -(la.r * eye)).unwrap();
        for p in [
            Vec3::new(0.3, 0.1, -0.4),
            Vec3::new(-1.0, 2.0, 1.0),
            Vec3::new(2.0, 0.0, 0.0),
        ] {
            let a = la.project(p).unwrap();
            let b = cal.project(p).unwrap();
            assert!((a - b).length() < 1e-3, "{a} vs {b}");
        }
        // An OpenCV projection by hand: u = fx X/Z + cx with pixel centres at integers.
        let p = Vec3::new(0.3, 0.1, -0.4);
        let c = la.r * p + la.t;
        let u_cv = la.fx * c.x / c.z + 319.5;
        assert!((cal.project(p).unwrap().x - (u_cv + 0.5)).abs() < 1e-3);
    }

    #[test]
    fn eight_directions_at_once_are_those_of_ray_to_the_bit() {
        let cam = Camera::look_at(
            256,
            192,
            Vec3::new(0.0, 1.6, -0.2),
            Vec3::new(0.3, 1.2, -1.1),
            Vec3::Y,
            40.0,
        )
        .unwrap();
        let mut rng = crate::math::sampler::TestRng(4);
        for _ in 0..200 {
            let x: [f32; 8] = std::array::from_fn(|_| rng.f32() * 256.0);
            let y: [f32; 8] = std::array::from_fn(|_| rng.f32() * 192.0);
            let d = cam.directions8(f32x8::from(x), f32x8::from(y));
            for i in 0..8 {
                let want = cam
                    .ray(Vec2::new(x[i], y[i]))
                    .d
                    .to_array()
                    .map(f32::to_bits);
                let got = [0, 1, 2].map(|k| d[k].to_array()[i].to_bits());
                assert_eq!(got, want, "film ({}, {})", x[i], y[i]);
            }
        }
    }

    #[test]
    fn orthographic_projects_known_points_and_rays_project_back() {
        // Film plane centred on (0, 0, 5), looking down −z, 4 units wide on 200×100 pixels:
        // 50 px per unit. The point (1, 0.5, −3) is 1·50 px right of the centre and 0.5·50 px
        // above it, at any depth in front of the plane.
        let cam = Camera::orthographic_look_at(
            200,
            100,
            Vec3::new(0.0, 0.0, 5.0),
            Vec3::ZERO,
            Vec3::Y,
            4.0,
        )
        .unwrap();
        assert_eq!((cam.fx, cam.fy), (50.0, 50.0));
        assert_eq!(cam.film_size_m(), Some(Vec2::new(4.0, 2.0)));
        assert_eq!(cam.fov_y_deg(), None);
        for z in [-3.0, 0.0, 4.9] {
            let p = cam.project(Vec3::new(1.0, 0.5, z)).unwrap();
            assert!((p - Vec2::new(150.0, 25.0)).length() < 1e-4, "{p}");
        }
        // Behind the film plane: not seen.
        assert!(cam.project(Vec3::new(0.0, 0.0, 5.1)).is_none());
        // Every ray is parallel to the view and starts on the film plane; a point along it
        // projects back onto its film position.
        for j in (0..=100).step_by(10) {
            for i in (0..=200).step_by(20) {
                let film = Vec2::new(i as f32, j as f32);
                let ray = cam.ray(film);
                assert_eq!(ray.d, -Vec3::Z);
                assert!((ray.o.z - 5.0).abs() < 1e-6);
                let back = cam.project(ray.o + ray.d * 7.0).unwrap();
                assert!((back - film).length() < 1e-4, "{film} → {back}");
            }
        }
        // The eight-lane directions are the rays' to the bit.
        let tilted = Camera::orthographic_look_at(
            64,
            48,
            Vec3::new(0.3, 1.6, 2.0),
            Vec3::new(0.1, 0.2, -0.3),
            Vec3::Y,
            1.7,
        )
        .unwrap();
        let xs = f32x8::from([0.5, 10.0, 63.5, 32.0, 1.0, 20.25, 60.0, 7.0]);
        let ys = f32x8::from([0.5, 5.0, 47.5, 24.0, 47.0, 10.75, 30.0, 40.0]);
        let d = tilted.directions8(xs, ys);
        for i in 0..8 {
            let r = tilted.ray(Vec2::new(xs.to_array()[i], ys.to_array()[i]));
            let got = [0, 1, 2].map(|k| d[k].to_array()[i].to_bits());
            assert_eq!(got, r.d.to_array().map(f32::to_bits));
        }
        // The calibrated form: fx, fy in pixels per unit, OpenCV's integer pixel centres.
        let cal = Camera::calibrated(64, 48, 20.0, 25.0, 31.5, 23.5, tilted.r, tilted.t)
            .unwrap()
            .orthographic();
        let p = Vec3::new(0.2, 0.4, -0.1);
        let c = tilted.r * p + tilted.t;
        let want = Vec2::new(20.0 * c.x + 32.0, 25.0 * c.y + 24.0);
        assert!((cal.project(p).unwrap() - want).length() < 1e-4);
    }

    #[test]
    fn non_rotations_are_refused() {
        let m = Mat3::from_diagonal(Vec3::new(1.0, 1.0, 2.0));
        assert!(Camera::calibrated(10, 10, 1.0, 1.0, 5.0, 5.0, m, Vec3::ZERO).is_none());
        assert!(Camera::look_at(10, 10, Vec3::ZERO, Vec3::Y, Vec3::Y, 40.0).is_none());
    }
}
