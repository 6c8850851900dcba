//! The entry points of the fuzz targets (`fuzz/fuzz_targets/*.rs`, run with `cargo +nightly
//! fuzz`) and of the corpus replay in the test suite (`tests/fuzz_replay.rs`): each takes
//! arbitrary bytes, runs them through the same code as the command line, and must never panic,
//! hang or exhaust memory (an `Err` is the expected answer to most inputs).

use crate::io::image::decode_raw;
use crate::photo::{photo_from_raw, PhotoOptions, Response};
use crate::scene::load::parse_scene;
use std::path::{Path, PathBuf};

/// The folder the fuzzed scene files pretend to live in: mesh and texture files they may name
/// (`meshes/cbox_*.obj` as in scenes/cornell, `mesh.ply`, `mesh.gltf`, `tex.png`, `tex.pfm`).
pub fn fixtures_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/fuzz/fixtures"))
}

/// Scene text → checked scene, as `matfit render/recover` load it; a scene that loads is also
/// written back (as `recover` writes `recovered.toml`) and must load again.
pub fn scene_parser(data: &[u8], dir: &Path) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = dir.join("scene.toml");
    let Ok(scene) = parse_scene(text, &path) else {
        return;
    };
    // Written into another existing folder, as into `recover`'s output folder: paths are rebased.
    let out = dir.join("meshes").join("recovered.toml");
    let written = crate::scene::write::scene_to_toml(&scene, &out);
    if let Err(e) = parse_scene(&written, &out) {
        panic!("a loaded scene, written back, does not load: {e}\n{written}");
    }
}

/// Photo file bytes → linear photo with its validity mask, as `matfit recover` reads a photo
/// (checked against a camera of the photo's own size, so that every check runs). Files that
/// start with `P` are read as PFM, the others by their content; the response curve and the
/// exposure vary with the length so that all of them are exercised.
pub fn photo_loader(data: &[u8]) {
    let path = Path::new(if data.starts_with(b"P") {
        "photo.pfm"
    } else {
        "photo.img"
    });
    let Ok(raw) = decode_raw(data, path) else {
        return;
    };
    let (w, h) = (raw.image.width as u32, raw.image.height as u32);
    let opts = PhotoOptions {
        response: match data.len() % 3 {
            0 => Response::Srgb,
            1 => Response::Linear,
            _ => Response::Gamma(2.2),
        },
        exposure: data.len().is_multiple_of(2).then_some(0.5),
    };
    let _ = photo_from_raw(raw, path, w, h, &opts);
}

/// Mesh file bytes → validated triangle mesh, as a scene's `shape = "mesh"` loads one. The first
/// byte chooses the format (OBJ, PLY, glTF, GLB); the rest is the file.
pub fn mesh_loader(data: &[u8]) {
    let Some((&sel, bytes)) = data.split_first() else {
        return;
    };
    let name = ["mesh.obj", "mesh.ply", "mesh.gltf", "mesh.glb"][sel as usize % 4];
    if let Ok(mut m) = crate::scene::meshio::mesh_from_bytes(bytes, Path::new(name), None) {
        if m.validate().is_ok() {
            let _ = m.area();
        }
    }
}
