//! Several photos of one scene (`[[view]]`, `recover SCENE PHOTO...`): one set of materials
//! fitted to all, each photo with its own exposure factor; views checked and rendered.

use crate::common::{json_rgb, results, root, run, small_scene, write};
use matfit::render::film::{render, RenderOptions};
use matfit::scene::load::parse_scene;
use std::path::Path;

/// The bundled light stage at 64×64 pixels.
fn light_stage(dir: &Path) -> std::path::PathBuf {
    let text = std::fs::read_to_string(root().join("scenes/lightstage/scene.toml"))
        .unwrap()
        .replace("width = 192", "width = 64")
        .replace("height = 192", "height = 64");
    write(dir, "scene.toml", &text)
}

fn ok(args: &[&str], dir: &Path) -> String {
    let (code, out, err) = run(args, dir);
    assert_eq!(code, 0, "matfit {args:?}\n{out}\n{err}");
    out
}

fn params(r: &serde_json::Value) -> (Vec<f64>, f64, f64) {
    let p = &r["groups"][0]["params"];
    (
        json_rgb(&p["rho_d"]),
        json_rgb(&p["rho_s"])[0],
        p["alpha_x"].as_f64().unwrap_or(f64::NAN),
    )
}

/// The ball's mean over the pixels where `truth` is not black.
fn ball_mean(img: &matfit::io::image::Image, truth: &matfit::io::image::Image) -> f64 {
    let (mut s, mut n) = (0.0f64, 0usize);
    for (a, t) in img.data.iter().zip(&truth.data) {
        if t.max_element() > 1e-4 {
            s += (a.x + a.y + a.z) as f64;
            n += 1;
        }
    }
    s / n.max(1) as f64
}

/// Three photos of the glossy ball, each under one distant light, the second light 5% brighter
/// than the scene file says (a calibration error). Fitted from that photo alone, every
/// reflectance carries the 5%; fitted from the three together, the photo's exposure factor
/// takes it (its ratio to the others' within 0.5% of 1.05) and the materials are the truth
/// scaled by the factors' geometric mean, 1.05^(1/3): ρ within 1%, α within 3%. The recovered
/// scene then predicts a photo under a light it never saw within 2% (ball mean).
#[test]
fn three_photos_share_one_material_and_absorb_a_light_calibration_error() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let scene = light_stage(d);
    let s = scene.to_str().unwrap();
    write(
        d,
        "brighter.toml",
        "[[light]]\nobject = \"l10\"\nscale = 1.05\n",
    );
    for (view, name, edit) in [
        ("1", "a.exr", None),
        ("10", "b.exr", Some("brighter.toml")),
        ("19", "c.exr", None),
        ("24", "unseen.exr", None),
    ] {
        let mut args = vec!["render", s, "--view", view, "--spp", "64", "-o", name];
        if let Some(e) = edit {
            args.extend(["--edit", e]);
        }
        ok(&args, d);
    }
    let quick = [
        "--no-register",
        "--max-iterations",
        "8",
        "--final-spp",
        "4",
        "--force",
    ];
    let mut one = vec!["recover", s, "b.exr", "--views", "10", "-o", "one"];
    one.extend(quick);
    ok(&one, d);
    let mut three = vec![
        "recover", s, "a.exr", "b.exr", "c.exr", "--views", "1,10,19", "-o", "three",
    ];
    three.extend(quick);
    let out = ok(&three, d);
    assert!(out.contains("photos fitted together"), "{out}");

    let truth_d = [0.35, 0.2, 0.12];
    let (rd1, _, _) = params(&results(&d.join("one")));
    assert!(
        (rd1[0] / truth_d[0] - 1.05).abs() < 0.01,
        "one photo carries the light's error into ρd: {rd1:?}"
    );
    let r3 = results(&d.join("three"));
    let views = r3["views"].as_array().unwrap();
    let k: Vec<f64> = views
        .iter()
        .map(|v| v["exposure"].as_f64().unwrap())
        .collect();
    assert_eq!(views[1]["name"], "l10");
    assert!((k[1] / k[0] - 1.05).abs() < 0.005, "factors {k:?}");
    assert!((k[2] / k[0] - 1.0).abs() < 0.005, "factors {k:?}");
    assert!((k.iter().product::<f64>() - 1.0).abs() < 1e-4, "{k:?}");
    let scale = 1.05f64.cbrt();
    let (rd, rs, alpha) = params(&r3);
    for c in 0..3 {
        assert!(
            (rd[c] / (truth_d[c] * scale) - 1.0).abs() < 0.01,
            "ρd {rd:?} vs {truth_d:?} × {scale}"
        );
    }
    assert!((rs / (0.12 * scale) - 1.0).abs() < 0.01, "ρs {rs}");
    assert!((alpha / 0.15 - 1.0).abs() < 0.03, "α {alpha}");
    assert_eq!(r3["inputs"]["photos"].as_array().unwrap().len(), 3);

    // The recovered scene keeps the views: it predicts the photo under light 24.
    ok(
        &[
            "render",
            "three/recovered.toml",
            "--view",
            "l24",
            "--spp",
            "64",
            "-o",
            "predicted.exr",
        ],
        d,
    );
    let read = |n: &str| matfit::io::image::read_linear(&d.join(n)).unwrap();
    let (truth, pred) = (read("unseen.exr"), read("predicted.exr"));
    let rel = ball_mean(&pred, &truth) / ball_mean(&truth, &truth) - 1.0;
    // The prediction carries the consensus scale, 1.05^(1/3): within 2% of the truth.
    assert!(rel.abs() < 0.02, "prediction off by {:.2}%", 100.0 * rel);
    let report = std::fs::read_to_string(d.join("three/report.html")).unwrap();
    assert!(report.contains("Photos fitted together") && report.contains("b.exr"));
}

