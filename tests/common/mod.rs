//! Helpers shared by the end-to-end tests.
#![allow(dead_code)]

mod scene;
pub use scene::*;

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository root (these tests are the command line's, in `cli/`).
pub fn root() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// The `matfit` binary built for these tests.
pub fn matfit() -> Command {
    Command::new(env!("CARGO_BIN_EXE_matfit"))
}

/// Runs matfit with `args`; returns (exit code, stdout, stderr).
pub fn run(args: &[&str], dir: &Path) -> (i32, String, String) {
    let out = matfit()
        .args(args)
        .current_dir(dir)
        .output()
        .expect("runs matfit");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The `results.json` a recovery wrote into `dir`.
pub fn results(dir: &Path) -> serde_json::Value {
    let path = dir.join("results.json");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

/// Group `name`'s entry in a `results.json`.
pub fn result_group<'a>(res: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    res["groups"]
        .as_array()
        .unwrap()
        .iter()
        .find(|g| g["name"] == name)
        .unwrap_or_else(|| panic!("no group '{name}' in results.json"))
}

/// A colour parameter of `results.json` as three channels: an RGB array, or a number for all
/// three; NaN where the parameter is absent.
pub fn json_rgb(v: &serde_json::Value) -> Vec<f64> {
    match v {
        serde_json::Value::Array(a) => a.iter().map(|x| x.as_f64().unwrap()).collect(),
        x => vec![x.as_f64().unwrap_or(f64::NAN); 3],
    }
}

/// Writes `text` to `dir/name` and returns the path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    if let Some(parent) = p.parent() {
        std::fs::create_dir_all(parent).unwrap();
    }
    std::fs::write(&p, text).unwrap();
    p
}

/// How many of a 4×4 grid of film points over pixel (x, y) (its corners included) hit the
/// scene: 0 for a pixel that sees only what lies beyond, 16 for one wholly on a surface.
pub fn film_hits(sc: &matfit::scene::Scene, x: usize, y: usize) -> usize {
    (0..16)
        .filter(|k| {
            let film = matfit::math::Vec2::new(
                x as f32 + (k % 4) as f32 / 3.0,
                y as f32 + (k / 4) as f32 / 3.0,
            );
            sc.intersect(&sc.camera.ray(film), f32::INFINITY).is_some()
        })
        .count()
}

/// A small valid scene: a floor quad seen from above at 64 × 48 pixels, lit by a quad light,
/// to which a test may add objects.
pub fn small_room() -> SceneToml {
    SceneToml::spaced()
        .camera_above(64, 48)
        .floor(&diffuse(&[0.5]))
        .lamp(5.0)
}

/// [`small_room`]'s text.
pub fn small_scene() -> String {
    small_room().to_toml()
}

/// Fit options that make `recover` on the small scene take a second or two.
pub const QUICK: [&str; 10] = [
    "--max-iterations",
    "2",
    "--light-samples",
    "4",
    "--indirect-samples",
    "4",
    "--final-spp",
    "2",
    "--max-pixels",
    "400",
];
