//! A uniform sphere whose photo is misregistered by 0.7 px must stay uniform: the shading
//! residual along its outline is the model's misplacement, not a texture. A glossy plastic
//! sphere under one distant light, seen by an orthographic camera at 128 × 128; the photo is
//! rendered with the sphere moved 0.7 px to the right of where the scene file puts it. The fit
//! runs with the default options (but a cheap final render), as a user would.

use crate::common::{result_group, results, run, vec3, write, SceneToml};
use std::path::Path;

const W: usize = 128;
/// The film's width in scene units: 1.5 over 128 pixels.
const WIDTH_M: f64 = 1.5;
/// The photo's sphere is this many pixels right of the model's.
const SHIFT_PX: f64 = 0.7;

fn scene(center_x: f64) -> String {
    let w = W.to_string();
    SceneToml::compact()
        .render(&[("spp", "64"), ("max_depth", "4")])
        .table(
            "[camera]",
            &[
                ("width", &w),
                ("height", &w),
                ("projection", "\"orthographic\""),
                ("eye", &vec3([0.0, 0.0, 3.0])),
                ("target", &vec3([0.0; 3])),
                ("width_m", &WIDTH_M.to_string()),
            ],
        )
        .sphere(
            "ball",
            "ball",
            [center_x, 0.0, 0.0],
            0.5,
            Some(256),
            "material = { type = \"plastic\", rho_d = [0.55, 0.3, 0.15], rho_s = 0.0387, \
             alpha = 0.1 }",
        )
        .raw(
            "[[light]]\nname = \"sun\"\ntype = \"directional\"\n\
             direction = [-0.45, -0.35, -1.0]\nirradiance = 3.0\n",
        )
        .to_toml()
}

/// Writes the model (`scene.toml`, the sphere at the origin) and renders the photo
/// (`photo.exr`) from the same scene with the sphere moved by SHIFT_PX.
fn model_and_shifted_photo(dir: &Path) {
    write(dir, "scene.toml", &scene(0.0));
    write(dir, "shifted.toml", &scene(SHIFT_PX * WIDTH_M / W as f64));
    let (code, _, err) = run(
        &["render", "shifted.toml", "-o", "photo.exr", "--spp", "256"],
        dir,
    );
    assert_eq!(code, 0, "{err}");
}

/// Recovers the photo with the default fit options and `extra`; returns the ball's results.json entry.
fn recover_ball(dir: &Path, out: &str, extra: &[&str]) -> serde_json::Value {
    let mut args = vec![
        "recover",
        "scene.toml",
        "photo.exr",
        "-o",
        out,
        "--final-spp",
        "8",
    ];
    args.extend(extra);
    let (code, stdout, err) = run(&args, dir);
    assert_eq!(code, 0, "{err}");
    eprintln!("{stdout}");
    let res = results(&dir.join(out));
    result_group(&res, "ball").clone()
}

fn assert_uniform(ball: &serde_json::Value) {
    assert_ne!(ball["level"], "textured", "{ball:#}");
    assert!(
        ball["texture"].is_null(),
        "a uniform sphere was given a texture: {ball:#}"
    );
}

/// With the default registration (the camera's pose refined), the misregistration is found and
/// the sphere keeps a uniform model.
#[test]
fn a_misregistered_uniform_sphere_stays_uniform_with_pose_refinement() {
    let d = tempfile::tempdir().unwrap();
    model_and_shifted_photo(d.path());
    assert_uniform(&recover_ball(d.path(), "posed", &[]));
}

/// With the camera held as given, the 0.7 px stays in the photo: the residual along the outline
/// must still not make the sphere textured.
#[test]
fn a_misregistered_uniform_sphere_stays_uniform_with_the_camera_held() {
    let d = tempfile::tempdir().unwrap();
    model_and_shifted_photo(d.path());
    assert_uniform(&recover_ball(d.path(), "held", &["--camera-is-calibrated"]));
}

/// With the pose refined, the sphere should come back as what it is: the plastic of the photo,
/// its base within 5% of the truth.
#[test]
#[ignore = "fails on main at the time of writing: the refined pose keeps most of the 0.7 px \
            (orthographic camera) and the sphere ends microfacet with rho_d about 12% low"]
fn a_misregistered_uniform_sphere_is_recovered_with_pose_refinement() {
    let d = tempfile::tempdir().unwrap();
    model_and_shifted_photo(d.path());
    let ball = recover_ball(d.path(), "posed", &[]);
    assert_eq!(ball["level"], "plastic", "{ball:#}");
    let rho = crate::common::json_rgb(&ball["params"]["rho_d"]);
    for (got, want) in rho.iter().zip([0.55, 0.3, 0.15]) {
        assert!((got / want - 1.0).abs() < 0.05, "rho_d {rho:?}: {ball:#}");
    }
}
