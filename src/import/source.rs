//! The XML files of one Mitsuba scene: the main file and every file it `<include>`s, each
//! upgraded to Mitsuba 3's names when it is older (version < 2.0) the way Mitsuba 3 upgrades it,
//! and the `<path>` folders that files are searched in.
//!
//! The upgrade rewrites the text in place, keeping every line where it was, so that messages
//! name the line of the file the user has: property names from camelCase to snake_case
//! (`toWorld` → `to_world`, `intIOR` → `int_ior`; not `<default>` names), a diffuse BSDF's
//! `diffuse_reflectance` → `reflectance`, and the `<lookAt>` tag → `<lookat>`. Mitsuba's other
//! upgrade, a bitmap's `uoffset`/`voffset`/`uscale`/`vscale` to a `to_uv` transform, is read
//! where bitmaps are read (`Source::old`).

use roxmltree::{Document, Node, ParsingOptions};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Includes nested deeper than this are refused (a file that includes itself, directly or not).
const MAX_DEPTH: usize = 16;

/// One XML file of the scene.
pub struct Source {
    pub path: PathBuf,
    /// The file's text, upgraded to Mitsuba 3's names.
    pub text: String,
    /// Written for Mitsuba before 2.0.
    pub old: bool,
}

/// The files of a scene and what connects them.
#[derive(Default)]
pub struct Sources {
    /// The main file first.
    pub files: Vec<Source>,
    /// (file index, an `<include>` element's text offset) → the included file's index.
    pub includes: HashMap<(usize, usize), usize>,
    /// `<path>` folders, in the order given.
    pub search: Vec<PathBuf>,
    /// Refusals found while reading the files (a missing include or folder), `FILE:LINE: why`.
    pub errors: Vec<String>,
}

pub fn options<'t>() -> ParsingOptions<'t> {
    ParsingOptions {
        allow_dtd: true,
        ..Default::default()
    }
}

/// Reads the scene whose main file has text `text` (at `path`) and every file it includes.
/// Malformed XML is an error at once (nothing after it can be read).
pub fn load(text: &str, path: &Path) -> Result<Sources, String> {
    let mut s = Sources::default();
    add(&mut s, text.to_string(), path, 0)?;
    Ok(s)
}

fn parse<'t>(text: &'t str, path: &Path) -> Result<Document<'t>, String> {
    Document::parse_with_options(text, options())
        .map_err(|e| format!("{}:{}: malformed XML: {e}", path.display(), e.pos().row))
}

fn add(s: &mut Sources, text: String, path: &Path, depth: usize) -> Result<usize, String> {
    let old = {
        let doc = parse(&text, path)?;
        doc.root_element()
            .attribute("version")
            .and_then(|v| v.split('.').next()?.trim().parse::<u32>().ok())
            .is_some_and(|major| major < 2)
    };
    let text = if old {
        upgrade(&text, &parse(&text, path)?)
    } else {
        text
    };
    let index = s.files.len();
    s.files.push(Source {
        path: path.to_path_buf(),
        text,
        old,
    });
    // The file's elements that name other files, in order: a <path> applies to what follows.
    let mut todo: Vec<(usize, String, u32)> = Vec::new();
    let mut found_files: Vec<(usize, PathBuf, u32)> = Vec::new();
    {
        let doc = parse(&s.files[index].text, path)?;
        let here = path.parent().map(Path::to_path_buf).unwrap_or_default();
        for c in doc.root_element().children().filter(Node::is_element) {
            let line = doc.text_pos_at(c.range().start).row;
            let at = |msg: String| format!("{}:{line}: {msg}", path.display());
            match c.tag_name().name() {
                "path" => match c.attribute("value") {
                    None => s
                        .errors
                        .push(at("<path> lacks its `value` attribute".into())),
                    Some(v) => {
                        let p = here.join(v);
                        if p.is_dir() {
                            s.search.push(p);
                        } else {
                            s.errors
                                .push(at(format!("<path>: folder {} not found", p.display())));
                        }
                    }
                },
                "include" => match c.attribute("filename") {
                    None => s
                        .errors
                        .push(at("<include> lacks its `filename` attribute".into())),
                    Some(f) => todo.push((c.range().start, f.to_string(), line)),
                },
                _ => {}
            }
        }
        // Each include is searched for when it is reached: the folders given before it.
        let mut resolved = Vec::new();
        for (offset, f, line) in todo {
            let found = std::iter::once(&here)
                .chain(s.search.iter())
                .map(|d| d.join(&f))
                .find(|p| p.is_file());
            resolved.push((offset, f, line, found));
        }
        for (offset, f, line, found) in resolved {
            let at = |msg: String| format!("{}:{line}: {msg}", path.display());
            match found {
                None => s.errors.push(at(format!(
                    "<include>: file {f} not found (searched {} and the <path> folders)",
                    here.display()
                ))),
                Some(_) if depth + 1 >= MAX_DEPTH => s.errors.push(at(format!(
                    "<include> of {f}: includes nest deeper than {MAX_DEPTH} (a file that \
                     includes itself?)"
                ))),
                Some(p) => found_files.push((offset, p, line)),
            }
        }
    }
    for (offset, p, line) in found_files {
        match std::fs::read_to_string(&p) {
            Ok(t) => {
                let child = add(s, t, &p, depth + 1)?;
                s.includes.insert((index, offset), child);
            }
            Err(e) => s.errors.push(format!(
                "{}:{line}: <include>: cannot read {}: {e}",
                path.display(),
                p.display()
            )),
        }
    }
    Ok(index)
}

