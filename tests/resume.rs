//! A recovery killed with SIGKILL after a checkpoint and resumed with `--resume` ends with
//! exactly the results of an uninterrupted run.

use crate::common::{matfit, root, run};
use std::path::Path;
use std::time::{Duration, Instant};

/// figure6 at 1/8 of its resolution, and its photo (16 spp) rendered by matfit.
fn small_scene_and_photo(dir: &Path) {
    let text = std::fs::read_to_string(root().join("scenes/figure6/scene.toml")).unwrap();
    let text = text
        .replace("width = 512\n", "width = 64\n")
        .replace("height = 384\n", "height = 48\n");
    std::fs::write(dir.join("scene.toml"), text).unwrap();
    let (code, _, err) = run(
        &["render", "scene.toml", "-o", "photo.exr", "--spp", "16"],
        dir,
    );
    assert_eq!(code, 0, "{err}");
}

const FIT: [&str; 10] = [
    "--light-samples",
    "8",
    "--indirect-samples",
    "8",
    "--final-spp",
    "4",
    "--max-iterations",
    "7",
    "--seed",
    "3",
];

/// results.json without its timing, log.jsonl without its times (seconds, elapsed, fit_seconds, cache_seconds),
/// and recovered.toml.
fn outputs(dir: &Path) -> (serde_json::Value, Vec<serde_json::Value>, String) {
    let mut res = crate::common::results(dir);
    res.as_object_mut().unwrap().remove("timing");
    let log = std::fs::read_to_string(dir.join("log.jsonl"))
        .unwrap()
        .lines()
        .map(|l| {
            let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
            v.as_object_mut().unwrap().remove("seconds");
            v.as_object_mut().unwrap().remove("elapsed");
            v.as_object_mut().unwrap().remove("fit_seconds");
            v.as_object_mut().unwrap().remove("cache_seconds");
            v
        })
        .collect();
    (
        res,
        log,
        std::fs::read_to_string(dir.join("recovered.toml")).unwrap(),
    )
}

/// Runs `recover scene.toml photo.exr` with `fit` whole (into `whole/`), and again killed with
/// SIGKILL as soon as it has written a checkpoint that contains `holding` and resumed (into
/// `killed/`); asserts that both end with the same outputs.
fn whole_equals_killed_and_resumed(d: &Path, fit: &[&str], holding: &str) {
    let mut args = vec!["recover", "scene.toml", "photo.exr", "-o", "whole"];
    args.extend(fit);
    let (code, _, err) = run(&args, d);
    assert_eq!(code, 0, "{err}");

    let mut args = vec!["recover", "scene.toml", "photo.exr", "-o", "killed"];
    args.extend(fit);
    let mut child = matfit().args(&args).current_dir(d).spawn().unwrap();
    let t = Instant::now();
    let written = || {
        std::fs::read_to_string(d.join("killed/checkpoint.json")).is_ok_and(|c| c.contains(holding))
    };
    while !written() && t.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap(); // SIGKILL on Unix
    child.wait().unwrap();
    assert!(written(), "no checkpoint holding {holding} was written");
    args.push("--resume");
    let (code, _, err) = run(&args, d);
    assert_eq!(code, 0, "{err}");
    let (a, b) = (outputs(&d.join("whole")), outputs(&d.join("killed")));
    assert_eq!(a.0, b.0, "results.json differs");
    assert_eq!(a.1, b.1, "log.jsonl differs");
    assert_eq!(a.2, b.2, "recovered.toml differs");
}

#[test]
fn kill_9_then_resume_gives_the_uninterrupted_result() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_scene_and_photo(d);
    whole_equals_killed_and_resumed(d, &FIT, "");

    // A checkpoint only resumes its own run.
    let mut args = vec![
        "recover",
        "scene.toml",
        "photo.exr",
        "-o",
        "killed",
        "--resume",
        "--seed",
        "4",
    ];
    args.extend(&FIT[..8]);
    let (code, _, err) = run(&args, d);
    assert_eq!(code, 2);
    assert!(
        err.contains("written for another scene, photo or set of options"),
        "{err}"
    );
}

#[test]
fn recover_results_are_identical_on_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_scene_and_photo(d);
    for (threads, out) in [("1", "t1"), ("2", "t2")] {
        let mut args = vec![
            "--threads",
            threads,
            "recover",
            "scene.toml",
            "photo.exr",
            "-o",
            out,
        ];
        args.extend(FIT);
        let (code, _, err) = run(&args, d);
        assert_eq!(code, 0, "{err}");
    }
    assert_eq!(outputs(&d.join("t1")), outputs(&d.join("t2")));
    assert_eq!(
        std::fs::read(d.join("t1/synthetic.exr")).unwrap(),
        std::fs::read(d.join("t2/synthetic.exr")).unwrap()
    );
}

#[test]
fn a_resumed_run_keeps_its_stray_light() {
    // The open sunroom at half size with a stray light in its photo, fitted with
    // --stray-light: the checkpoint carries the estimate, so the resumed run ends the same.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (text, truth) = crate::stray_light::sunroom_with_stray_light();
    std::fs::write(d.join("scene.toml"), text).unwrap();
    std::fs::write(d.join("truth.toml"), truth).unwrap();
    let (code, _, err) = run(
        &["render", "truth.toml", "-o", "photo.exr", "--spp", "64"],
        d,
    );
    assert_eq!(code, 0, "{err}");
    let fit = [
        "--final-spp",
        "4",
        "--max-iterations",
        "8",
        "--seed",
        "3",
        "--stray-light",
    ];
    // Killed once the checkpoint holds a determined stray light.
    whole_equals_killed_and_resumed(d, &fit, "\"estimated\":true");
    let res = crate::common::results(&d.join("killed"));
    assert!(
        res["stray_light"]["estimated"] == true,
        "{}",
        res["stray_light"]
    );
}
