//! Import of other renderers' scene files into matfit's TOML scene format, so that published
//! scenes can be recovered without retyping them. The inverse of [`crate::export`].

mod mesh;
pub mod mitsuba;
mod source;
pub mod spectrum;

/// What an import produced, and what it could not carry over exactly.
#[derive(Clone, Debug, Default)]
pub struct ImportReport {
    /// The matfit scene file's text (TOML), its header comment included.
    pub toml: String,
    /// One message per approximation, each naming the element and its line.
    pub warnings: Vec<String>,
    /// Textures the scene file refers to that the import made (paths relative to its folder):
    /// copies turned to matfit's texture coordinates.
    pub textures: Vec<(String, crate::io::image::Image)>,
    /// Meshes the import made (paths relative to its folder; OBJ files' bytes): Mitsuba's
    /// serialized meshes and disks, which matfit's scene format refers to as mesh files.
    pub meshes: Vec<(String, Vec<u8>)>,
}

impl ImportReport {
    /// Writes the textures and meshes the import made into `folder` (the scene file's).
    pub fn write_files(&self, folder: &std::path::Path) -> Result<(), String> {
        let create = |path: &std::path::Path| -> Result<(), String> {
            match path.parent() {
                Some(dir) => std::fs::create_dir_all(dir)
                    .map_err(|e| format!("cannot create {}: {e}", dir.display())),
                None => Ok(()),
            }
        };
        for (name, image) in &self.textures {
            let path = folder.join(name);
            create(&path)?;
            image.write(&path)?;
        }
        for (name, bytes) in &self.meshes {
            let path = folder.join(name);
            create(&path)?;
            crate::io::atomic::write_atomic(&path, bytes)
                .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        }
        Ok(())
    }
}