/// Mitsuba 3's camelCase → snake_case rule: an underscore before an upper-case letter that
/// follows a lower-case one, and that run of upper-case letters lowered (`intIOR` → `int_ior`).
pub fn snake_case(name: &str) -> String {
    let c: Vec<char> = name.chars().collect();
    let mut out = String::with_capacity(name.len() + 4);
    let mut i = 0;
    while i < c.len() {
        if i > 0 && c[i - 1].is_ascii_lowercase() && c[i].is_ascii_uppercase() {
            out.push('_');
            while i < c.len() && c[i].is_ascii_uppercase() {
                out.push(c[i].to_ascii_lowercase());
                i += 1;
            }
        } else {
            out.push(c[i]);
            i += 1;
        }
    }
    out
}

/// `text` (parsed as `doc`) with Mitsuba 3's upgrade of an old file applied, byte ranges
/// replaced without adding or removing a line.
fn upgrade(text: &str, doc: &Document) -> String {
    let mut edits: Vec<(std::ops::Range<usize>, String)> = Vec::new();
    for n in doc.descendants().filter(Node::is_element) {
        let tag = n.tag_name().name();
        if tag != "default" {
            if let Some(a) = n.attributes().find(|a| a.name() == "name") {
                let mut new = snake_case(a.value());
                let parent_is_diffuse = n.parent_element().is_some_and(|p| {
                    p.tag_name().name() == "bsdf" && p.attribute("type") == Some("diffuse")
                });
                if new == "diffuse_reflectance" && parent_is_diffuse {
                    new = "reflectance".into();
                }
                if new != a.value() && !text[a.range_value()].contains('&') {
                    edits.push((a.range_value(), new));
                }
            }
        }
        if tag == "lookAt" {
            let r = n.range();
            edits.push((r.start + 1..r.start + 7, "lookat".into()));
            if text[r.clone()].ends_with("</lookAt>") {
                edits.push((r.end - 7..r.end - 1, "lookat".into()));
            }
        }
    }
    edits.sort_by_key(|e| e.0.start);
    let mut out = text.to_string();
    for (r, new) in edits.into_iter().rev() {
        out.replace_range(r, &new);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_convert_as_mitsuba_converts_them() {
        for (a, b) in [
            ("toWorld", "to_world"),
            ("sampleCount", "sample_count"),
            ("maxDepth", "max_depth"),
            ("intIOR", "int_ior"),
            ("extIOR", "ext_ior"),
            ("alphaU", "alpha_u"),
            ("diffuseReflectance", "diffuse_reflectance"),
            ("fov", "fov"),
            ("UV", "UV"),
        ] {
            assert_eq!(snake_case(a), b);
        }
    }

    #[test]
    fn the_upgrade_keeps_every_line() {
        let text = "<scene version=\"0.5.0\">\n<bsdf type=\"diffuse\">\n\
                    <rgb name=\"diffuseReflectance\" value=\"0.5\"/></bsdf>\n\
                    <sensor><transform name=\"toWorld\">\n<lookAt origin=\"0,0,1\" \
                    target=\"0,0,0\"></lookAt></transform></sensor></scene>";
        let doc = Document::parse(text).unwrap();
        let up = upgrade(text, &doc);
        assert_eq!(up.lines().count(), text.lines().count());
        assert!(up.contains("name=\"reflectance\""), "{up}");
        assert!(up.contains("name=\"to_world\""), "{up}");
        assert!(
            up.contains("<lookat origin") && up.contains("</lookat>"),
            "{up}"
        );
    }
}
