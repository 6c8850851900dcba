//! The scene file's [camera] (or a [[view]]'s, or an edit's) made a checked [`Camera`]: the
//! look-at or calibrated pinhole, orthographic projection, and lens distortion.

use super::camera::Lens;
use super::context::Ctx;
use super::error::SceneError;
use super::schema::{CameraSpec, ProjectionKind, SceneFile};
use super::Camera;
use crate::math::{Mat3, Vec2, Vec3};
use serde::Deserialize;
use std::path::Path;

/// Checks a parsed scene file's camera alone (an edit's new camera).
pub(super) fn check_camera(
    file: &SceneFile,
    text: &str,
    path: &Path,
) -> Result<Camera, SceneError> {
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    build_camera(file, &Ctx { path, text, dir })
}

pub(super) fn build_camera(file: &SceneFile, cx: &Ctx) -> Result<Camera, SceneError> {
    let mut cam = pinhole(file, cx)?;
    let (key, lens, k): (&str, Lens, Vec<f32>) = match (file.camera.distortion, file.camera.fisheye)
    {
        (None, None) => return Ok(cam),
        // A lens model bends rays through one centre; parallel rays have none to bend about.
        (d, _) if cam.is_orthographic() => {
            let key = if d.is_some() { "distortion" } else { "fisheye" };
            return Err(cx.camera_at(
                key,
                format!(
                    "[camera] {key} is for a perspective camera's lens: an orthographic \
                     camera has no lens to distort (remove `{key}` or the projection)"
                ),
            ));
        }
        (Some(_), Some(_)) => {
            return Err(cx.camera_at(
                "fisheye",
                "[camera] has both `distortion` and `fisheye`: give one lens model".into(),
            ))
        }
        (Some(k), None) => ("distortion", Lens::Brown(k), k.to_vec()),
        (None, Some(k)) => ("fisheye", Lens::Fisheye(k), k.to_vec()),
    };
    if !k.iter().all(|x| x.is_finite()) {
        return Err(cx.camera_at(key, format!("[camera] {key} has a NaN or infinite value")));
    }
    cam.distortion = Some(lens);
    // The model must be invertible over the film: every border pixel's ray lands back on it.
    let (w, h) = (cam.width as f32, cam.height as f32);
    for i in 0..=16 {
        let f = i as f32 / 16.0;
        for film in [
            Vec2::new(f * w, 0.0),
            Vec2::new(f * w, h),
            Vec2::new(0.0, f * h),
            Vec2::new(w, f * h),
        ] {
            let ray = cam.ray(film);
            let back = cam.project(ray.o + ray.d);
            if back.is_none_or(|b| (b - film).length() > 0.01) {
                return Err(cx.camera_at(
                    key,
                    format!(
                        "[camera] {key} {k:?} cannot be inverted at film position ({}, {}): \
                         too strong for this field of view (are the coefficients OpenCV's, for \
                         these fx, fy?)",
                        film.x, film.y
                    ),
                ));
            }
        }
    }
    Ok(cam)
}

