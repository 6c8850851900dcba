//! Export of a scene to other renderers' formats, so that people can keep working in their own
//! tools and so that an independent renderer can check ours (`bench/crosscheck.py`).

pub mod gltf;
pub mod mitsuba;

/// The formats `matfit export` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Mitsuba 3 scene (XML, version 3.0.0) with one binary PLY per object.
    Mitsuba,
    /// glTF 2.0 binary (.glb): meshes, metallic-roughness materials, textures, the camera.
    Gltf,
}

/// What an export wrote, and what it could not carry over exactly.
#[derive(Clone, Debug, Default)]
pub struct ExportReport {
    /// Files written, the scene file first.
    pub files: Vec<std::path::PathBuf>,
    /// One message per approximation (a material or camera the target cannot express).
    pub warnings: Vec<String>,
}
