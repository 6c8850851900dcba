//! Pose refinement through the binary (`recover`): a right camera is left alone however the
//! object is lit, a camera turned by ~1° and moved by 2 cm is found, and `--camera-is-calibrated`
//! skips it all.

use crate::common::{diffuse, run, write, SceneToml, QUICK};
use matfit::math::{Mat3, Vec3};
use matfit::scene::{load_scene, Camera, Scene};
use std::path::Path;

/// A Lambert sphere lit from the side by the sun, against black, and a box beside it, seen
/// through `camera` (the `[camera]` lines after width and height).
fn side_lit(camera: &str) -> String {
    SceneToml::compact()
        .table("[camera]", &[("width", "160"), ("height", "120")])
        .raw(&format!("{camera}\n"))
        .sphere("ball", "ball", [0.0; 3], 0.5, Some(128), &diffuse(&[0.7]))
        .cuboid(
            "block",
            "block",
            [0.6, -0.5, -0.3],
            [1.0, 0.1, 0.2],
            &diffuse(&[0.4]),
        )
        .raw("[[light]]\nname = \"sun\"\ntype = \"directional\"\ndirection = [-1.0, -0.3, -0.4]\nirradiance = 3.0\n")
        .to_toml()
}

const MODEL: &str = "eye = [0.2, 0.3, 3.0]\ntarget = [0.2, 0.0, 0.0]\nfov_y_deg = 35";
/// The photo's camera: 2 cm to the side, turned by 0.95° (its view direction from
/// (0, −0.3, −3) to (0.05, −0.3, −3)).
const TRUE: &str = "eye = [0.22, 0.3, 3.0]\ntarget = [0.27, 0.0, 0.0]\nfov_y_deg = 35";

fn recover(dir: &Path, scene: &str, out: &str, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["recover", scene, "photo.exr", "-o", out];
    args.extend(QUICK);
    args.extend(extra);
    let (code, _, err) = run(&args, dir);
    assert_eq!(code, 0, "{err}");
    crate::common::results(&dir.join(out))
}

fn rho(json: &serde_json::Value, group: &str) -> f32 {
    let g = json["groups"]
        .as_array()
        .unwrap()
        .iter()
        .find(|g| g["name"] == group)
        .unwrap();
    g["params"]["rho_d"][1].as_f64().unwrap() as f32
}

/// The camera results.json reports, rebuilt from its R | t.
fn reported_camera(json: &serde_json::Value, like: &Camera) -> Camera {
    let reg = &json["inputs"]["registration"];
    let f = |v: &serde_json::Value| v.as_f64().unwrap() as f32;
    let rows: Vec<Vec3> = (0..3)
        .map(|i| {
            Vec3::new(
                f(&reg["camera_rotation"][i][0]),
                f(&reg["camera_rotation"][i][1]),
                f(&reg["camera_rotation"][i][2]),
            )
        })
        .collect();
    let r = Mat3::from_cols(rows[0], rows[1], rows[2]).transpose();
    let t = &reg["camera_translation"];
    Camera {
        r,
        t: Vec3::new(f(&t[0]), f(&t[1]), f(&t[2])),
        ..like.clone()
    }
}

/// RMS distance in pixels between where cameras `a` and `b` see the scene's visible points.
fn reprojection_px(scene: &Scene, a: &Camera, b: &Camera) -> f32 {
    let pts: Vec<Vec3> = scene
        .camera_grid_hits(40, 30)
        .into_iter()
        .map(|(_, _, h)| h.p)
        .collect();
    matfit::prepare::pose::motion(a, b, &pts).1
}

#[test]
fn a_right_camera_stays_a_wrong_one_is_found_and_a_calibrated_one_is_kept() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "model.toml", &side_lit(MODEL));
    write(d, "true.toml", &side_lit(TRUE));
    let model = load_scene(&d.join("model.toml")).unwrap();
    let truth = load_scene(&d.join("true.toml")).unwrap();

    // (a) The photo through the model's own camera: the sphere's lit limb ramps, its dark
    // side has no edge; the correction stays below 0.1 px and is not applied.
    let (code, _, err) = run(
        &["render", "model.toml", "--spp", "64", "-o", "photo.exr"],
        d,
    );
    assert_eq!(code, 0, "{err}");
    let right = recover(d, "model.toml", "right", &["--refine-pose"]);
    let reg = &right["inputs"]["registration"];
    let rms = reg["rms_px"].as_f64().unwrap();
    eprintln!("right camera: {reg}");
    assert!(rms < 0.1, "a right camera moved by {rms} px RMS: {reg}");
    assert_eq!(reg["applied"], false);

    // (b) The photo through a camera turned by 0.95° and moved by 2 cm.
    let (code, _, err) = run(
        &["render", "true.toml", "--spp", "64", "-o", "photo.exr"],
        d,
    );
    assert_eq!(code, 0, "{err}");
    let before = reprojection_px(&truth, &model.camera, &truth.camera);
    let found = recover(d, "model.toml", "found", &["--refine-pose"]);
    let reg = &found["inputs"]["registration"];
    eprintln!("turned camera: {reg}");
    assert_eq!(reg["applied"], true, "{reg}");
    let cam = reported_camera(&found, &model.camera);
    let after = reprojection_px(&truth, &cam, &truth.camera);
    eprintln!("reprojection error {before:.2} px → {after:.3} px");
    assert!(before > 3.0 && after < 0.3, "{before} → {after}");
    // recovered.toml has the refined camera, and says so.
    let rec = load_scene(&d.join("found/recovered.toml")).unwrap();
    let written = reprojection_px(&truth, &rec.camera, &truth.camera);
    assert!(written < 0.3, "recovered.toml's camera is {written} px off");
    let text = std::fs::read_to_string(d.join("found/recovered.toml")).unwrap();
    assert!(
        text.contains("# Camera: the scene's, refined to the photo and applied"),
        "{text}"
    );
    // The materials are those recovered through the true camera.
    let reference = recover(d, "true.toml", "reference", &["--camera-is-calibrated"]);
    for g in ["ball", "block"] {
        let (a, b) = (rho(&found, g), rho(&reference, g));
        eprintln!("{g}: ρd {a:.4} through the refined camera, {b:.4} through the true one");
        assert!((a - b).abs() < 0.01, "{g}: {a} vs {b}");
    }

    // (c) --camera-is-calibrated keeps the (wrong) camera: no registration is reported, and
    // the materials show it.
    let kept = recover(d, "model.toml", "kept", &["--camera-is-calibrated"]);
    assert!(
        kept["inputs"]["registration"].is_null(),
        "{}",
        kept["inputs"]
    );
}
