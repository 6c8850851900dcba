//! The library's one error type: what went wrong ([`ErrorKind`]), the message a user reads,
//! and where, when a file and line are known (as pbrt's `FileLoc` or ripgrep's
//! `ignore::Error::WithLineNumber` carry it).

use std::fmt;
use std::path::{Path, PathBuf};

/// What kind of input or step failed; the Python package maps each to its own exception.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ErrorKind {
    /// The scene file or an edit: syntax, schema, meshes, textures, views.
    Scene,
    /// A photograph: unreadable, wrong size, invalid values, exposure, masks.
    Photo,
    /// The recovery itself: nothing usable to fit, a diverging fit, a checkpoint that does not
    /// match.
    Recover,
    /// Writing a scene for another renderer.
    Export,
    /// Reading or writing files other than the inputs above (outputs, checkpoints).
    Io,
    /// An option out of its range, or options that contradict each other.
    Options,
    /// The caller asked the work to stop (the observer's [`crate::Observer::cancelled`]); the
    /// last checkpoint is kept.
    Interrupted,
}

/// A file and, when known, a line in it (1-based).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    pub path: PathBuf,
    pub line: Option<usize>,
}

/// An error of any matfit call: its kind, its message (the command line prints exactly this
/// after `error: `), and the file and line it concerns when known.
#[derive(Clone, Debug)]
pub struct Error {
    kind: ErrorKind,
    message: String,
    location: Option<Location>,
}

impl Error {
    /// An error of `kind` whose message is `message`, as the user reads it.
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> Error {
        Error {
            kind,
            message: message.into(),
            location: None,
        }
    }

    /// The same error, located at `path` (and `line`, if known). The message is unchanged: the
    /// messages already name their file where a user needs it.
    pub fn at(mut self, path: impl AsRef<Path>, line: Option<usize>) -> Error {
        self.location = Some(Location {
            path: path.as_ref().to_path_buf(),
            line,
        });
        self
    }

    pub fn kind(&self) -> ErrorKind {
        self.kind
    }

    pub fn message(&self) -> &str {
        &self.message
    }

    /// The file (and line) the error concerns, when known.
    pub fn location(&self) -> Option<&Location> {
        self.location.as_ref()
    }

    pub(crate) fn scene(message: impl Into<String>) -> Error {
        Error::new(ErrorKind::Scene, message)
    }

    pub(crate) fn recover(message: impl Into<String>) -> Error {
        Error::new(ErrorKind::Recover, message)
    }

    pub(crate) fn io(message: impl Into<String>) -> Error {
        Error::new(ErrorKind::Io, message)
    }

    pub(crate) fn options(message: impl Into<String>) -> Error {
        Error::new(ErrorKind::Options, message)
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Error {}

/// For the engine's functions that still say what failed in a `String`: the message.
impl From<Error> for String {
    fn from(e: Error) -> String {
        e.message
    }
}

impl From<std::io::Error> for Error {
    fn from(e: std::io::Error) -> Error {
        Error::io(e.to_string())
    }
}

/// `Result<T, String>` of the engine's lower layers as a [`Result`] of `kind`.
pub(crate) trait Kind<T> {
    fn kind(self, kind: ErrorKind) -> Result<T, Error>;
}

impl<T> Kind<T> for Result<T, String> {
    fn kind(self, kind: ErrorKind) -> Result<T, Error> {
        self.map_err(|m| Error::new(kind, m))
    }
}

/// The result of every front-door call.
pub type Result<T, E = Error> = std::result::Result<T, E>;
