//! Helpers shared by the end-to-end tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
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

/// Writes `text` to `dir/name` and returns the path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    if let Some(parent) = p.parent() {
        std::fs::create_dir_all(parent).unwrap();
    }
    std::fs::write(&p, text).unwrap();
    p
}

/// A small valid scene: a floor quad seen from above, lit by a quad light.
pub const SMALL_SCENE: &str = r#"
[camera]
width = 64
height = 48
eye = [0.0, 2.0, 2.0]
target = [0.0, 0.0, 0.0]
fov_y_deg = 45.0

[[object]]
name = "floor"
group = "floor"
shape = "quad"
corner = [-1.0, 0.0, 1.0]
edge_u = [2.0, 0.0, 0.0]
edge_v = [0.0, 0.0, -2.0]
material = { type = "diffuse", rho_d = 0.5 }

[[object]]
name = "lamp"
group = "lamp"
shape = "quad"
corner = [-0.2, 1.5, -0.2]
edge_u = [0.4, 0.0, 0.0]
edge_v = [0.0, 0.0, 0.4]
emission = 5.0
"#;

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
