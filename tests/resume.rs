//! A recovery killed with SIGKILL after a checkpoint and resumed with `--resume` ends with
//! exactly the results of an uninterrupted run (issue 6).

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

/// results.json without its timing, log.jsonl without the seconds and elapsed, and recovered.toml.
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
            v
        })
        .collect();
    (
        res,
        log,
        std::fs::read_to_string(dir.join("recovered.toml")).unwrap(),
    )
}

#[test]
fn kill_9_then_resume_gives_the_uninterrupted_result() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_scene_and_photo(d);
    let mut args = vec!["recover", "scene.toml", "photo.exr", "-o", "whole"];
    args.extend(FIT);
    let (code, _, err) = run(&args, d);
    assert_eq!(code, 0, "{err}");

    // The same run, killed as soon as its first checkpoint exists.
    let mut args = vec!["recover", "scene.toml", "photo.exr", "-o", "killed"];
    args.extend(FIT);
    let mut child = matfit().args(&args).current_dir(d).spawn().unwrap();
    let t = Instant::now();
    while !d.join("killed/checkpoint.json").exists() && t.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap(); // SIGKILL on Unix
    child.wait().unwrap();
    assert!(
        d.join("killed/checkpoint.json").exists(),
        "no checkpoint was written"
    );
    let mut args = vec![
        "recover",
        "scene.toml",
        "photo.exr",
        "-o",
        "killed",
        "--resume",
    ];
    args.extend(FIT);
    let (code, _, err) = run(&args, d);
    assert_eq!(code, 0, "{err}");
    let (a, b) = (outputs(&d.join("whole")), outputs(&d.join("killed")));
    assert_eq!(a.0, b.0, "results.json differs");
    assert_eq!(a.1, b.1, "log.jsonl differs");
    assert_eq!(a.2, b.2, "recovered.toml differs");

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
