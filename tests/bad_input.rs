//! Bad inputs beyond the scene file (tests/scene_errors.rs) and the photo file
//! (tests/photo.rs): output places that cannot be written, a resume without a checkpoint,
//! options out of range, a group with no usable pixel, a photo whose values make a fit diverge.
//! Each gets a clear message and a non-zero exit (or, for the group without pixels, a warning
//! and a stated default), quickly: before the long work, never a panic.

use crate::common::{run, small_room, small_scene, write, QUICK};
use matfit::io::image::Image;
use matfit::math::Rgb;
use std::path::Path;
use std::time::Instant;

/// The small scene and its photo (a 16-spp rendering) in `dir`, and a regular file `blocker`.
fn setup(dir: &Path) {
    write(dir, "scene.toml", &small_scene());
    let (code, _, err) = run(
        &["render", "scene.toml", "-o", "photo.exr", "--spp", "16"],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    write(dir, "blocker", "a file, not a folder");
}

/// Runs matfit; checks exit 2, an `error:` message holding every needle, no panic, and that it
/// failed within `secs` seconds.
fn fails(dir: &Path, args: &[&str], needles: &[&str], secs: f64) -> String {
    let t = Instant::now();
    let (code, _, err) = run(args, dir);
    let took = t.elapsed().as_secs_f64();
    eprintln!("{args:?} → exit {code} in {took:.2} s: {}", err.trim());
    assert_eq!(code, 2, "{args:?}: {err}");
    // Warnings about the input (e.g. a photo far brighter than the lights allow) may come first.
    let first = err
        .lines()
        .find(|l| !l.starts_with("warning: "))
        .unwrap_or("");
    assert!(first.starts_with("error: "), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: expected '{n}' in: {err}");
    }
    assert!(took < secs, "{args:?}: took {took:.1} s to fail");
    err
}

#[test]
fn outputs_that_cannot_be_written_fail_before_the_work() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    setup(dir);
    // As root, permissions do not stop a write: a regular file where a folder must be does.
    let blocked = ["blocker is a file, not a folder"];
    let mut recover = vec!["recover", "scene.toml", "photo.exr", "-o", "blocker/out"];
    recover.extend(QUICK);
    fails(dir, &recover, &blocked, 5.0);
    fails(
        dir,
        &["inspect", "scene.toml", "photo.exr", "-o", "blocker/out"],
        &blocked,
        5.0,
    );
    fails(
        dir,
        &["export", "mitsuba", "scene.toml", "-o", "blocker/out"],
        &blocked,
        5.0,
    );
    fails(
        dir,
        &["demo", "--scene", "scene.toml", "-o", "blocker/demo"],
        &blocked,
        5.0,
    );
    // A render of a million samples per pixel would take minutes: it must fail at once.
    fails(
        dir,
        &[
            "render",
            "scene.toml",
            "-o",
            "blocker/x.exr",
            "--spp",
            "1000000",
        ],
        &["blocker/x.exr", "blocker is a file, not a folder"],
        5.0,
    );
    std::fs::create_dir(dir.join("taken.exr")).unwrap();
    fails(
        dir,
        &[
            "render",
            "scene.toml",
            "-o",
            "taken.exr",
            "--spp",
            "1000000",
        ],
        &["taken.exr", "it is a folder"],
        5.0,
    );
    assert!(!dir.join("blocker").is_dir());
}

#[test]
fn resume_without_a_usable_checkpoint() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    setup(dir);
    let mut args = vec![
        "recover",
        "scene.toml",
        "photo.exr",
        "-o",
        "out",
        "--resume",
    ];
    args.extend(QUICK);
    fails(dir, &args, &["cannot resume", "checkpoint.json"], 10.0);
    write(dir, "out/checkpoint.json", "{ \"version\": 1, \"fingerp");
    fails(
        dir,
        &args,
        &["cannot resume", "is not a matfit checkpoint"],
        10.0,
    );
    // The run's own checkpoint, edited: a reflectance no fit can produce.
    let (code, _, err) = run(
        &args[..5].iter().chain(&QUICK).copied().collect::<Vec<_>>(),
        dir,
    );
    assert_eq!(code, 0, "{err}");
    let path = dir.join("out/checkpoint.json");
    let mut ck: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let floor = ck["states"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .find(|s| s["name"] == "floor")
        .unwrap();
    floor["params"]["rho_d"] = serde_json::json!([1.5, 0.5, 0.5]);
    std::fs::write(&path, ck.to_string()).unwrap();
    fails(
        dir,
        &args,
        &["cannot resume", "outside their physical bounds", "'floor'"],
        10.0,
    );
}