/// The camera of `[camera]` without its lens distortion.
fn pinhole(file: &SceneFile, cx: &Ctx) -> Result<Camera, SceneError> {
    let c = &file.camera;
    let ortho = c.projection == Some(ProjectionKind::Orthographic);
    // The film's extent: a field of view for a pinhole, a width in scene units for parallel rays.
    let (extent_key, extent) = if ortho {
        if c.fov_y_deg.is_some() {
            return Err(cx.camera_at(
                "fov_y_deg",
                "[camera] an orthographic camera has no field of view: give its film's width in \
                 scene units, `width_m`, instead of fov_y_deg"
                    .into(),
            ));
        }
        ("width_m", c.width_m)
    } else {
        if c.width_m.is_some() {
            return Err(cx.camera_at(
                "width_m",
                "[camera] width_m (the film's width in scene units) is for \
                 projection = \"orthographic\": give fov_y_deg for a perspective camera"
                    .into(),
            ));
        }
        ("fov_y_deg", c.fov_y_deg)
    };
    if c.width == 0 || c.height == 0 || c.width > 65536 || c.height > 65536 {
        return Err(cx.whole(format!(
            "[camera] width and height must be between 1 and 65536, got {}×{}",
            c.width, c.height
        )));
    }
    let max = crate::io::image::MAX_PIXELS;
    if c.width as usize * c.height as usize > max {
        return Err(cx.whole(format!(
            "[camera] {}×{} is more than matfit's limit of {} megapixels",
            c.width,
            c.height,
            max >> 20
        )));
    }
    let look_at = [c.eye.is_some(), c.target.is_some(), extent.is_some()];
    let calib = [
        c.fx.is_some(),
        c.fy.is_some(),
        c.cx.is_some(),
        c.cy.is_some(),
        c.rotation.is_some(),
        c.translation.is_some(),
    ];
    let any_la = look_at.iter().any(|&b| b) || c.up.is_some();
    let any_cal = calib.iter().any(|&b| b);
    if any_la && any_cal {
        return Err(cx.whole(format!(
            "[camera] mixes the look-at form (eye, target, up, {extent_key}) with the \
                 calibrated form (fx, fy, cx, cy, rotation, translation): give one"
        )));
    }
    let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
    if any_cal {
        let names = ["fx", "fy", "cx", "cy", "rotation", "translation"];
        let missing: Vec<&str> = names
            .iter()
            .zip(calib)
            .filter(|(_, b)| !b)
            .map(|(n, _)| *n)
            .collect();
        if !missing.is_empty() {
            return Err(cx.whole(format!(
                "[camera] calibrated form lacks {}",
                missing.join(", ")
            )));
        }
        let rot = c.rotation.unwrap();
        let r = Mat3::from_cols_array_2d(&rot).transpose(); // rows in the file
        let (fx, fy, ccx, ccy) = (c.fx.unwrap(), c.fy.unwrap(), c.cx.unwrap(), c.cy.unwrap());
        let t = c.translation.unwrap();
        if !finite(&[fx, fy, ccx, ccy]) || !finite(&t) || !finite(rot.as_flattened()) {
            return Err(cx.whole("[camera] has a NaN or infinite value".into()));
        }
        let cam = Camera::calibrated(c.width, c.height, fx, fy, ccx, ccy, r, Vec3::from(t));
        let cam = if ortho {
            cam.map(Camera::orthographic)
        } else {
            cam
        };
        cam.ok_or_else(|| {
            if !(fx > 0.0) {
                cx.camera_at("fx", format!("[camera] fx must be > 0, got {fx}"))
            } else if !(fy > 0.0) {
                cx.camera_at("fy", format!("[camera] fy must be > 0, got {fy}"))
            } else {
                let rows = r.transpose();
                let off = (rows * rows.transpose() - Mat3::IDENTITY)
                    .to_cols_array()
                    .iter()
                    .fold(0.0f32, |m, x| m.max(x.abs()));
                cx.camera_at(
                    "rotation",
                    format!(
                        "[camera] rotation is not a rotation matrix: its rows must be orthonormal \
                         (largest deviation of R Rᵀ from I: {off:.2e}) and its determinant +1 \
                         (it is {:.4})",
                        r.determinant()
                    ),
                )
            }
        })
    } else {
        let names = ["eye", "target", extent_key];
        let missing: Vec<&str> = names
            .iter()
            .zip(look_at)
            .filter(|(_, b)| !b)
            .map(|(n, _)| *n)
            .collect();
        if !missing.is_empty() {
            return Err(cx.whole(format!(
                "[camera] lacks {} (give eye, target, {extent_key} and optionally up; or fx, fy, cx, cy, rotation, translation)",
                missing.join(", ")
            )));
        }
        let (eye, target, up) = (
            c.eye.unwrap(),
            c.target.unwrap(),
            c.up.unwrap_or([0.0, 1.0, 0.0]),
        );
        let extent = extent.unwrap();
        if !finite(&eye) || !finite(&target) || !finite(&up) || !extent.is_finite() {
            return Err(cx.whole("[camera] has a NaN or infinite value".into()));
        }
        let (w, h, e, tg, u) = (c.width, c.height, eye.into(), target.into(), up.into());
        let cam = if ortho {
            Camera::orthographic_look_at(w, h, e, tg, u, extent)
        } else {
            Camera::look_at(w, h, e, tg, u, extent)
        };
        let fov = extent;
        let fov_ok = fov > 0.0 && fov < 180.0;
        cam.ok_or_else(|| {
            let view = Vec3::from(target) - Vec3::from(eye);
            if ortho && !(extent > 0.0) {
                cx.camera_at(
                    "width_m",
                    format!("[camera] width_m (the film's width in scene units) must be > 0, got {extent}"),
                )
            } else if !ortho && !fov_ok {
                cx.camera_at(
                    "fov_y_deg",
                    format!("[camera] fov_y_deg (vertical field of view, degrees) must be in (0, 180), got {fov}"),
                )
            } else if view.length() < 1e-6 {
                cx.camera_at(
                    "target",
                    format!("[camera] eye and target are the same point {eye:?}: the camera has no view direction"),
                )
            } else if c.up.is_some() {
                cx.camera_at(
                    "up",
                    format!("[camera] up {up:?} is parallel to the view direction (target − eye): give an up that is not"),
                )
            } else {
                cx.camera_at(
                    "target",
                    "[camera] the view direction (target − eye) is vertical, parallel to the default up [0, 1, 0]: give `up`".into(),
                )
            }
        })
    }
}

/// The edit's camera table with the scene's width and height where it gives none.
pub(super) fn edited_camera(table: &toml::Table, scene: &CameraSpec) -> Result<CameraSpec, String> {
    let mut t = table.clone();
    t.entry("width")
        .or_insert(toml::Value::Integer(scene.width.into()));
    t.entry("height")
        .or_insert(toml::Value::Integer(scene.height.into()));
    CameraSpec::deserialize(toml::Value::Table(t)).map_err(|e| {
        format!(
            "[camera]: {}",
            super::context::with_suggestion(&e.to_string())
        )
    })
}
