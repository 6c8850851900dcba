//! Where in a scene file a loading error is, and what the user probably meant: the line of a
//! byte offset or of a [camera] key, serde's "unknown field" turned into "did you mean", and
//! the loader's context ([`Ctx`]) that every error is made from.

use super::error::SceneError;
use std::path::{Path, PathBuf};

/// 1-based line of `key = ...` inside the `[camera]` table, else of the `[camera]` header.
pub(super) fn camera_key_line(text: &str, key: &str) -> Option<usize> {
    let mut header = None;
    for (i, line) in text.lines().enumerate() {
        let l = line.trim();
        if header.is_none() {
            if l.starts_with("[camera]") {
                header = Some(i + 1);
            }
            continue;
        }
        if l.starts_with('[') {
            break;
        }
        if let Some(rest) = l.strip_prefix(key) {
            if rest.trim_start().starts_with('=') {
                return Some(i + 1);
            }
        }
    }
    header
}

/// 1-based line of a byte offset.
pub(super) fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// Words users write for a key or value of the schema, with the schema's word.
const SYNONYMS: &[(&str, &str)] = &[
    ("cube", "box"),
    ("cuboid", "box"),
    ("aabb", "box"),
    ("plane", "quad"),
    ("rectangle", "quad"),
    ("rect", "quad"),
    ("ball", "sphere"),
    ("obj", "mesh"),
    ("ply", "mesh"),
    ("fov", "fov_y_deg"),
    ("fovy", "fov_y_deg"),
    ("fov_y", "fov_y_deg"),
    ("orthogonal", "orthographic"),
    ("ortho", "orthographic"),
    ("parallel", "orthographic"),
    ("pinhole", "perspective"),
    ("position", "eye"),
    ("origin", "eye"),
    ("look_at", "target"),
    ("lookat", "target"),
    ("center_of_interest", "target"),
    ("lambert", "diffuse"),
    ("lambertian", "diffuse"),
    ("specular", "mirror"),
    ("glossy", "ward"),
    ("albedo", "rho_d"),
    ("color", "rho_d"),
    ("colour", "rho_d"),
    ("roughness", "alpha"),
    ("radiance", "emission"),
    ("emit", "emission"),
    ("samples", "spp"),
    ("size", "radius"),
];

/// Adds "did you mean `x`?" to serde's "unknown field `y`, expected one of `a`, `b`" messages.
pub(super) fn with_suggestion(msg: &str) -> String {
    let Some(pos) = msg
        .find("unknown field `")
        .or_else(|| msg.find("unknown variant `"))
    else {
        return msg.to_string();
    };
    let rest = &msg[pos..];
    let start = rest.find('`').unwrap() + 1;
    let Some(len) = rest[start..].find('`') else {
        return msg.to_string();
    };
    let bad = &rest[start..start + len];
    let candidates: Vec<&str> = rest[start + len + 1..]
        .split('`')
        .skip(1)
        .step_by(2)
        .collect();
    // A word of the same meaning first (cube → box), then the nearest spelling.
    let by_meaning = SYNONYMS
        .iter()
        .find(|(w, to)| w.eq_ignore_ascii_case(bad) && candidates.contains(to))
        .map(|(_, to)| (0, *to));
    let best = by_meaning.or_else(|| {
        candidates
            .iter()
            .map(|c| (strsim::damerau_levenshtein(bad, c), *c))
            .min()
    });
    match best {
        Some((d, c)) if d <= 3.max(bad.len() / 3) => {
            format!("{}\n(did you mean `{c}`?)", msg.trim_end())
        }
        _ => msg.to_string(),
    }
}

/// Where the loader is: the scene file's path and text (what errors point into) and its folder
/// (what relative paths in it are relative to).
pub(super) struct Ctx<'a> {
    pub(super) path: &'a Path,
    pub(super) text: &'a str,
    pub(super) dir: PathBuf,
}

impl Ctx<'_> {
    pub(super) fn at(&self, offset: usize, message: String) -> SceneError {
        SceneError::At {
            path: self.path.to_owned(),
            line: line_of(self.text, offset),
            message,
        }
    }
    /// An error at the line of `key` in the [camera] table (camera keys carry no span), or of
    /// the table itself, or of the file as a whole.
    pub(super) fn camera_at(&self, key: &str, message: String) -> SceneError {
        match camera_key_line(self.text, key) {
            Some(line) => SceneError::At {
                path: self.path.to_owned(),
                line,
                message,
            },
            None => self.whole(message),
        }
    }
    pub(super) fn whole(&self, message: String) -> SceneError {
        SceneError::Scene {
            path: self.path.to_owned(),
            message,
        }
    }
}