#[test]
fn photo_options_out_of_range() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    setup(dir);
    let inspect = |extra: &[&str]| {
        let mut a = vec!["inspect", "scene.toml", "photo.exr", "-o", "out"];
        a.extend(extra);
        a.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let demo = [
        "demo",
        "--scene",
        "scene.toml",
        "-o",
        "d",
        "--photo-spp",
        "0",
    ];
    let demo: Vec<String> = demo.into_iter().map(String::from).collect();
    let cases: [(Vec<String>, &[&str]); 6] = [
        (demo, &["--photo-spp", "0"]),
        (
            inspect(&["--exposure=-2"]),
            &["exposure must be positive", "-2"],
        ),
        (inspect(&["--exposure=nan"]), &["exposure must be positive"]),
        (
            inspect(&["--grey-card", "flor=0.5"]),
            &["no group 'flor'", "floor"],
        ),
        (inspect(&["--grey-card", "floor=1.5"]), &["(0, 1]"]),
        (
            inspect(&["--response", "table:missing.txt"]),
            &["missing.txt"],
        ),
    ];
    for (args, needles) in cases {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        fails(dir, &a, needles, 5.0);
    }
}

/// A sticker on the floor two pixels wide: visible, but the band around object boundaries
/// takes all of its pixels. `recover` warns, states the default it gives, and carries on.
#[test]
fn a_group_with_no_usable_pixels_gets_a_warning_and_a_stated_default() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let text = small_room()
        .quad(
            "sticker",
            "sticker",
            [0.0, 0.001, 0.06],
            [0.06, 0.0, 0.0],
            [0.0, 0.0, -0.06],
            "",
        )
        .to_toml();
    write(dir, "scene.toml", &text);
    let (code, _, err) = run(
        &["render", "scene.toml", "-o", "photo.exr", "--spp", "16"],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    let mut args = vec!["recover", "scene.toml", "photo.exr", "-o", "out"];
    args.extend(QUICK);
    let (code, out, err) = run(&args, dir);
    eprintln!("{out}{err}");
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("group 'sticker': no usable pixels")
            && err.contains("estimated from the light it reflects")
            && err.contains("--white-unseen"),
        "{err}"
    );
    let res = crate::common::results(&dir.join("out"));
    let g = res["groups"]
        .as_array()
        .unwrap()
        .iter()
        .find(|g| g["name"] == "sticker")
        .unwrap();
    assert_eq!(g["status"], "default", "{g}");
    assert!(g["visible_pixels"].as_u64().unwrap() > 0, "{g}");
    assert_eq!(g["usable_pixels"], 0, "{g}");
    // Two pixels wide, its light does not measurably reach the floor: the stated default.
    assert!(
        g["note"]
            .as_str()
            .unwrap()
            .contains("area-weighted mean albedo"),
        "{g}"
    );
    assert_eq!(g["unseen"]["rule"], "scene_mean", "{g}");
}

/// A photo whose values are finite but so large that sums over a group overflow (a raw dump
/// read as radiance, say) makes the floor's fit diverge: recover stops, naming the group, and
/// leaves no results behind as if they were good.
#[test]
fn a_diverging_fit_stops_recover_naming_the_group() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    setup(dir);
    let huge = Image {
        width: 64,
        height: 48,
        data: vec![Rgb::splat(3e38); 64 * 48],
    };
    huge.write(&dir.join("huge.pfm")).unwrap();
    let mut args = vec![
        "recover",
        "scene.toml",
        "huge.pfm",
        "-o",
        "out",
        "--no-register",
    ];
    args.extend(QUICK);
    fails(
        dir,
        &args,
        &["group 'floor'", "diverged", "iteration 0"],
        30.0,
    );
    assert!(!dir.join("out/results.json").exists());
    assert!(!dir.join("out/checkpoint.json").exists());
    assert!(dir.join("out/log.jsonl").exists());
}

#[test]
fn a_camera_that_sees_nothing_stops_render_and_recover() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    setup(dir);
    write(
        dir,
        "away.toml",
        &small_scene().replace("target = [0.0, 0.0, 0.0]", "target = [0.0, 4.0, 4.0]"),
    );
    fails(
        dir,
        &["render", "away.toml", "-o", "x.exr", "--spp", "1000000"],
        &["away.toml", "sees no geometry"],
        5.0,
    );
    let mut args = vec!["recover", "away.toml", "photo.exr", "-o", "out"];
    args.extend(QUICK);
    fails(dir, &args, &["away.toml", "sees no geometry"], 5.0);
}