/// The small scene (a floor under a quad lamp, group "lamps") with a sun as well.
fn two_lights() -> String {
    let sun = "\n[[light]]\nname = \"sun\"\ntype = \"directional\"\n\
               direction = [0.3, -1.0, -0.2]\nirradiance = 2.0\n";
    small_scene().replace("group = \"lamp\"", "group = \"lamps\"") + sun
}

/// A view with only the sun on renders to the bit what the same scene renders with the lamp a
/// black quad (still there, occluding) and the sun alone; its camera is its own.
#[test]
fn a_view_is_the_scene_with_its_camera_and_only_its_lights() {
    let views = r#"
[[view]]
name = "sun only"
lights = ["sun"]
camera = { eye = [0.5, 2.5, 1.5], target = [0.0, 0.0, 0.0], fov_y_deg = 40.0 }

[[view]]
lights = ["lamps"]
"#;
    let sc = parse_scene(&format!("{}{views}", two_lights()), Path::new("v.toml")).unwrap();
    assert_eq!(sc.views.len(), 2);
    assert_eq!(sc.views[1].name, "view 2");
    let sun = sc.in_view(0);
    // A lamp turned off keeps its surface: black, as an emitter's default material.
    let by_hand = two_lights()
        .replace("emission = 5.0", "material = { type = \"black\" }")
        .replace(
            "eye = [0.0, 2.0, 2.0]\ntarget = [0.0, 0.0, 0.0]\nfov_y_deg = 45.0",
            "eye = [0.5, 2.5, 1.5]\ntarget = [0.0, 0.0, 0.0]\nfov_y_deg = 40.0",
        );
    let hand = parse_scene(&by_hand, Path::new("h.toml")).unwrap();
    let opts = RenderOptions {
        spp: 8,
        seed: 3,
        progress: false,
    };
    let (a, b) = (
        render(&sun, &sun.camera, &opts),
        render(&hand, &hand.camera, &opts),
    );
    assert!(a.data.iter().any(|c| c.max_element() > 0.0));
    assert_eq!(a.data, b.data);
    // The lamp's view: the lamp by its group's name, no sun; the scene's camera.
    let lamp = sc.in_view(1);
    assert!(lamp.punctual_lights.is_empty() && lamp.objects[1].is_emitter());
    assert_eq!(lamp.camera, sc.camera);
    assert_eq!(sc.view_index("sun only").ok(), Some(0));
    assert_eq!(sc.view_index("2").ok(), Some(1));
    assert!(sc
        .view_index("3")
        .unwrap_err()
        .message()
        .contains("give 1 to 2"));
}

/// Views' mistakes are named with their line; photos and views must pair up.
#[test]
fn views_and_photos_that_do_not_pair_up_are_clear_errors() {
    let bad =
        |views: &str| match parse_scene(&format!("{}{views}", two_lights()), Path::new("v.toml")) {
            Ok(_) => panic!("{views} loaded"),
            Err(e) => e.to_string(),
        };
    let e = bad("\n[[view]]\nlights = [\"sunn\"]\n");
    assert!(
        e.contains("v.toml:33") && e.contains("no light is named 'sunn'") && e.contains("lamps"),
        "{e}"
    );
    let e = bad("\n[[view]]\nlights = []\n");
    assert!(e.contains("needs a light on"), "{e}");
    let e = bad("\n[[view]]\ncamera = { eye = [0.0, 1.0, 0.0], target = [0.0, 1.0, 0.0], fov_y_deg = 40.0 }\n");
    assert!(
        e.contains("[[view]] 'view 1'") && e.contains("same point"),
        "{e}"
    );
    let e = bad("\n[[view]]\nname = \"a\"\n[[view]]\nname = \"a\"\n");
    assert!(e.contains("two views have this name"), "{e}");
    let e = bad("\n[[view]]\nlight = [\"sun\"]\n");
    assert!(e.contains("did you mean `lights`"), "{e}");

    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write(d, "s.toml", &two_lights());
    let (code, _, err) = run(&["recover", "s.toml", "a.exr", "b.exr", "-o", "o"], d);
    assert!(code != 0 && err.contains("0 [[view]]"), "{err}");
    write(
        d,
        "v.toml",
        &format!("{}\n[[view]]\n[[view]]\n", two_lights()),
    );
    let (code, _, err) = run(
        &[
            "recover", "v.toml", "a.exr", "b.exr", "--views", "1", "-o", "o",
        ],
        d,
    );
    assert!(code != 0 && err.contains("one per photo"), "{err}");
    let (code, _, err) = run(&["render", "v.toml", "--view", "7", "-o", "x.exr"], d);
    assert!(code != 0 && err.contains("no view '7'"), "{err}");
    let (code, _, err) = run(&["render", "s.toml", "--view", "1", "-o", "x.exr"], d);
    assert!(code != 0 && err.contains("has no [[view]]"), "{err}");
}
