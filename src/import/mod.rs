//! Import of other renderers' scene files into matfit's TOML scene format, so that published
//! scenes can be recovered without retyping them. The inverse of [`crate::export`].

pub mod mitsuba;
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
}
