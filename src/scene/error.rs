//! Errors of scene loading: each names the file and, where there is one, the line and key or
//! the object at fault.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    // The io error is part of the message, not a `source`: a chain printer would repeat it.
    #[error("cannot read scene file {path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    /// A TOML syntax or schema error, with toml's own line/column excerpt.
    #[error("{path}: {message}")]
    Toml { path: PathBuf, message: String },
    /// A semantic error at a known line of the scene file.
    #[error("{path}:{line}: {message}")]
    At {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// A semantic error of the scene as a whole.
    #[error("{path}: {message}")]
    Scene { path: PathBuf, message: String },
}
