//! Import of a Mitsuba 3 scene (XML) as a matfit scene file: the inverse of
//! `export/mitsuba.rs`, for the subset of Mitsuba that matfit can render.
//!
//! Usage: `matfit import mitsuba SCENE.xml -o scene.toml [-D name=value ...]`. The scene file is
//! written with its header listing every approximation; meshes and textures the import makes
//! go to `meshes/` and `textures/` beside it. An import check over public scenes (Mitsuba's own
//! and Bitterli's) is `bench/import_public.py` (`bench/IMPORT_PUBLIC.md`).
//!
//! How each part maps (an approximation is a warning naming the element and its line; an element
//! matfit cannot render at all is an error `FILE:LINE: what`, and every such refusal of a scene
//! is reported in the same run, with the approximations found so far):
//! - **Files.** A file older than Mitsuba 2 (`version="0.5.0"`, …: Bitterli's scenes) is
//!   upgraded as Mitsuba 3 upgrades it (`import/source.rs`): camelCase property names become
//!   snake_case (`toWorld`, `sampleCount`, `maxDepth`, `intIOR`, …), a diffuse BSDF's
//!   `diffuse_reflectance` its `reflectance`, `<lookAt>` `<lookat>`, and a bitmap's
//!   `uoffset`/`voffset`/`uscale`/`vscale` its `to_uv`. `<include filename>` splices in another
//!   file (messages name its lines); `<path value>` adds a folder that files are searched in
//!   (after the main file's folder). A property of an element the import reads that it does
//!   not read itself is a warning naming it and its line (once per kind of element, with the
//!   other lines), never dropped in silence; output-only ones (`pixel_format`, `banner`,
//!   `high_quality_edges`, clipping planes, sampler seeds) change nothing and are not.
//! - **Parameters.** `<default name value>` and `$name` in any attribute (the command line's
//!   `-D name=value` wins over a default, as Mitsuba's `load_file(**params)` does).
//! - **Camera.** `perspective` (or `thinlens`, as a pinhole: a warning). Its field of view is
//!   converted to matfit's vertical one with Mitsuba's own rule (`fov_axis` x, y, diagonal,
//!   smaller, larger; `focal_length` as a 36×24 mm diagonal). `to_world` (any chain of
//!   `lookat`, `matrix`, `translate`, `rotate`, `scale`) gives eye = M·0, forward = M's third
//!   column and up = its second (the exporter's up = −R row 2, reversed); camera x in Mitsuba is
//!   the image's left, so matfit's R rows are (−c0, −c1, c2) normalised. A mirroring or shearing
//!   `to_world` is an error (matfit cameras are rotations). Principal point offsets make the
//!   calibrated form with cx = (½ − offset_x)·width − ½ and cy = (½ − offset_y)·height − ½
//!   (OpenCV pixel centres), the exporter's rule inverted; otherwise the look-at form.
//!   `orthographic` becomes `projection = "orthographic"`: `to_world`'s x and y scales are half
//!   the film's width (`width_m`), or fx, fy in the calibrated form when they differ.
//!   `hdrfilm` width/height (Mitsuba's defaults 768×576); an rfilter other than `box` is a
//!   warning (matfit's pixel filter is a box). `sampler` `sample_count` → `[render] spp`.
//! - **Integrator.** `path` (or `volpath`, the same without media) `max_depth` and `rr_depth` →
//!   `[render]`; Mitsuba's unbounded max_depth −1 becomes 64 (a warning); `hide_emitters` is a
//!   warning (matfit shows emitters).
//! - **Shapes.** `rectangle` ([−1,1]² in z = 0, facing +z) → quad corner M(−1,−1,0), edges
//!   M(2,0,0) and M(0,2,0), swapped when M mirrors or `flip_normals` is set, so that the emitting
//!   side (matfit's edge_u × edge_v) is Mitsuba's normal. `cube` ([−1,1]³) → box min/max when M
//!   keeps it axis-aligned, else a unit box with a `transform`. `sphere` (center, radius,
//!   to_world) → sphere (256 segments: the tessellation's area is 0.01% short of the sphere's),
//!   with a `transform` if M scales unevenly. `obj`/`ply` → mesh, the file referred to relative
//!   to the output scene file, `to_world` as matfit's transform (scale, rotate X→Y→Z, translate;
//!   a shear cannot be written: an error); a mesh whose triangles all have zero area (which
//!   Mitsuba loads and draws nothing of) is skipped with a warning naming its file;
//!   `face_normals` on a mesh with vertex normals writes a copy without them (matfit then
//!   shades with the triangles' normals, as Mitsuba does). `serialized` (Mitsuba's zlib
//!   format, versions 3 and 4, `shape_index`; without normals, the angle-weighted vertex
//!   normals Mitsuba makes, unless `face_normals`) and `disk` (a 256-gon, a warning) become
//!   OBJ meshes in `meshes/`, `to_world` and `flip_normals` applied to vertices and winding.
//!   `flip_normals` on an emitting box, sphere or mesh is
//!   an error (matfit emits along the wound normal, outward), elsewhere it changes nothing
//!   (matfit's surfaces reflect on both sides).
//! - **Texture coordinates.** Mitsuba reads a bitmap with v = 0 at the image's top row; matfit
//!   at its bottom row. Mitsuba's OBJ loader flips v, so an OBJ's texture is used as it is; on a
//!   PLY and a rectangle ((x + 1)/2, (y + 1)/2 of its square) the import writes the texture
//!   flipped top to bottom, and on a mirrored rectangle (whose edges matfit swaps: Mitsuba's
//!   (u, v) is matfit's (v, u)) transposed as well: linear EXRs in `textures/` beside the scene
//!   file (`ImportReport::textures`; the values matfit decodes from the source), so that every
//!   point reads what Mitsuba reads. A texture on a `cube` or `sphere`, whose coordinates differ
//!   from matfit's box and sphere, is a warning.
//! - **Textures.** `bitmap` (`filter_type` nearest and `wrap_mode` mirror/clamp are warnings:
//!   matfit's lookup is bilinear and repeats; a `to_uv` is baked into a resampled copy) and
//!   `checkerboard` (drawn into an image from Mitsuba's rule, `to_uv` included: a warning,
//!   its edges soft over one texel). A texture where matfit takes a constant (a conductor's
//!   `specular_reflectance`, a blend) gives the texture's mean, a warning.
//! - **Groups.** What matfit fits: a shape whose BSDF has an id (a `<ref>` to a shared BSDF, or
//!   an inline one with an id) is in the group named by that id, so that shapes sharing a BSDF
//!   share their reflectance; any other shape is its own group, named by its id (or
//!   `TYPE_N`, the N-th shape, when it has none). Objects are named by the shape's id; a shape
//!   without one is named after its BSDF's id if no object has that name yet (how `matfit export
//!   mitsuba` writes an object named like its group, ids being one namespace in Mitsuba), else
//!   `TYPE_N`.
//! - **Lights.** `area` emitters' `radiance` (rgb, a constant or a sampled spectrum) → emission;
//!   `directional` (irradiance), `point` and `spot` (intensity, cutoff_angle, beam_width) →
//!   `[[light]]` of the same meaning; `envmap` (filename, scale, a rotation) → `[environment]`;
//!   `constant` (radiance) → `[stray_light]`; an envmap's translation is ignored, as Mitsuba
//!   ignores it (the map is at infinity). Every other emitter is an error: the
//!   lights are known inputs of a recovery, and one dropped would bias every group.
//! - **BSDFs** (matfit's surfaces are two-sided: `twosided` is unwrapped, a one-sided BSDF is a
//!   warning). Exact: `diffuse` (reflectance rgb / constant or sampled spectrum / bitmap texture →
//!   textured; `raw` matters to 8/16-bit images only, whose matfit decoding is sRGB: a warning)
//!   → diffuse; `bumpmap`/`normalmap` → its nested BSDF (a warning: matfit has no bump
//!   maps); `mask` → its nested BSDF, opaque (a warning naming the opacity); `conductor` with material `none` → mirror ρs = specular_reflectance;
//!   `blendbsdf` of those → diffuse_mirror ρd = (1−w)·ρd₁ + w·ρd₂, ρs likewise (the exporter's
//!   blend inverted); `roughconductor` with material `none` and `distribution` "ggx" or
//!   "beckmann", alone or blended with a `diffuse` → microfacet, likewise; a textured `diffuse`
//!   blended with a specular lobe (the exporter's varnished texture) → textured, scale 1 − w,
//!   with the lobe's ρs and α as its Ward varnish (a warning where the lobe is a microfacet one:
//!   matfit's varnish is Ward's); `roughplastic` with `distribution` "ggx" or "beckmann"
//!   → plastic (ρd = diffuse_reflectance, ρs = F0·specular_reflectance, α, η = int_ior/ext_ior,
//!   a named IOR as Mitsuba's table; `nonlinear`'s ρ/(1 − ρ·F_int) as the linear model's
//!   ρd = ρ(1 − F_int)/(1 − ρ·F_int), also exact). With a bitmap `diffuse_reflectance`: the
//!   texture under the same coat (a textured material with `eta`), exact too; `nonlinear` goes
//!   into a copy of the texture in `textures/`, per texel. Initial guesses, not truth (a warning
//!   each), with ρs from Fresnel reflectance at normal incidence F0: conductors with eta/k (or a named metal, from a small
//!   table) → mirror ρs = F0·specular_reflectance; `roughconductor` → microfacet of its
//!   distribution (Ward for another) ρd 0, ρs as the conductor, α = alpha (αx, αy = alpha_u,
//!   alpha_v; Beckmann's and Ward's α are the same slope width); `plastic` → plastic with a
//!   GGX coat of the fitter's least α for the smooth one (matfit's coats are rough), η and ρs
//!   as for `roughplastic`, ρd = ρ(1 − F_c)/(1 − F_s) (F_s: ρ·F_s when `nonlinear`), F_c the
//!   rough coat's internal reflectance, F_s the smooth one's; a bitmap stays a texture, under
//!   the coat;
//!   `principled` →
//!   Ward α = roughness², F0 = 0.08·specular blended to base_color by metallic,
//!   ρd = (1−metallic)(1−F0)·base_color. Anything else
//!   (dielectrics, …) → diffuse 0.5 with a warning. A shape with no BSDF gets Mitsuba's default,
//!   diffuse 0.5; a zero reflectance is written `black`. ρd + ρs over 1 is scaled down, a
//!   plastic's ρd over 1 (its bound, `RhoBound`) lowered to 1 (a warning).
//! - **Spectra.** A sampled spectrum (wavelength:value pairs) becomes linear sRGB as Mitsuba's
//!   RGB variants convert it ([`super::spectrum`]); a warning, since a spectral render differs.
//!   A constant spectrum is grey, except on an emitter, where Mitsuba takes it as equal-energy
//!   light, pinkish in sRGB (a warning).

use super::ImportReport;
use crate::scene::schema::{
    CameraSpec, Color, EnvironmentSpec, LightKind, LightSpec, MaterialSpec, ObjectSpec,
    ProjectionKind, RenderSpec, SceneFile, ShapeKind, StrayLightSpec, TransformSpec,
};
use crate::scene::write::relative;
use crate::scene::{Distribution, RhoBound};
use glam::{DMat3, DMat4, DQuat, DVec3, DVec4, EulerRot};
use roxmltree::{Document, Node};
use std::cell::RefCell;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use toml::Spanned;

/// Reads the Mitsuba scene `xml` and returns the matfit scene file to be written at `out`
/// (mesh and texture paths relative to `out`'s folder). `params` override `<default>`s.
pub fn import(xml: &Path, out: &Path, params: &[(String, String)]) -> Result<ImportReport, String> {
    let text = std::fs::read_to_string(xml)
        .map_err(|e| format!("cannot read Mitsuba scene {}: {e}", xml.display()))?;
    import_str(&text, xml, out, params)
}

/// [`import`] of XML text as if it were the file `xml`.
pub fn import_str(
    text: &str,
    xml: &Path,
    out: &Path,
    params: &[(String, String)],
) -> Result<ImportReport, String> {
    let sources = super::source::load(text, xml)?;
    let docs = sources
        .files
        .iter()
        .map(|s| Document::parse_with_options(&s.text, super::source::options()))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| format!("{}: malformed XML after the upgrade: {e}", xml.display()))?;
    let out_dir = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut cx = Ctx {
        sources: &sources,
        docs: &docs,
        dir: xml.parent().map(Path::to_path_buf).unwrap_or_default(),
        out_dir,
        params: params.iter().cloned().collect(),
        ids: HashMap::new(),
        warnings: Vec::new(),
        errors: sources.errors.clone(),
        warned: HashSet::new(),
        reoriented: HashMap::new(),
        linearised: HashMap::new(),
        textures: Vec::new(),
        meshes: Vec::new(),
        made: HashMap::new(),
        means: HashMap::new(),
        used: RefCell::new(HashSet::new()),
        read: RefCell::new(HashSet::new()),
        failed: Vec::new(),
    };
    let file = cx.scene();
    cx.unread_properties();
    let file = match (file, cx.errors.is_empty()) {
        (Some(f), true) => f,
        _ => {
            let mut msg = match &cx.errors[..] {
                [one] => one.clone(),
                all => {
                    let mut m = format!(
                        "{}: the scene cannot be imported ({} problems):",
                        xml.display(),
                        all.len()
                    );
                    for e in all {
                        m.push_str(&format!("\n  {e}"));
                    }
                    m
                }
            };
            if !cx.warnings.is_empty() {
                msg.push_str("\nand, if these were fixed, these approximations:");
                for w in &cx.warnings {
                    msg.push_str(&format!("\n  {w}"));
                }
            }
            return Err(msg);
        }
    };
    let mut header = format!(
        "# Imported by `matfit import mitsuba` (matfit {}) from {}.\n\
         # Mapping rules: src/import/mitsuba.rs. Groups: a shape whose BSDF has an id is in the\n\
         # group of that id (shapes sharing a BSDF share a reflectance); any other shape is its own.\n",
        env!("CARGO_PKG_VERSION"),
        xml.display()
    );
    if cx.warnings.is_empty() {
        header.push_str("# Approximations: none.\n");
    } else {
        header.push_str("# Approximations:\n");
        for w in &cx.warnings {
            header.push_str(&format!("# - {}\n", w.replace('\n', " ")));
        }
    }
    let body = toml::to_string(&file).map_err(|e| format!("cannot write TOML: {e}"))?;
    Ok(ImportReport {
        toml: format!("{header}\n{}", compact(&body)),
        warnings: cx.warnings,
        textures: cx.textures,
        meshes: cx.meshes,
    })
}

struct Ctx<'a> {
    sources: &'a super::source::Sources,
    docs: &'a [Document<'a>],
    /// The main file's folder.
    dir: PathBuf,
    out_dir: PathBuf,
    params: HashMap<String, String>,
    ids: HashMap<String, Node<'a, 'a>>,
    warnings: Vec<String>,
    /// Every refusal, `FILE:LINE: why`: the import goes on past one to report them all.
    errors: Vec<String>,
    /// Elements (by text offset) already warned about, so that a shared BSDF warns once.
    warned: HashSet<(usize, &'static str)>,
    /// Re-oriented copies of textures: (source path, orientation) → the copy's path.
    reoriented: HashMap<(String, Orient), String>,
    /// A nonlinear plastic's texture, each texel ρ taken to ρ(1 − F_c)/(1 − ρ·F_s): by source
    /// path and the two F's bits, the copy's path.
    linearised: HashMap<(String, u64, u64), String>,
    /// The copies' images, to be written next to the scene file.
    textures: Vec<(String, crate::io::image::Image)>,
    /// Meshes the import made (serialized meshes, disks), to be written next to the scene file.
    meshes: Vec<(String, Vec<u8>)>,
    /// Textures the import made, by the element (and what) they were made for: a texture or
    /// BSDF shared by many shapes is made once.
    made: HashMap<((usize, usize), &'static str), String>,
    /// Textures' means, by path.
    means: HashMap<String, DVec3>,
    /// Property elements read, and the elements whose properties were read (by [`key`]): a
    /// property of a read element that nothing read is reported, never dropped in silence.
    used: RefCell<HashSet<(usize, usize)>>,
    read: RefCell<HashSet<(usize, usize)>>,
    /// Top-level elements that were refused (their unread properties say nothing more).
    failed: Vec<(usize, usize)>,
}

/// An element's identity across the scene's files: its document's address and its offset.
fn key(n: Node) -> (usize, usize) {
    (n.document() as *const _ as usize, n.range().start)
}

/// How a texture must be turned so that matfit's lookup over a shape's UVs reads what Mitsuba's
/// reads: matfit's v runs up from the image's bottom row, Mitsuba's down from its top.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Orient {
    /// Mitsuba's (u, v) is matfit's (u, v) on this shape (OBJ: Mitsuba's loader flips v).
    Same,
    /// The same (u, v) on both sides, read from opposite ends (PLY, a rectangle).
    FlipV,
    /// Mitsuba's (u, v) is matfit's (v, u) (a mirrored rectangle, whose edges matfit swaps).
    Transpose,
}

type N<'a> = Node<'a, 'a>;

/// One material as lobes, so that blends can add them: ρd (or a texture), ρs, and a Ward lobe
/// width where the specular part is not an ideal mirror.
#[derive(Clone, Debug, Default)]
struct Lobes {
    d: DVec3,
    s: DVec3,
    alpha: Option<(f64, f64)>,
    texture: Option<String>,
    /// The rough part is matfit's microfacet lobe of this distribution: a GGX or Beckmann
    /// `roughconductor` (exactly with `material = "none"`, else with Fresnel frozen at F0).
    microfacet: Option<Distribution>,
    /// A `roughplastic`: matfit's plastic with this coat's η and distribution (d and s as
    /// matfit's ρd and ρs).
    plastic: Option<(f64, Distribution)>,
}

impl Lobes {
    /// Lambert alone: no specular part, no texture.
    fn plain_diffuse(&self) -> bool {
        self.alpha.is_none() && self.texture.is_none() && self.s == DVec3::ZERO
    }
}

impl<'a> Ctx<'a> {
    fn line(&self, n: N<'a>) -> u32 {
        n.document().text_pos_at(n.range().start).row
    }

    /// The index of the file `n` is in.
    fn file_of(&self, n: N<'a>) -> usize {
        self.docs
            .iter()
            .position(|d| std::ptr::eq(d, n.document()))
            .unwrap_or(0)
    }

    fn path_of(&self, n: N<'a>) -> &Path {
        &self.sources.files[self.file_of(n)].path
    }

    fn err(&self, n: N<'a>, msg: impl std::fmt::Display) -> String {
        format!("{}:{}: {msg}", self.path_of(n).display(), self.line(n))
    }

    fn warn(&mut self, n: N<'a>, msg: impl std::fmt::Display) {
        let w = format!("{}:{}: {msg}", self.path_of(n).display(), self.line(n));
        if !self.warnings.contains(&w) {
            self.warnings.push(w);
        }
    }

    /// `<tag type=".." id="..">` as it is written, for messages.
    fn describe(&self, n: N<'a>) -> String {
        let mut s = format!("<{}", n.tag_name().name());
        for a in ["type", "id", "name"] {
            if let Some(v) = n.attribute(a) {
                s.push_str(&format!(" {a}=\"{v}\""));
            }
        }
        s + ">"
    }

    /// An attribute with `$name` parameters substituted.
    fn attr(&self, n: N<'a>, name: &str) -> Result<Option<String>, String> {
        let Some(v) = n.attribute(name) else {
            return Ok(None);
        };
        if !v.contains('$') {
            return Ok(Some(v.to_string()));
        }
        let mut out = String::new();
        let mut rest = v;
        while let Some(i) = rest.find('$') {
            out.push_str(&rest[..i]);
            let after = &rest[i + 1..];
            let len = after
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(after.len());
            let key = &after[..len];
            let value = self.params.get(key).ok_or_else(|| {
                self.err(
                    n,
                    format!(
                        "parameter ${key} has no value: add <default name=\"{key}\" value=\"...\"/> \
                         or pass -D {key}=VALUE"
                    ),
                )
            })?;
            out.push_str(value);
            rest = &after[len..];
        }
        out.push_str(rest);
        Ok(Some(out))
    }

    fn need_attr(&self, n: N<'a>, name: &str) -> Result<String, String> {
        self.attr(n, name)?.ok_or_else(|| {
            self.err(
                n,
                format!("{} lacks its `{name}` attribute", self.describe(n)),
            )
        })
    }

    fn numbers(&self, n: N<'a>, s: &str) -> Result<Vec<f64>, String> {
        s.split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
            .map(|t| {
                t.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| self.err(n, format!("'{t}' is not a finite number")))
            })
            .collect()
    }

    fn number(&self, n: N<'a>, s: &str) -> Result<f64, String> {
        match self.numbers(n, s)?[..] {
            [v] => Ok(v),
            _ => Err(self.err(n, format!("expected one number, got '{s}'"))),
        }
    }

    /// Child elements of `n` (comments and text skipped).
    fn children(n: N<'a>) -> impl Iterator<Item = N<'a>> {
        n.children().filter(|c| c.is_element())
    }

    /// The child of `n` that is property `name`, a `<ref name=...>` resolved to its element.
    fn prop(&self, n: N<'a>, name: &str) -> Result<Option<N<'a>>, String> {
        self.read.borrow_mut().insert(key(n));
        for c in Self::children(n) {
            if self.attr(c, "name")?.as_deref() == Some(name) {
                self.used.borrow_mut().insert(key(c));
                if c.tag_name().name() == "ref" {
                    return self.resolve(c).map(Some);
                }
                return Ok(Some(c));
            }
        }
        Ok(None)
    }

    fn resolve(&self, r: N<'a>) -> Result<N<'a>, String> {
        let id = self.need_attr(r, "id")?;
        self.ids.get(&id).copied().ok_or_else(|| {
            self.err(
                r,
                format!("<ref id=\"{id}\"> names no element defined before it"),
            )
        })
    }

    fn float(&self, n: N<'a>, name: &str, default: f64) -> Result<f64, String> {
        match self.prop(n, name)? {
            None => Ok(default),
            Some(p) if matches!(p.tag_name().name(), "float" | "integer") => {
                self.number(p, &self.need_attr(p, "value")?)
            }
            Some(p) => Err(self.err(
                p,
                format!("`{name}` must be a <float> here, got {}", self.describe(p)),
            )),
        }
    }

    fn string(&self, n: N<'a>, name: &str) -> Result<Option<String>, String> {
        match self.prop(n, name)? {
            None => Ok(None),
            Some(p) => self.need_attr(p, "value").map(Some),
        }
    }

    fn boolean(&self, n: N<'a>, name: &str) -> Result<bool, String> {
        match self.prop(n, name)? {
            None => Ok(false),
            Some(p) => match self.need_attr(p, "value")?.as_str() {
                "true" => Ok(true),
                "false" => Ok(false),
                v => Err(self.err(p, format!("`{name}` must be true or false, got '{v}'"))),
            },
        }
    }

    /// A point or vector: `x`, `y`, `z` attributes or `value="x, y, z"`.
    fn vec3_of(&self, n: N<'a>, default: f64) -> Result<DVec3, String> {
        if let Some(v) = self.attr(n, "value")? {
            return match self.numbers(n, &v)?[..] {
                [x, y, z] => Ok(DVec3::new(x, y, z)),
                [x] => Ok(DVec3::splat(x)),
                _ => Err(self.err(n, format!("expected three numbers, got '{v}'"))),
            };
        }
        let c = |a: &str| -> Result<f64, String> {
            match self.attr(n, a)? {
                Some(v) => self.number(n, &v),
                None => Ok(default),
            }
        };
        Ok(DVec3::new(c("x")?, c("y")?, c("z")?))
    }

    /// A colour property: rgb, spectrum (constant or sampled) or float. `Ok(None)` when absent; a bitmap
    /// texture gives `Err(path)` in the inner result (only diffuse reflectance takes one).
    fn color(&mut self, n: N<'a>, name: &str) -> Result<Option<Result<DVec3, String>>, String> {
        let Some(p) = self.prop(n, name)? else {
            return Ok(None);
        };
        match p.tag_name().name() {
            "rgb" => {
                let v = self.need_attr(p, "value")?;
                match self.numbers(p, &v)?[..] {
                    [r, g, b] => Ok(Some(Ok(DVec3::new(r, g, b)))),
                    [x] => Ok(Some(Ok(DVec3::splat(x)))),
                    _ => Err(self.err(p, format!("<rgb> needs three numbers, got '{v}'"))),
                }
            }
            "float" | "integer" => Ok(Some(Ok(DVec3::splat(
                self.number(p, &self.need_attr(p, "value")?)?,
            )))),
            "spectrum" => {
                let v = self.attr(p, "value")?.ok_or_else(|| {
                    self.err(
                        p,
                        "a <spectrum> read from a file cannot be imported: give an <rgb>",
                    )
                })?;
                let emitted = matches!(name, "radiance" | "irradiance" | "intensity");
                if !v.contains(':') {
                    let x = self.number(p, &v)?;
                    if !emitted {
                        return Ok(Some(Ok(DVec3::splat(x))));
                    }
                    let rgb = super::spectrum::uniform_emission_to_srgb(x);
                    self.warn(
                        p,
                        format!(
                            "`{name}`: constant spectrum {x} is equal-energy light, linear sRGB \
                             ({:.4}, {:.4}, {:.4}) as Mitsuba's RGB variants convert it (an \
                             <rgb> or <float> gives grey)",
                            rgb.x, rgb.y, rgb.z
                        ),
                    );
                    return Ok(Some(Ok(rgb)));
                }
                let mut samples = Vec::new();
                for pair in v.split(',') {
                    let parsed = pair.split_once(':').and_then(|(l, x)| {
                        Some((l.trim().parse::<f64>().ok()?, x.trim().parse::<f64>().ok()?))
                    });
                    match parsed {
                        Some((l, x))
                            if l.is_finite()
                                && x.is_finite()
                                && samples.last().is_none_or(|&(prev, _)| l > prev) =>
                        {
                            samples.push((l, x))
                        }
                        _ => {
                            return Err(self.err(
                                p,
                                format!(
                                    "`{name}`: '{}' is not a wavelength:value pair with the \
                                     wavelengths increasing",
                                    pair.trim()
                                ),
                            ))
                        }
                    }
                }
                let rgb = super::spectrum::to_srgb(&samples, emitted);
                self.warn(
                    p,
                    format!(
                        "`{name}`: sampled spectrum converted to linear sRGB ({:.4}, {:.4}, \
                         {:.4}) as Mitsuba's RGB variants convert it (src/import/spectrum.rs); \
                         a spectral render differs (tools/cornell_rgb.md)",
                        rgb.x, rgb.y, rgb.z
                    ),
                );
                Ok(Some(Ok(rgb)))
            }
            "texture" => self.texture(p).map(|t| Some(Err(t))),
            _ => Err(self.err(p, format!("`{name}` cannot be a {}", self.describe(p)))),
        }
    }

    /// A colour property that must be a constant: a texture gives its mean (a warning).
    fn rgb(&mut self, n: N<'a>, name: &str, default: f64) -> Result<DVec3, String> {
        match self.color(n, name)? {
            None => Ok(DVec3::splat(default)),
            Some(Ok(c)) => Ok(c),
            Some(Err(t)) => {
                let p = self.prop(n, name)?.unwrap_or(n);
                let mean = self.texture_mean(p, &t)?;
                self.warn(
                    p,
                    format!(
                        "a texture for `{name}` of {}: matfit has no texture there, its mean \
                         ({:.4}, {:.4}, {:.4}) instead",
                        self.describe(n),
                        mean.x,
                        mean.y,
                        mean.z
                    ),
                );
                Ok(mean)
            }
        }
    }

    /// A `<texture>`: `bitmap` (its file, or a copy the import made when `to_uv` moves it) or
    /// `checkerboard` (an image the import draws), as a path relative to the output's folder
    /// in Mitsuba's orientation (v = 0 at the top row; the shape turns it, [`Self::reoriented`]).
    fn texture(&mut self, p: N<'a>) -> Result<String, String> {
        if let Some(t) = self.made.get(&(key(p), "texture")) {
            return Ok(t.clone());
        }
        let t = self.make_texture(p)?;
        self.made.insert((key(p), "texture"), t.clone());
        Ok(t)
    }

    fn make_texture(&mut self, p: N<'a>) -> Result<String, String> {
        let ty = self.need_attr(p, "type")?;
        let to_uv = self.uv_transform(p)?;
        match ty.as_str() {
            "bitmap" => {
                let f = self.string(p, "filename")?.ok_or_else(|| {
                    self.err(p, "a bitmap texture needs <string name=\"filename\">")
                })?;
                let float = crate::io::image::is_float_format(Path::new(&f));
                // A float image is linear in both renderers; raw changes 8/16-bit ones only.
                if self.boolean(p, "raw")? && !float {
                    self.warn(
                        p,
                        "raw=\"true\" bitmap: matfit decodes 8-bit textures as sRGB, Mitsuba \
                         reads this one as linear",
                    );
                }
                match self.string(p, "filter_type")?.as_deref() {
                    None | Some("bilinear") => {}
                    Some("nearest") => self.warn(
                        p,
                        "filter_type \"nearest\": matfit's texture lookup is bilinear (the same \
                         at texel centres, smoother between them)",
                    ),
                    Some(o) => {
                        return Err(self.err(
                            p,
                            format!("filter_type '{o}' is not one of bilinear, nearest"),
                        ))
                    }
                }
                match self.string(p, "wrap_mode")?.as_deref() {
                    None | Some("repeat") => {}
                    Some(w @ ("mirror" | "clamp")) => self.warn(
                        p,
                        format!(
                            "wrap_mode \"{w}\": matfit's textures repeat (the same wherever \
                             texture coordinates stay in [0, 1])"
                        ),
                    ),
                    Some(o) => {
                        return Err(self.err(
                            p,
                            format!("wrap_mode '{o}' is not one of repeat, mirror, clamp"),
                        ))
                    }
                }
                let file = self.file_ref(p, &f)?;
                if to_uv == DMat4::IDENTITY {
                    return Ok(file);
                }
                let src = self.texture_image(p, &file)?;
                let stretch = [to_uv.x_axis, to_uv.y_axis]
                    .map(|c| c.truncate().truncate().length().ceil().max(1.0) as usize);
                let (w, h) = (src.width * stretch[0], src.height * stretch[1]);
                if w.max(h) > 8192 {
                    self.warn(
                        p,
                        format!(
                            "to_uv repeats the texture {}×{} times: more texels than matfit \
                             draws ({w}×{h}); to_uv ignored",
                            stretch[0], stretch[1]
                        ),
                    );
                    return Ok(file);
                }
                let image = resample(w, h, |uv| bilinear_mitsuba(&src, uv), to_uv);
                let stem = Path::new(&f)
                    .file_stem()
                    .map(|s| sanitize(&s.to_string_lossy()))
                    .unwrap_or_default();
                Ok(self.generated(&format!("{stem}_uv"), image))
            }
            "checkerboard" => {
                let c0 = self.rgb(p, "color0", 0.4)?;
                let c1 = self.rgb(p, "color1", 0.2)?;
                // Enough texels per check that the bilinear lookup softens only its edges.
                let checks = [to_uv.x_axis, to_uv.y_axis]
                    .map(|c| c.truncate().truncate().length().max(1.0))
                    .iter()
                    .fold(1.0f64, |a, &b| a.max(b));
                let res = ((64.0 * checks) as usize).clamp(128, 4096);
                self.warn(
                    p,
                    format!(
                        "checkerboard drawn as a {res}×{res} texture (its edges soft over one \
                         texel)"
                    ),
                );
                let image = resample(
                    res,
                    res,
                    |uv| {
                        let fx = uv[0] - uv[0].floor() > 0.5;
                        let fy = uv[1] - uv[1].floor() > 0.5;
                        let c = if fx == fy { c0 } else { c1 };
                        crate::math::Rgb::new(c.x as f32, c.y as f32, c.z as f32)
                    },
                    to_uv,
                );
                Ok(self.generated("checkerboard", image))
            }
            _ => Err(self.err(
                p,
                format!("texture type '{ty}' is not supported (bitmap and checkerboard are)"),
            )),
        }
    }

    /// A texture's `to_uv` (Mitsuba 3) or, in an old file, its uoffset/voffset/uscale/vscale
    /// (scale after offset, as Mitsuba's upgrade builds it), as a matrix on (u, v, 0, 1).
    fn uv_transform(&self, p: N<'a>) -> Result<DMat4, String> {
        let mut m = self.transform(p, "to_uv")?;
        if self.sources.files[self.file_of(p)].old {
            let offset = DVec3::new(
                self.float(p, "uoffset", 0.0)?,
                self.float(p, "voffset", 0.0)?,
                0.0,
            );
            let scale = DVec3::new(
                self.float(p, "uscale", 1.0)?,
                self.float(p, "vscale", 1.0)?,
                1.0,
            );
            m = DMat4::from_scale(scale) * DMat4::from_translation(offset) * m;
        }
        Ok(m)
    }

    /// An image the import made, to be written as `textures/{stem}_N.exr`: its path.
    fn generated(&mut self, stem: &str, image: crate::io::image::Image) -> String {
        let name = format!("textures/{stem}_{}.exr", self.textures.len());
        self.textures.push((name.clone(), image));
        name
    }

    /// The image of a texture path (one the import made, or a file relative to the output).
    fn texture_image(&self, n: N<'a>, path: &str) -> Result<crate::io::image::Image, String> {
        if let Some((_, i)) = self.textures.iter().find(|(p, _)| p == path) {
            return Ok(i.clone());
        }
        crate::io::image::read_linear(&self.out_dir.join(path))
            .map_err(|e| self.err(n, format!("texture: {e}")))
    }

    /// The mean of a texture's texels; kept, as shared BSDFs ask again.
    fn texture_mean(&mut self, n: N<'a>, path: &str) -> Result<DVec3, String> {
        if let Some(m) = self.means.get(path) {
            return Ok(*m);
        }
        let i = self.texture_image(n, path)?;
        let sum = i.data.iter().fold(DVec3::ZERO, |a, c| {
            a + DVec3::new(c.x as f64, c.y as f64, c.z as f64)
        });
        let mean = sum / (i.data.len().max(1) as f64);
        self.means.insert(path.to_string(), mean);
        Ok(mean)
    }

    /// A copy of the texture at `path` with each texel ρ taken to ρ(1 − f_c)/(1 − ρ·f_s): a
    /// nonlinear plastic's base as matfit's coat's (f_c its internal reflectance, f_s the
    /// plastic's; the same for a `roughplastic`), as a linear EXR in `textures/`.
    fn linearised(&mut self, n: N<'a>, path: &str, f_c: f64, f_s: f64) -> Result<String, String> {
        let key = (path.to_string(), f_c.to_bits(), f_s.to_bits());
        if let Some(p) = self.linearised.get(&key) {
            return Ok(p.clone());
        }
        let mut image = self.texture_image(n, path)?;
        let g = |r: f32| (r as f64 * (1.0 - f_c) / (1.0 - r as f64 * f_s)) as f32;
        for t in image.data.iter_mut() {
            *t = crate::math::Rgb::new(g(t.x), g(t.y), g(t.z));
        }
        let stem = Path::new(path)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut name = format!("textures/{stem}_linear.exr");
        if self.textures.iter().any(|(n, _)| *n == name) {
            name = format!("textures/{stem}_linear_{}.exr", self.textures.len());
        }
        self.textures.push((name.clone(), image));
        self.linearised.insert(key, name.clone());
        Ok(name)
    }

    /// A file named in the XML, found as Mitsuba finds it (relative to the main file's folder,
    /// the `<path>` folders, or the folder of the file that names it), as an absolute path.
    fn find_file(&self, n: N<'a>, f: &str) -> Result<PathBuf, String> {
        let own = self
            .path_of(n)
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default();
        let dirs: Vec<&PathBuf> = std::iter::once(&self.dir)
            .chain(self.sources.search.iter())
            .chain(std::iter::once(&own))
            .collect();
        for d in &dirs {
            let p = d.join(f);
            if p.is_file() {
                return Ok(std::path::absolute(&p).unwrap_or(p));
            }
        }
        let abs = std::path::absolute(self.dir.join(f)).unwrap_or_else(|_| self.dir.join(f));
        Err(self.err(
            n,
            format!(
                "file {} not found{}",
                abs.display(),
                if self.sources.search.is_empty() {
                    String::new()
                } else {
                    format!(" (nor in the {} <path> folders)", self.sources.search.len())
                }
            ),
        ))
    }

    /// A file named in the XML, as a path relative to the output file.
    fn file_ref(&self, n: N<'a>, f: &str) -> Result<String, String> {
        let abs = self.find_file(n, f)?;
        let base = std::path::absolute(&self.out_dir).unwrap_or_else(|_| self.out_dir.clone());
        Ok(relative(&abs, &base)
            .unwrap_or(abs)
            .to_string_lossy()
            .into_owned())
    }

    /// The `<transform name=name>` child of `n` as a matrix (identity when absent). Each
    /// operation applies after the ones before it, as in Mitsuba.
    fn transform(&self, n: N<'a>, name: &str) -> Result<DMat4, String> {
        let Some(t) = self.prop(n, name)? else {
            return Ok(DMat4::IDENTITY);
        };
        if t.tag_name().name() != "transform" {
            return Err(self.err(t, format!("`{name}` must be a <transform>")));
        }
        let mut m = DMat4::IDENTITY;
        for op in Self::children(t) {
            let step = match op.tag_name().name() {
                "translate" => DMat4::from_translation(self.vec3_of(op, 0.0)?),
                "scale" => DMat4::from_scale(self.vec3_of(op, 1.0)?),
                "rotate" => {
                    let axis = self.vec3_of(op, 0.0)?;
                    let angle = self.number(op, &self.need_attr(op, "angle")?)?;
                    if axis.length() == 0.0 {
                        return Err(self.err(op, "<rotate> needs a non-zero axis"));
                    }
                    DMat4::from_axis_angle(axis.normalize(), angle.to_radians())
                }
                "matrix" => {
                    let v = self.numbers(op, &self.need_attr(op, "value")?)?;
                    match v.len() {
                        16 => DMat4::from_cols_slice(&v).transpose(),
                        9 => DMat4::from_mat3(DMat3::from_cols_slice(&v).transpose()),
                        k => {
                            return Err(
                                self.err(op, format!("<matrix> needs 16 (or 9) numbers, got {k}"))
                            )
                        }
                    }
                }
                "lookat" => {
                    let p = |a: &str| -> Result<Option<DVec3>, String> {
                        match self.attr(op, a)? {
                            None => Ok(None),
                            Some(v) => match self.numbers(op, &v)?[..] {
                                [x, y, z] => Ok(Some(DVec3::new(x, y, z))),
                                _ => Err(self.err(op, format!("`{a}` needs three numbers"))),
                            },
                        }
                    };
                    let origin = p("origin")?.unwrap_or(DVec3::ZERO);
                    let target = p("target")?.unwrap_or(DVec3::Z);
                    let dir = (target - origin).normalize_or_zero();
                    let up = p("up")?.unwrap_or_else(|| dir.any_orthonormal_vector());
                    let left = up.cross(dir).normalize_or_zero();
                    if dir == DVec3::ZERO || left == DVec3::ZERO {
                        return Err(self.err(
                            op,
                            "<lookat> has origin = target or up parallel to the view direction",
                        ));
                    }
                    let new_up = dir.cross(left);
                    DMat4::from_cols(
                        left.extend(0.0),
                        new_up.extend(0.0),
                        dir.extend(0.0),
                        origin.extend(1.0),
                    )
                }
                other => return Err(self.err(op, format!("unknown transform operation <{other}>"))),
            };
            m = step * m;
        }
        Ok(m)
    }

    /// The scene's top-level elements, each `<include>` replaced by the included file's.
    fn top_level(&self, root: N<'a>, out: &mut Vec<N<'a>>) {
        for c in Self::children(root) {
            if c.tag_name().name() != "include" {
                out.push(c);
                continue;
            }
            let at = (self.file_of(c), c.range().start);
            if let Some(&i) = self.sources.includes.get(&at) {
                let r = self.docs[i].root_element();
                if r.tag_name().name() == "scene" {
                    self.top_level(r, out);
                } else {
                    out.push(r);
                }
            }
        }
    }

    /// The scene, or None when something was refused (each refusal is in `errors`).
    fn scene(&mut self) -> Option<SceneFile> {
        let root = self.docs[0].root_element();
        if root.tag_name().name() != "scene" {
            let e = self.err(
                root,
                format!(
                    "expected a <scene> root element, got <{}>",
                    root.tag_name().name()
                ),
            );
            self.errors.push(e);
            return None;
        }
        let mut top = Vec::new();
        self.top_level(root, &mut top);
        // Defaults first (the command line's values win), then ids of every element.
        for &c in &top {
            if c.tag_name().name() == "default" {
                let kv = self
                    .need_attr(c, "name")
                    .and_then(|k| Ok((k, self.need_attr(c, "value")?)));
                match kv {
                    Ok((k, v)) => {
                        self.params.entry(k).or_insert(v);
                    }
                    Err(e) => self.errors.push(e),
                }
            }
        }
        for d in self.docs.iter().flat_map(|d| d.descendants()) {
            if !d.is_element() {
                continue;
            }
            match self.attr(d, "id") {
                Ok(Some(id)) => {
                    if d.tag_name().name() != "ref" && self.ids.insert(id.clone(), d).is_some() {
                        let e = self.err(d, format!("id '{id}' is defined twice"));
                        self.errors.push(e);
                    }
                }
                Ok(None) => {}
                Err(e) => self.errors.push(e),
            }
        }

        let mut camera = None;
        let mut sensors = 0;
        let mut render = RenderSpec::default();
        let mut objects = Vec::new();
        let mut shapes = 0;
        let mut lights = Vec::new();
        let mut environment = None;
        let mut stray_light = None;
        let mut names = HashSet::new();
        let mut shape_counts: HashMap<String, usize> = HashMap::new();
        for c in top {
            let done: Result<(), String> = (|| {
                match c.tag_name().name() {
                    "default" | "bsdf" | "texture" | "path" | "include" => {}
                    "integrator" => self.integrator(c, &mut render)?,
                    "sensor" => {
                        sensors += 1;
                        if sensors > 1 {
                            self.warn(c, "a second <sensor> is ignored (matfit uses the first)");
                            return Ok(());
                        }
                        let (cam, spp) = self.sensor(c)?;
                        camera = Some(cam);
                        render.spp = spp;
                    }
                    "shape" => {
                        shapes += 1;
                        let ty = self.need_attr(c, "type")?;
                        let k = shape_counts.entry(ty.clone()).or_default();
                        *k += 1;
                        let mut name = match self.attr(c, "id")? {
                            Some(id) => id,
                            None => match self.bsdf_id(c)? {
                                Some(b) if !names.contains(&b) => b,
                                _ => format!("{ty}_{k}"),
                            },
                        };
                        while !names.insert(name.clone()) {
                            name.push('_');
                        }
                        if let Some(o) = self.shape(c, &ty, name)? {
                            objects.push(o);
                        }
                    }
                    "emitter" if self.attr(c, "type")?.as_deref() == Some("envmap") => {
                        let env = self.envmap(c)?;
                        if environment.is_some() {
                            return Err(
                                self.err(c, "a second envmap: matfit takes one environment")
                            );
                        }
                        environment = Some(Spanned::new(0..0, env));
                    }
                    "emitter" if self.attr(c, "type")?.as_deref() == Some("constant") => {
                        let r = f32s(self.rgb(c, "radiance", 1.0)?);
                        if stray_light.is_some() {
                            return Err(self.err(c, "a second constant emitter: matfit takes one"));
                        }
                        stray_light = Some(Spanned::new(0..0, StrayLightSpec { radiance: r }));
                    }
                    // An area emitter defined for shapes to refer to (`<ref id=.../>`).
                    "emitter"
                        if self.attr(c, "type")?.as_deref() == Some("area")
                            && self.attr(c, "id")?.is_some() => {}
                    "emitter" => {
                        let k = lights.len() + 1;
                        lights.push(self.emitter(c, k)?);
                    }
                    other => self.warn(c, format!("<{other}> is ignored")),
                }
                Ok(())
            })();
            if let Err(e) = done {
                self.failed.push(key(c));
                if !self.errors.contains(&e) {
                    self.errors.push(e);
                }
            }
        }
        if sensors == 0 {
            let e = self.err(root, "the scene has no <sensor>");
            self.errors.push(e);
        }
        if shapes == 0 {
            let e = self.err(root, "the scene has no <shape>");
            self.errors.push(e);
        } else if objects.is_empty() && self.errors.is_empty() {
            let e = self.err(
                root,
                "every <shape> of the scene was skipped (warnings above)",
            );
            self.errors.push(e);
        }
        Some(SceneFile {
            render: Some(render),
            camera: camera?,
            groups: Vec::new(),
            objects,
            lights,
            environment,
            stray_light,
            views: Vec::new(),
        })
    }

    /// Warns of every property of an element the import read that it did not read itself:
    /// Mitsuba would use it, so matfit's scene may differ where it matters.
    fn unread_properties(&mut self) {
        const PROPERTY_TAGS: [&str; 11] = [
            "float",
            "integer",
            "boolean",
            "string",
            "rgb",
            "spectrum",
            "point",
            "vector",
            "transform",
            "texture",
            "ref",
        ];
        // What changes nothing in a matfit scene: output formats, clipping planes and
        // samplers' seeds (matfit's film, camera and sampler have none).
        const HARMLESS: [&str; 10] = [
            "pixel_format",
            "component_format",
            "file_format",
            "banner",
            "high_quality_edges",
            "near_clip",
            "far_clip",
            "seed",
            "jitter",
            "sample_border",
        ];
        let read = self.read.borrow().clone();
        let used = self.used.borrow().clone();
        type Unread = ((usize, String, String, String), Vec<u32>);
        let mut unread: Vec<Unread> = Vec::new();
        let docs = self.docs;
        for e in docs.iter().flat_map(|d| d.descendants()) {
            if !e.is_element() || !PROPERTY_TAGS.contains(&e.tag_name().name()) {
                continue;
            }
            let (Some(parent), Some(name)) = (e.parent_element(), e.attribute("name")) else {
                continue;
            };
            if !read.contains(&key(parent))
                || used.contains(&key(e))
                || HARMLESS.contains(&name)
                || (e.tag_name().name() == "ref" && name == "bsdf")
                || e.ancestors().any(|a| self.failed.contains(&key(a)))
            {
                continue;
            }
            let what = (
                self.file_of(e),
                name.to_string(),
                self.describe(e),
                format!(
                    "<{} type=\"{}\">",
                    parent.tag_name().name(),
                    parent.attribute("type").unwrap_or("")
                ),
            );
            let line = self.line(e);
            match unread.iter_mut().find(|(w, _)| *w == what) {
                Some((_, lines)) => lines.push(line),
                None => unread.push((what, vec![line])),
            }
        }
        // One warning per property of a kind of element, at its first line.
        for ((file, name, prop, parent), lines) in unread {
            let more = match lines.len() {
                1 => String::new(),
                k => format!(
                    " (on {k} elements, lines {}{})",
                    lines
                        .iter()
                        .take(8)
                        .map(u32::to_string)
                        .collect::<Vec<_>>()
                        .join(", "),
                    if k > 8 { ", …" } else { "" }
                ),
            };
            self.warnings.push(format!(
                "{}:{}: property `{name}` ({prop}) of {parent} is not read by matfit's \
                 import: ignored{more}",
                self.sources.files[file].path.display(),
                lines[0]
            ));
        }
    }

    /// A light outside any shape: `directional`, `point` or `spot` (Mitsuba 3's meanings, which
    /// are matfit's `[[light]]`s'); positions and directions from `to_world` or from the
    /// `position`/`direction` shortcuts.
    fn emitter(&mut self, n: N<'a>, k: usize) -> Result<LightSpec, String> {
        let ty = self.need_attr(n, "type")?;
        let name = self.attr(n, "id")?.unwrap_or_else(|| format!("{ty}_{k}"));
        let m = self.transform(n, "to_world")?;
        let vector = |s: &Self, key: &str| -> Result<Option<DVec3>, String> {
            s.prop(n, key)?.map(|p| s.vec3_of(p, 0.0)).transpose()
        };
        let position = match vector(self, "position")? {
            Some(p) => p,
            None => m.transform_point3(DVec3::ZERO),
        };
        let axis = match vector(self, "direction")? {
            Some(d) => d,
            None => m.transform_vector3(DVec3::Z),
        };
        let mut spec = LightSpec {
            name: Spanned::new(0..0, name),
            kind: Spanned::new(0..0, LightKind::Point),
            direction: None,
            irradiance: None,
            position: None,
            target: None,
            intensity: None,
            cutoff_deg: None,
            beam_width_deg: None,
            angle_deg: None,
        };
        let rgb = |v: DVec3| Color(f32s(v));
        match ty.as_str() {
            "directional" => {
                spec.kind = Spanned::new(0..0, LightKind::Directional);
                spec.direction = Some(f32s(axis));
                spec.irradiance = Some(rgb(self.rgb(n, "irradiance", 1.0)?));
            }
            "point" => {
                spec.position = Some(f32s(position));
                spec.intensity = Some(rgb(self.rgb(n, "intensity", 1.0)?));
            }
            "spot" => {
                spec.kind = Spanned::new(0..0, LightKind::Spot);
                spec.position = Some(f32s(position));
                spec.direction = Some(f32s(axis));
                spec.intensity = Some(rgb(self.rgb(n, "intensity", 1.0)?));
                let cutoff = self.float(n, "cutoff_angle", 20.0)?;
                spec.cutoff_deg = Some(cutoff as f32);
                spec.beam_width_deg = Some(self.float(n, "beam_width", 0.75 * cutoff)? as f32);
                if self.prop(n, "texture")?.is_some() {
                    return Err(self.err(n, "a textured spot light cannot be imported"));
                }
            }
            _ => {
                return Err(self.err(
                    n,
                    format!(
                        "emitter type '{ty}' cannot be imported: matfit's lights are emitting \
                         surfaces (an area emitter inside a <shape>), directional, point and \
                         spot lights, an envmap and a constant emitter (its stray light)"
                    ),
                ))
            }
        }
        Ok(spec)
    }

    /// An `envmap` emitter: its file, scale and rotation (`to_world`'s 3×3 part must be a
    /// rotation; its translation is ignored, as Mitsuba ignores it: the map is at infinity).
    fn envmap(&mut self, n: N<'a>) -> Result<EnvironmentSpec, String> {
        let f = self
            .string(n, "filename")?
            .ok_or_else(|| self.err(n, "an envmap needs <string name=\"filename\">"))?;
        let file = self.file_ref(n, &f)?;
        let scale = self.float(n, "scale", 1.0)? as f32;
        let m = self.transform(n, "to_world")?;
        let mut m = m;
        m.w_axis = DVec4::W;
        let t = decompose(m)
            .filter(|t| {
                let unit = |c: &Color| c.0.iter().all(|x| (x - 1.0).abs() < 1e-4);
                t.scale.as_ref().is_none_or(unit)
            })
            .ok_or_else(|| {
                self.err(
                    n,
                    "an envmap's to_world must be a rotation (and a translation, which is \
                     ignored): it scales, mirrors or shears",
                )
            })?;
        Ok(EnvironmentSpec {
            file,
            scale: (scale != 1.0).then_some(scale),
            rotate_deg: t.rotate_deg,
        })
    }

    fn integrator(&mut self, n: N<'a>, render: &mut RenderSpec) -> Result<(), String> {
        let ty = self.need_attr(n, "type")?;
        if !matches!(ty.as_str(), "path" | "volpath") {
            self.warn(
                n,
                format!("integrator '{ty}' is rendered as matfit's path tracer (Mitsuba's `path`)"),
            );
            return Ok(());
        }
        let depth = self.float(n, "max_depth", -1.0)?;
        render.max_depth = Some(if depth < 0.0 {
            self.warn(
                n,
                "max_depth -1 (unbounded) becomes 64; paths end by Russian roulette long before",
            );
            64
        } else {
            depth as u32
        });
        render.rr_depth = Some(self.float(n, "rr_depth", 5.0)?.max(1.0) as u32);
        if self.boolean(n, "hide_emitters")? {
            self.warn(n, "hide_emitters: matfit's images show the emitters");
        }
        Ok(())
    }

    fn sensor(&mut self, n: N<'a>) -> Result<(CameraSpec, Option<u32>), String> {
        let ty = self.need_attr(n, "type")?;
        match ty.as_str() {
            "perspective" | "orthographic" => {}
            "thinlens" => self.warn(n, "thinlens sensor imported as a pinhole (no defocus)"),
            _ => {
                return Err(self.err(
                    n,
                    format!(
                        "sensor type '{ty}' is not supported (only perspective and orthographic)"
                    ),
                ))
            }
        }
        let film = Self::children(n).find(|c| c.tag_name().name() == "film");
        let (mut w, mut h) = (768u32, 576u32);
        if let Some(f) = film {
            let size = |cx: &Self, key: &str, d: u32| -> Result<u32, String> {
                let v = cx.float(f, key, d as f64)?;
                if !(1.0..=65536.0).contains(&v) {
                    return Err(cx.err(f, format!("film {key} must be 1 to 65536, got {v}")));
                }
                Ok(v as u32)
            };
            w = size(self, "width", w)?;
            h = size(self, "height", h)?;
            match Self::children(f).find(|c| c.tag_name().name() == "rfilter") {
                Some(r) if self.attr(r, "type")?.as_deref() == Some("box") => {}
                // A wider filter blurs a sharp highlight or edge into the pixels beside it,
                // which matfit's box keeps out: pixels there differ, and the image with them.
                Some(r) => self.warn(
                    r,
                    "pixel filter is not a box: matfit's is (Mitsuba's spreads a sharp \
                     highlight or edge into neighbouring pixels)",
                ),
                None => self.warn(
                    f,
                    "no rfilter: Mitsuba's default is gaussian, matfit's pixel filter is a box \
                     (Mitsuba's spreads a sharp highlight or edge into neighbouring pixels)",
                ),
            }
            if self.prop(f, "crop_width")?.is_some() || self.prop(f, "crop_offset_x")?.is_some() {
                self.warn(f, "the film's crop window is ignored");
            }
        }
        let spp = match Self::children(n).find(|c| c.tag_name().name() == "sampler") {
            Some(s) => {
                let v = self.float(s, "sample_count", 4.0)?;
                if !(v >= 1.0) {
                    return Err(self.err(s, "sample_count must be at least 1"));
                }
                Some(v as u32)
            }
            None => None,
        };
        let aspect = w as f64 / h as f64;
        let m = self.transform(n, "to_world")?;
        if ty == "orthographic" {
            return Ok((self.orthographic(n, m, w, h)?, spp));
        }
        let fov_x = self.fov_x(n, aspect)?;
        let fov_y = 2.0 * ((0.5 * fov_x.to_radians()).tan() / aspect).atan();

        let eye = m.w_axis.truncate();
        let ([right, down, fwd], [l0, l1, l2]) = self.sensor_frame(n, &m)?;
        if (l0 - l1).abs() > 1e-6 * l0 || (l1 - l2).abs() > 1e-6 * l1 {
            self.warn(
                n,
                "the sensor's to_world scales unevenly; its scale is ignored",
            );
        }
        let off_x = self.float(n, "principal_point_offset_x", 0.0)?;
        let off_y = self.float(n, "principal_point_offset_y", 0.0)?;
        let cam = if off_x == 0.0 && off_y == 0.0 {
            CameraSpec {
                width: w,
                height: h,
                eye: Some(f32s(eye)),
                target: Some(f32s(eye + fwd)),
                up: Some(f32s(-down)),
                fov_y_deg: Some(fov_y.to_degrees() as f32),
                ..Default::default()
            }
        } else {
            let r = DMat3::from_cols(right, down, fwd).transpose();
            let t = -(r * eye);
            let fy = 0.5 * h as f64 / (0.5 * fov_y).tan();
            let rows = [r.row(0), r.row(1), r.row(2)].map(|v| v.as_vec3().to_array());
            CameraSpec {
                width: w,
                height: h,
                fx: Some(fy as f32),
                fy: Some(fy as f32),
                cx: Some(((0.5 - off_x) * w as f64 - 0.5) as f32),
                cy: Some(((0.5 - off_y) * h as f64 - 0.5) as f32),
                rotation: Some(rows),
                translation: Some(f32s(t)),
                ..Default::default()
            }
        };
        Ok((cam, spp))
    }

    /// A sensor's `to_world` as matfit's camera axes (right, down, forward; module comment) and
    /// the lengths of its three columns, or an error if it shears, collapses or mirrors.
    fn sensor_frame(&self, n: N<'a>, m: &DMat4) -> Result<([DVec3; 3], [f64; 3]), String> {
        let (c0, c1, c2) = (
            m.x_axis.truncate(),
            m.y_axis.truncate(),
            m.z_axis.truncate(),
        );
        let (l0, l1, l2) = (c0.length(), c1.length(), c2.length());
        let shear = [(c0, c1), (c1, c2), (c0, c2)]
            .iter()
            .map(|(a, b)| a.dot(*b).abs() / (a.length() * b.length()).max(1e-300))
            .fold(0.0f64, f64::max);
        if !(l0 > 0.0 && l1 > 0.0 && l2 > 0.0) || shear > 1e-4 {
            return Err(self.err(n, "the sensor's to_world shears or collapses the view"));
        }
        if DMat3::from_cols(c0, c1, c2).determinant() < 0.0 {
            return Err(self.err(
                n,
                "the sensor's to_world mirrors the image (a negative scale): matfit's cameras \
                 cannot",
            ));
        }
        Ok(([-c0 / l0, -c1 / l1, c2 / l2], [l0, l1, l2]))
    }

    /// An `orthographic` sensor: its `to_world` scales local [−1, 1] × [−1/aspect, 1/aspect]
    /// to the film (the inverse of the export's `write_orthographic_sensor`), and its rays start
    /// `near_clip` along the view, where matfit's film plane goes.
    fn orthographic(&self, n: N<'a>, m: DMat4, w: u32, h: u32) -> Result<CameraSpec, String> {
        let ([right, down, fwd], [l0, l1, _]) = self.sensor_frame(n, &m)?;
        let near = self.float(n, "near_clip", 0.01)?;
        let centre = m.w_axis.truncate() + fwd * near;
        let (fx, fy) = (w as f64 / (2.0 * l0), w as f64 / (2.0 * l1));
        Ok(if (l0 - l1).abs() <= 1e-6 * l0 {
            CameraSpec {
                width: w,
                height: h,
                eye: Some(f32s(centre)),
                target: Some(f32s(centre + fwd)),
                up: Some(f32s(-down)),
                projection: Some(ProjectionKind::Orthographic),
                width_m: Some((2.0 * l0) as f32),
                ..Default::default()
            }
        } else {
            let r = DMat3::from_cols(right, down, fwd).transpose();
            let rows = [r.row(0), r.row(1), r.row(2)].map(|v| v.as_vec3().to_array());
            CameraSpec {
                width: w,
                height: h,
                fx: Some(fx as f32),
                fy: Some(fy as f32),
                cx: Some(0.5 * w as f32 - 0.5),
                cy: Some(0.5 * h as f32 - 0.5),
                rotation: Some(rows),
                translation: Some(f32s(-(r * centre))),
                projection: Some(ProjectionKind::Orthographic),
                ..Default::default()
            }
        })
    }

    /// Mitsuba's horizontal field of view in degrees (its `parse_fov`).
    fn fov_x(&mut self, n: N<'a>, aspect: f64) -> Result<f64, String> {
        let fov = self.prop(n, "fov")?;
        let (value, axis) = match (fov, self.string(n, "focal_length")?) {
            (Some(_), Some(_)) => {
                return Err(self.err(n, "give either `fov` or `focal_length`, not both"))
            }
            (Some(_), None) => {
                let v = self.float(n, "fov", 0.0)?;
                let axis = self
                    .string(n, "fov_axis")?
                    .unwrap_or_else(|| "x".into())
                    .to_ascii_lowercase();
                let axis = match axis.as_str() {
                    "smaller" if aspect > 1.0 => "y".to_string(),
                    "smaller" => "x".to_string(),
                    "larger" if aspect > 1.0 => "x".to_string(),
                    "larger" => "y".to_string(),
                    _ => axis,
                };
                (v, axis)
            }
            (None, f) => {
                let f = f.unwrap_or_else(|| "50mm".into());
                let mm = self.number(n, f.trim_end_matches("mm"))?;
                if !(mm > 0.0) {
                    return Err(self.err(n, format!("focal_length must be positive, got {f}")));
                }
                let diag = (36.0f64 * 36.0 + 24.0 * 24.0).sqrt();
                (
                    (2.0 * (diag / (2.0 * mm)).atan()).to_degrees(),
                    "diagonal".into(),
                )
            }
        };
        if !(value > 0.0 && value < 180.0) {
            return Err(self.err(n, format!("fov must be in (0, 180) degrees, got {value}")));
        }
        let half = (0.5 * value.to_radians()).tan();
        Ok(match axis.as_str() {
            "x" => value,
            "y" => (2.0 * (half * aspect).atan()).to_degrees(),
            "diagonal" => {
                let width = 2.0 * half / (1.0 + 1.0 / (aspect * aspect)).sqrt();
                (2.0 * (0.5 * width).atan()).to_degrees()
            }
            other => {
                return Err(self.err(
                    n,
                    format!("fov_axis '{other}' is not one of x, y, diagonal, smaller, larger"),
                ))
            }
        })
    }

    /// A shape's child elements with its `<ref>`s resolved (a ref named other than `bsdf` is
    /// skipped).
    fn shape_children(&mut self, n: N<'a>) -> Result<Vec<N<'a>>, String> {
        let mut out = Vec::new();
        for c in Self::children(n) {
            if c.tag_name().name() != "ref" {
                out.push(c);
            } else if c.attribute("name").is_none_or(|v| v == "bsdf") {
                out.push(self.resolve(c)?);
            }
        }
        Ok(out)
    }

    /// The id of a shape's BSDF (referenced, or inline with an id), if it has one.
    fn bsdf_id(&mut self, n: N<'a>) -> Result<Option<String>, String> {
        match self
            .shape_children(n)?
            .into_iter()
            .find(|c| c.tag_name().name() == "bsdf")
        {
            Some(b) => self.attr(b, "id"),
            None => Ok(None),
        }
    }

    /// A shape as a matfit object; None when it is skipped (a warning says why).
    fn shape(&mut self, n: N<'a>, ty: &str, name: String) -> Result<Option<ObjectSpec>, String> {
        let mut bsdf = None;
        let mut emitter = None;
        for el in self.shape_children(n)? {
            match el.tag_name().name() {
                "bsdf" => bsdf = Some(el),
                "emitter" => emitter = Some(el),
                "medium" => self.warn(el, "media are ignored"),
                _ => {}
            }
        }
        let group = match bsdf {
            Some(b) => match self.attr(b, "id")? {
                Some(id) => id,
                None => name.clone(),
            },
            None => name.clone(),
        };
        let emission = match emitter {
            None => None,
            Some(e) => {
                let ety = self.need_attr(e, "type")?;
                if ety != "area" {
                    return Err(self.err(
                        e,
                        format!("emitter type '{ety}' inside a shape: only 'area' is supported"),
                    ));
                }
                let c = match self.color(e, "radiance")? {
                    Some(Ok(c)) => c,
                    Some(Err(_)) => {
                        return Err(self.err(e, "a textured radiance cannot be imported"))
                    }
                    None => return Err(self.err(e, "an area emitter needs `radiance`")),
                };
                Some(Spanned::new(0..0, Color(c.as_vec3().to_array())))
            }
        };
        let material = match bsdf {
            Some(b) => {
                let one_sided = b.tag_name().name() == "bsdf"
                    && self.attr(b, "type")?.as_deref() != Some("twosided");
                if one_sided && self.warned.insert((b.range().start, "one-sided")) {
                    self.warn(
                        b,
                        format!(
                            "{} is one-sided in Mitsuba (black from behind); matfit's surfaces \
                             reflect on both sides (the same wherever only front sides are seen \
                             and lit)",
                            self.describe(b)
                        ),
                    );
                }
                let l = self.lobes(b)?;
                self.material_spec(b, l)
            }
            None => MaterialSpec::Diffuse {
                rho_d: Color([0.5; 3]),
            },
        };
        let flip = self.boolean(n, "flip_normals")?;
        let m = self.transform(n, "to_world")?;
        let lin = DMat3::from_mat4(m);
        let p = |v: DVec3| m.transform_point3(v);
        let f = f32s;
        let mut o = ObjectSpec {
            name: Spanned::new(0..0, name.clone()),
            group: Some(Spanned::new(0..0, group)),
            shape: Spanned::new(0..0, ShapeKind::Quad),
            corner: None,
            edge_u: None,
            edge_v: None,
            min: None,
            max: None,
            center: None,
            radius: None,
            segments: None,
            file: None,
            transform: None,
            tangent: None,
            material: Some(Spanned::new(0..0, material)),
            emission,
        };
        let emits = o.emission.is_some();
        let no_flip = |cx: &mut Self| -> Result<(), String> {
            if flip && emits {
                return Err(cx.err(
                    n,
                    format!(
                        "flip_normals on an emitting {ty}: matfit's {ty} lights emit outward \
                         (along the wound normal)"
                    ),
                ));
            }
            Ok(())
        };
        let mut orient = None;
        match ty {
            "rectangle" => {
                let (mut u, mut v) = (
                    lin * DVec3::new(2.0, 0.0, 0.0),
                    lin * DVec3::new(0.0, 2.0, 0.0),
                );
                orient = Some(Orient::FlipV);
                if (lin.determinant() < 0.0) != flip {
                    std::mem::swap(&mut u, &mut v);
                    orient = Some(Orient::Transpose);
                }
                if u.cross(v).length() == 0.0 {
                    return Err(self.err(n, "the rectangle's to_world collapses it"));
                }
                o.corner = Some(f(p(DVec3::new(-1.0, -1.0, 0.0))));
                o.edge_u = Some(f(u));
                o.edge_v = Some(f(v));
            }
            "cube" => {
                no_flip(self)?;
                o.shape = Spanned::new(0..0, ShapeKind::Box);
                if axis_aligned(lin) {
                    let (a, b) = (p(DVec3::splat(-1.0)), p(DVec3::splat(1.0)));
                    o.min = Some(f(a.min(b)));
                    o.max = Some(f(a.max(b)));
                } else {
                    o.min = Some([-1.0; 3]);
                    o.max = Some([1.0; 3]);
                    o.transform = Some(self.decompose(n, m)?);
                }
            }
            "sphere" => {
                no_flip(self)?;
                o.shape = Spanned::new(0..0, ShapeKind::Sphere);
                o.segments = Some(256);
                let c = self
                    .prop(n, "center")?
                    .map(|c| self.vec3_of(c, 0.0))
                    .transpose()?;
                let r = self.float(n, "radius", 1.0)?;
                if !(r > 0.0) {
                    return Err(self.err(n, format!("sphere radius must be positive, got {r}")));
                }
                let full = m
                    * DMat4::from_translation(c.unwrap_or(DVec3::ZERO))
                    * DMat4::from_scale(DVec3::splat(r));
                let fl = DMat3::from_mat4(full);
                let s = [fl.x_axis.length(), fl.y_axis.length(), fl.z_axis.length()];
                let uniform = s.iter().all(|x| (x - s[0]).abs() <= 1e-6 * s[0]);
                let ortho = (fl.transpose() * fl
                    - DMat3::from_diagonal(DVec3::from(s.map(|x| x * x))))
                .to_cols_array()
                .iter()
                .all(|x| x.abs() <= 1e-6 * s[0] * s[0]);
                if uniform && ortho {
                    o.center = Some(f(full.transform_point3(DVec3::ZERO)));
                    o.radius = Some(s[0] as f32);
                } else {
                    o.center = Some([0.0; 3]);
                    o.radius = Some(1.0);
                    o.transform = Some(self.decompose(n, full)?);
                }
            }
            "obj" | "ply" => {
                no_flip(self)?;
                o.shape = Spanned::new(0..0, ShapeKind::Mesh);
                let fname = self.string(n, "filename")?.ok_or_else(|| {
                    self.err(n, format!("a {ty} shape needs <string name=\"filename\">"))
                })?;
                let abs = self.find_file(n, &fname)?;
                // Mitsuba loads a mesh whose triangles all have zero area (it draws nothing);
                // matfit refuses one, so it is left out.
                let mut mesh = crate::scene::meshio::load_mesh(&abs).map_err(|e| self.err(n, e))?;
                use crate::geometry::mesh::MeshProblem;
                match mesh.validate() {
                    Ok(_) => {}
                    Err(MeshProblem::AllDegenerate | MeshProblem::NoTriangles) => {}
                    Err(e) => {
                        return Err(self.err(n, format!("mesh {}: {e}", abs.display())));
                    }
                }
                if mesh.indices.is_empty() {
                    self.warn(
                        n,
                        format!(
                            "mesh {} is skipped: it has no triangle of non-zero area (Mitsuba \
                             draws nothing of it either)",
                            abs.display()
                        ),
                    );
                    return Ok(None);
                }
                // Mitsuba's face_normals shades with the triangles' own normals: a copy of the
                // mesh without its vertex normals, which matfit then shades the same way.
                if self.boolean(n, "face_normals")? && mesh.normals.is_some() {
                    let copy = super::mesh::Mesh {
                        positions: mesh.positions.iter().map(|p| p.as_dvec3()).collect(),
                        normals: None,
                        // matfit reads an OBJ's and a PLY's (u, v) as they are written; the
                        // copy keeps them (to_obj writes Mitsuba's v back as 1 − v).
                        uvs: mesh
                            .uvs
                            .as_ref()
                            .map(|uv| uv.iter().map(|t| [t.x as f64, 1.0 - t.y as f64]).collect()),
                        indices: mesh.indices.clone(),
                    };
                    let file = format!("meshes/{}.obj", sanitize(&name));
                    self.meshes.push((file.clone(), copy.to_obj()));
                    o.file = Some(Spanned::new(0..0, file));
                } else {
                    o.file = Some(Spanned::new(0..0, self.file_ref(n, &fname)?));
                }
                if m != DMat4::IDENTITY {
                    o.transform = Some(self.decompose(n, m)?);
                }
                orient = Some(if ty == "obj" {
                    Orient::Same
                } else {
                    Orient::FlipV
                });
            }
            "serialized" | "disk" => {
                o.shape = Spanned::new(0..0, ShapeKind::Mesh);
                let mut mesh = if ty == "disk" {
                    super::mesh::disk(DISK_SEGMENTS)
                } else {
                    let fname = self.string(n, "filename")?.ok_or_else(|| {
                        self.err(n, "a serialized shape needs <string name=\"filename\">")
                    })?;
                    let abs = self.find_file(n, &fname)?;
                    let index = self.float(n, "shape_index", 0.0)?;
                    if !(index >= 0.0 && index.fract() == 0.0) {
                        return Err(self.err(n, "shape_index must be a whole number ≥ 0"));
                    }
                    super::mesh::read_serialized(&abs, index as usize)
                        .map_err(|e| self.err(n, e))?
                };
                let face_normals = ty == "serialized" && self.boolean(n, "face_normals")?;
                if face_normals {
                    mesh.normals = None;
                }
                // Mitsuba's flip_normals turns the wound normal, which is matfit's emitting side.
                let flip_winding = flip != (lin.determinant() < 0.0);
                mesh.apply(&m, flip_winding);
                // Mitsuba shades a mesh without normals smoothly, with normals it makes.
                if ty == "serialized" && !face_normals && mesh.normals.is_none() {
                    mesh.generate_normals();
                }
                if mesh.all_degenerate() {
                    self.warn(
                        n,
                        format!(
                            "{} is skipped: every triangle of it is degenerate (zero area; \
                             Mitsuba draws nothing of it either)",
                            self.describe(n)
                        ),
                    );
                    return Ok(None);
                }
                let file = format!("meshes/{}.obj", sanitize(&name));
                self.meshes.push((file.clone(), mesh.to_obj()));
                o.file = Some(Spanned::new(0..0, file));
                // Written with Mitsuba's (u, v) as an OBJ's (u, 1 − v): read as Mitsuba reads.
                // (A disk's coordinates are polar in Mitsuba: not written.)
                orient = (ty == "serialized").then_some(Orient::Same);
                if ty == "disk" {
                    self.warn(
                        n,
                        format!(
                            "disk tessellated as a {DISK_SEGMENTS}-gon mesh (area 0.01% short)"
                        ),
                    );
                }
            }
            other => {
                return Err(self.err(
                    n,
                    format!(
                        "shape type '{other}' is not supported (rectangle, cube, sphere, disk, \
                         obj, ply, serialized are)"
                    ),
                ))
            }
        }
        if let Some(MaterialSpec::Textured { texture, .. }) =
            o.material.as_mut().map(Spanned::get_mut)
        {
            match orient {
                Some(orient) => *texture = self.reoriented(n, texture, orient)?,
                None => self.warn(
                    n,
                    format!(
                        "Mitsuba's {ty} has texture coordinates of its own; matfit's {ty} lays \
                         the texture out differently"
                    ),
                ),
            }
        }
        Ok(Some(o))
    }

    /// The texture at `path` (relative to the output's folder) turned by `orient`: a copy, as a
    /// linear EXR in `textures/` next to the scene file (the values matfit decodes from the
    /// source), or the source itself when it needs no turning.
    fn reoriented(&mut self, n: N<'a>, path: &str, orient: Orient) -> Result<String, String> {
        if orient == Orient::Same {
            return Ok(path.to_string());
        }
        let key = (path.to_string(), orient);
        if let Some(p) = self.reoriented.get(&key) {
            return Ok(p.clone());
        }
        let src = self.texture_image(n, path)?;
        let (w, h) = (src.width, src.height);
        let image = match orient {
            Orient::Same => src,
            // matfit's row (1 − v)·H is Mitsuba's row v·H.
            Orient::FlipV => crate::io::image::Image {
                width: w,
                height: h,
                data: (0..h)
                    .rev()
                    .flat_map(|y| src.data[y * w..(y + 1) * w].to_vec())
                    .collect(),
            },
            // matfit's (column u·W', row (1 − v)·H') is Mitsuba's (column v·W, row u·H).
            Orient::Transpose => {
                let mut out = crate::io::image::Image::new(h, w);
                for r in 0..w {
                    for c in 0..h {
                        out.set(c, r, src.get(w - 1 - r, c));
                    }
                }
                out
            }
        };
        let stem = Path::new(path)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let suffix = match orient {
            Orient::FlipV => "flipped",
            _ => "transposed",
        };
        let mut name = format!("textures/{stem}_{suffix}.exr");
        if self.textures.iter().any(|(n, _)| *n == name) {
            name = format!("textures/{stem}_{suffix}_{}.exr", self.textures.len());
        }
        self.textures.push((name.clone(), image));
        self.reoriented.insert(key, name.clone());
        Ok(name)
    }

    /// matfit's transform (scale, then rotations about X, Y, Z, then translate) of an affine
    /// matrix without shear.
    fn decompose(&self, n: N<'a>, m: DMat4) -> Result<TransformSpec, String> {
        decompose(m).ok_or_else(|| {
            self.err(
                n,
                "to_world shears the shape: matfit's transform is scale, rotate, translate only",
            )
        })
    }

    /// The lobes of a BSDF element (twosided and other wrappers unwrapped).
    fn lobes(&mut self, b: N<'a>) -> Result<Lobes, String> {
        let ty = self.need_attr(b, "type")?;
        let nested = |cx: &Self| -> Result<Vec<N<'a>>, String> {
            let mut v = Vec::new();
            for c in Self::children(b) {
                match c.tag_name().name() {
                    "bsdf" => v.push(c),
                    "ref" if c.attribute("name").is_none_or(|x| x == "bsdf") => {
                        let r = cx.resolve(c)?;
                        if r.tag_name().name() == "bsdf" {
                            v.push(r)
                        }
                    }
                    _ => {}
                }
            }
            Ok(v)
        };
        let guess = |cx: &mut Self, rule: &str| {
            if cx.warned.insert((b.range().start, "guess")) {
                let d = cx.describe(b);
                cx.warn(
                    b,
                    format!("{d} imported as {rule}: an initial guess for recovery, not the truth"),
                );
            }
        };
        Ok(match ty.as_str() {
            "twosided" | "mask" | "bumpmap" | "normalmap" => {
                let inner = nested(self)?;
                let Some(first) = inner.first().copied() else {
                    return Err(self.err(b, format!("{} has no nested <bsdf>", self.describe(b))));
                };
                match ty.as_str() {
                    "twosided" => {}
                    "bumpmap" | "normalmap" => self.warn(
                        b,
                        format!(
                            "{}: matfit has no bump or normal maps; imported as its nested BSDF \
                             (the shading differs where the bumps show)",
                            self.describe(b)
                        ),
                    ),
                    _ => {
                        let opacity = match self.prop(b, "opacity")? {
                            Some(p) if p.tag_name().name() == "texture" => {
                                "a textured opacity".to_string()
                            }
                            _ => {
                                let o = self.rgb(b, "opacity", 0.5)?;
                                format!("opacity ({:.4}, {:.4}, {:.4})", o.x, o.y, o.z)
                            }
                        };
                        self.warn(
                            b,
                            format!(
                                "{}: Mitsuba passes 1 − opacity of the light straight through \
                                 it ({opacity}); matfit's surfaces are opaque, so its nested \
                                 BSDF is used in full (brighter, and darker behind it, than \
                                 in Mitsuba)",
                                self.describe(b)
                            ),
                        )
                    }
                }
                if inner.len() > 1 {
                    self.warn(
                        b,
                        "a twosided BSDF with two different sides: the front one is used",
                    );
                }
                self.lobes(first)?
            }
            "diffuse" => match self.color(b, "reflectance")? {
                None => Lobes {
                    d: DVec3::splat(0.5),
                    ..Default::default()
                },
                Some(Ok(c)) => Lobes {
                    d: c,
                    ..Default::default()
                },
                // For a texture, d is the factor on its texels.
                Some(Err(tex)) => Lobes {
                    texture: Some(tex),
                    d: DVec3::ONE,
                    ..Default::default()
                },
            },
            "conductor" | "roughconductor" => {
                let spec = self.rgb(b, "specular_reflectance", 1.0)?;
                let f0 = self.conductor_f0(b)?;
                let rough = ty == "roughconductor";
                let distribution = if rough {
                    self.string(b, "distribution")?
                        .unwrap_or_else(|| "beckmann".into())
                } else {
                    String::new()
                };
                // With eta/k the lobe's shape is still Mitsuba's; only the Fresnel term is
                // frozen at normal incidence.
                let microfacet = Distribution::from_name(&distribution).filter(|_| rough);
                if f0.is_some() || (rough && microfacet.is_none()) {
                    guess(
                        self,
                        if microfacet.is_some() {
                            "microfacet (its distribution) ρd 0, ρs = F0 × \
                             specular_reflectance, α = alpha (no Fresnel rise toward grazing)"
                        } else if rough {
                            "Ward ρd 0, ρs = F0 × specular_reflectance, α = alpha"
                        } else {
                            "a mirror with ρs = Fresnel reflectance at normal incidence × specular_reflectance"
                        },
                    );
                }
                let s = spec * f0.unwrap_or(DVec3::ONE);
                Lobes {
                    s,
                    alpha: if rough {
                        Some(self.alpha(b, 0.1)?)
                    } else {
                        None
                    },
                    microfacet,
                    ..Default::default()
                }
            }
            "roughplastic" => {
                // matfit's plastic is this plugin with `nonlinear = false`; a nonlinear one's
                // diffuse part ρ/(1 − ρ·F_int) is the linear one's ρ'/(1 − F_int) with
                // ρ' = ρ (1 − F_int)/(1 − ρ·F_int): exact too.
                let eta = self.ior_ratio(b)?;
                let f0 = crate::render::bsdf::plastic::fresnel_dielectric(1.0, eta as f32) as f64;
                let distribution = self
                    .string(b, "distribution")?
                    .unwrap_or_else(|| "beckmann".into());
                let known = Distribution::from_name(&distribution);
                let nonlinear = self.boolean(b, "nonlinear")?;
                let (a, _) = self.alpha(b, 0.1)?;
                let s = self.rgb(b, "specular_reflectance", 1.0)? * f0;
                let coat =
                    crate::render::bsdf::Coat::get(a as f32, eta as f32, known.unwrap_or_default());
                let f_int = coat_internal_reflectance(coat);
                let linear = |rho: f64| {
                    if nonlinear {
                        rho * (1.0 - f_int) / (1.0 - rho * f_int)
                    } else {
                        rho
                    }
                };
                match self.color(b, "diffuse_reflectance")? {
                    Some(Err(texture)) => {
                        if known.is_none() {
                            guess(
                                self,
                                "plastic with a GGX coat of the same alpha and η, ρs = F0 × \
                                 specular_reflectance",
                            );
                        }
                        // Exact: the texture (nonlinear folded into a copy, per texel) under
                        // matfit's coat.
                        let texture = if nonlinear {
                            self.linearised(b, &texture, f_int, f_int)?
                        } else {
                            texture
                        };
                        Lobes {
                            d: DVec3::ONE,
                            s,
                            alpha: Some((a, a)),
                            texture: Some(texture),
                            plastic: Some((eta, known.unwrap_or_default())),
                            ..Default::default()
                        }
                    }
                    d => {
                        if known.is_none() {
                            guess(
                                self,
                                "plastic with a GGX coat of the same alpha and η, ρs = F0 × \
                                 specular_reflectance",
                            );
                        }
                        let d = match d {
                            Some(Ok(c)) => c,
                            _ => DVec3::splat(0.5),
                        };
                        Lobes {
                            d: DVec3::new(linear(d.x), linear(d.y), linear(d.z)),
                            s,
                            alpha: Some((a, a)),
                            plastic: Some((eta, known.unwrap_or_default())),
                            ..Default::default()
                        }
                    }
                }
            }
            "plastic" => {
                // matfit's coats are rough: the smooth one becomes the narrowest GGX coat the
                // fitter reaches (α = ALPHA_MIN), which keeps the coat's Fresnel reflection,
                // rising toward grazing, and the base's (1 − F) falloff at both ends. Mitsuba's
                // diffuse part is ρ/(1 − F_s)·(1 − F(θi))(1 − F(θo))/(π η²), with ρ·F_s in
                // place of F_s when `nonlinear`, F_s the smooth coat's fdr_int; matfit's is
                // ρd/(1 − F_c)·t(θi) t(θo)/(π η²), F_c its own coat's, t ≈ 1 − F. So
                // ρd = ρ(1 − F_c)/(1 − F_s), or ρ(1 − F_c)/(1 − ρ·F_s).
                let eta = self.ior_ratio(b)?;
                let alpha = crate::fit::params::ALPHA_MIN;
                let coat = crate::render::bsdf::Coat::get(alpha, eta as f32, Distribution::Ggx);
                let f0 = coat.f0 as f64;
                let nonlinear = self.boolean(b, "nonlinear")?;
                let f_s = smooth_internal_reflectance(eta);
                let f_c = coat_internal_reflectance(coat);
                let linear = |rho: f64| {
                    rho * (1.0 - f_c) / (1.0 - if nonlinear { rho * f_s } else { f_s })
                };
                guess(
                    self,
                    &format!(
                        "plastic with a GGX coat of α = {alpha} for its smooth one (matfit's \
                         coats are rough; the reflection is that wide, and dims a little \
                         toward grazing), ρs = F0 × specular_reflectance, F0 = {f0:.4}, \
                         ρd = ρ(1 − F_c)/(1 − {}F_s), F_c = {f_c:.4} the rough coat's internal \
                         reflectance, F_s = {f_s:.4} the smooth one's",
                        if nonlinear { "ρ·" } else { "" }
                    ),
                );
                let s = self.rgb(b, "specular_reflectance", 1.0)? * f0;
                let lobes = |d: DVec3, texture: Option<String>| Lobes {
                    d,
                    s,
                    alpha: Some((alpha as f64, alpha as f64)),
                    texture,
                    plastic: Some((eta, Distribution::Ggx)),
                    ..Default::default()
                };
                match self.color(b, "diffuse_reflectance")? {
                    // The texture under the coat: a nonlinear one's texels go into a copy, a
                    // linear one's factor is the texture's scale.
                    Some(Err(texture)) if nonlinear => {
                        let texture = self.linearised(b, &texture, f_c, f_s)?;
                        lobes(DVec3::ONE, Some(texture))
                    }
                    Some(Err(texture)) => lobes(DVec3::splat(linear(1.0)), Some(texture)),
                    d => {
                        let d = match d {
                            Some(Ok(c)) => c,
                            _ => DVec3::splat(0.5),
                        };
                        lobes(DVec3::new(linear(d.x), linear(d.y), linear(d.z)), None)
                    }
                }
            }
            "principled" => {
                let base = self.rgb(b, "base_color", 0.5)?;
                let metallic = self.float(b, "metallic", 0.0)?.clamp(0.0, 1.0);
                let rough = self.float(b, "roughness", 0.5)?.clamp(1e-3, 1.0);
                let f0d = 0.08 * self.float(b, "specular", 0.5)?;
                guess(
                    self,
                    "Ward with α = roughness², ρs = 0.08·specular blended to base_color by \
                     metallic, ρd = (1 − metallic)(1 − ρs)·base_color",
                );
                let s = DVec3::splat(f0d) * (1.0 - metallic) + base * metallic;
                Lobes {
                    d: base * (1.0 - metallic) * (DVec3::ONE - s),
                    s,
                    alpha: Some((rough * rough, rough * rough)),
                    ..Default::default()
                }
            }
            "blendbsdf" => {
                let w = match self.prop(b, "weight")? {
                    Some(p) if p.tag_name().name() == "float" => {
                        self.number(p, &self.need_attr(p, "value")?)?
                    }
                    Some(p) => {
                        return Err(self.err(p, "a textured blend weight cannot be imported"))
                    }
                    None => 0.5,
                };
                let inner = nested(self)?;
                let [a, c] = inner[..] else {
                    return Err(self.err(b, "a blendbsdf needs two nested BSDFs"));
                };
                let (la, lc) = (self.lobes(a)?, self.lobes(c)?);
                // The exporter's form of a microfacet material: exact.
                let microfacet = match (la.microfacet, lc.microfacet) {
                    (Some(d), None) if lc.plain_diffuse() => Some(d),
                    (None, Some(d)) if la.plain_diffuse() => Some(d),
                    _ => None,
                };
                // The exporter's form of a varnished texture: a textured diffuse and a lobe
                // with no diffuse part.
                let varnished = |t: &Lobes, l: &Lobes| {
                    t.texture.is_some()
                        && t.s == DVec3::ZERO
                        && t.alpha.is_none()
                        && l.texture.is_none()
                        && l.d == DVec3::ZERO
                        && l.plastic.is_none()
                };
                let texture = if varnished(&la, &lc) {
                    la.texture.clone()
                } else if varnished(&lc, &la) {
                    lc.texture.clone()
                } else {
                    None
                };
                if texture.is_some() && (la.microfacet.is_some() || lc.microfacet.is_some()) {
                    guess(
                        self,
                        "a textured Ward varnish of the rough part's α (matfit's varnish is a \
                         Ward lobe, not a microfacet one)",
                    );
                } else if texture.is_none()
                    && microfacet.is_none()
                    && (la.texture.is_some()
                        || lc.texture.is_some()
                        || la.alpha.is_some()
                        || lc.alpha.is_some())
                {
                    guess(
                        self,
                        "the blend of its parts' ρd and ρs, the rough part's α (no textures)",
                    );
                }
                if la.plastic.is_some() || lc.plastic.is_some() {
                    guess(self, "the blend of its parts' ρd and ρs as a Ward lobe");
                }
                Lobes {
                    d: la.d * (1.0 - w) + lc.d * w,
                    s: la.s * (1.0 - w) + lc.s * w,
                    alpha: la.alpha.or(lc.alpha),
                    microfacet: if texture.is_some() { None } else { microfacet },
                    texture,
                    plastic: None,
                }
            }
            other => {
                // A transmitting BSDF made opaque also shades whatever Mitsuba lights through it.
                let opaque = if other.contains("dielectric") {
                    "; opaque, so what Mitsuba lights through it is darker"
                } else {
                    ""
                };
                guess(
                    self,
                    &format!("diffuse 0.5 (matfit has no '{other}' material{opaque})"),
                );
                Lobes {
                    d: DVec3::splat(0.5),
                    ..Default::default()
                }
            }
        })
    }

    /// A dielectric's η = int_ior / ext_ior (Mitsuba's defaults: polypropylene in air).
    fn ior_ratio(&self, b: N<'a>) -> Result<f64, String> {
        let eta = self.ior(b, "int_ior", 1.49)? / self.ior(b, "ext_ior", 1.000277)?;
        if !(eta > 1.0 && eta.is_finite()) {
            return Err(self.err(b, "int_ior must exceed ext_ior"));
        }
        Ok(eta)
    }

    /// An index of refraction: a number, or one of the names Mitsuba knows.
    fn ior(&self, b: N<'a>, name: &str, default: f64) -> Result<f64, String> {
        match self.prop(b, name)? {
            Some(p) if p.tag_name().name() == "string" => {
                let v = self.need_attr(p, "value")?;
                // Mitsuba's table of named indices (its `ior.h`).
                let eta = match v.to_ascii_lowercase().as_str() {
                    "vacuum" => 1.0,
                    "helium" => 1.000036,
                    "hydrogen" => 1.000132,
                    "air" => 1.000277,
                    "carbon dioxide" => 1.00045,
                    "water" => 1.3330,
                    "acetone" => 1.36,
                    "ethanol" => 1.361,
                    "carbon tetrachloride" => 1.461,
                    "glycerol" => 1.4729,
                    "benzene" => 1.501,
                    "silicone oil" => 1.52045,
                    "bromine" => 1.661,
                    "water ice" => 1.31,
                    "fused quartz" => 1.458,
                    "pyrex" => 1.470,
                    "acrylic glass" => 1.49,
                    "polypropylene" => 1.49,
                    "bk7" => 1.5046,
                    "sodium chloride" => 1.544,
                    "amber" => 1.55,
                    "pet" => 1.5750,
                    "diamond" => 2.419,
                    _ => return Err(self.err(p, format!("unknown index of refraction '{v}'"))),
                };
                Ok(eta)
            }
            _ => self.float(b, name, default),
        }
    }

    fn alpha(&self, b: N<'a>, default: f64) -> Result<(f64, f64), String> {
        let a = self.float(b, "alpha", default)?;
        let ax = self.float(b, "alpha_u", a)?;
        let ay = self.float(b, "alpha_v", a)?;
        if !(ax > 0.0 && ay > 0.0) {
            return Err(self.err(b, "alpha must be positive"));
        }
        Ok((ax, ay))
    }

    /// Fresnel reflectance at normal incidence of a conductor; None for material "none" with no
    /// eta/k (an ideal mirror).
    fn conductor_f0(&mut self, b: N<'a>) -> Result<Option<DVec3>, String> {
        if self.prop(b, "eta")?.is_some() || self.prop(b, "k")?.is_some() {
            let eta = self.rgb(b, "eta", 0.0)?;
            let k = self.rgb(b, "k", 1.0)?;
            let f = |e: f64, k: f64| ((e - 1.0).powi(2) + k * k) / ((e + 1.0).powi(2) + k * k);
            return Ok(Some(DVec3::new(
                f(eta.x, k.x),
                f(eta.y, k.y),
                f(eta.z, k.z),
            )));
        }
        // Mitsuba's default material is "none": a 100% mirror.
        let name = self.string(b, "material")?.unwrap_or_else(|| "none".into());
        if name == "none" {
            return Ok(None);
        }
        // Linear-RGB F0 of common metals (Hoffman, "Physics and Math of Shading", 2013).
        let f0 = match name.as_str() {
            "Au" => [1.000, 0.766, 0.336],
            "Ag" => [0.972, 0.960, 0.915],
            "Cu" => [0.955, 0.638, 0.538],
            "Al" => [0.913, 0.922, 0.924],
            "Cr" => [0.549, 0.556, 0.554],
            "Fe" => [0.562, 0.565, 0.578],
            "Ni" => [0.660, 0.609, 0.526],
            "Ti" => [0.542, 0.497, 0.449],
            "W" => [0.504, 0.498, 0.478],
            _ => {
                self.warn(
                    b,
                    format!("metal '{name}' is not in matfit's table: ρs 0.9 as a guess"),
                );
                [0.9; 3]
            }
        };
        Ok(Some(DVec3::from(f0)))
    }

    fn material_spec(&mut self, b: N<'a>, l: Lobes) -> MaterialSpec {
        let c = |v: DVec3| Color(v.as_vec3().to_array());
        let mut d = l.d.max(DVec3::ZERO);
        let mut s = l.s.max(DVec3::ZERO);
        let bound = RhoBound::of(l.plastic.is_some() && l.alpha.is_some());
        let reach = (0..3).map(|k| bound.reach(d[k], s[k])).fold(0.0, f64::max);
        // (A texture's d is a factor on its texels, not a reflectance.)
        if reach > 1.0 + 1e-6 && l.texture.is_none() {
            match bound {
                RhoBound::Each => {
                    // A plastic's ρs is its coat's Fresnel reflection, set by η, below 1: only
                    // its base can pass the bound.
                    self.warn(
                        b,
                        format!(
                            "a plastic's ρd reaches {reach:.4} > 1 (more light out than in): \
                             lowered to 1 where over, ρs kept"
                        ),
                    );
                    d = d.min(DVec3::ONE);
                    s = s.min(DVec3::ONE);
                }
                RhoBound::Sum => {
                    self.warn(
                        b,
                        format!(
                            "ρd + ρs reaches {reach:.4} > 1 (more light out than in): scaled to 1"
                        ),
                    );
                    d /= reach;
                    s /= reach;
                }
            }
        }
        let (alpha, alpha_x, alpha_y) = match l.alpha {
            Some((ax, ay)) if ax == ay => (Some(ax as f32), None, None),
            Some((ax, ay)) => (None, Some(ax as f32), Some(ay as f32)),
            None => (None, None, None),
        };
        let has_s = s.max_element() > 0.0;
        if let Some(t) = l.texture {
            // Under a plastic's coat the lobe is kept even where ρs is zero (the coat still
            // refracts).
            let coat = l.plastic.filter(|_| l.alpha.is_some());
            let has_s = has_s || coat.is_some();
            return MaterialSpec::Textured {
                texture: t,
                scale: (d != DVec3::ONE).then(|| c(d)),
                mapping: None,
                texel_size: None,
                rho_s: has_s.then(|| c(s)),
                alpha: if has_s { alpha.or(Some(0.05)) } else { None },
                alpha_x: if has_s { alpha_x } else { None },
                alpha_y: if has_s { alpha_y } else { None },
                theta_deg: None,
                eta: coat.map(|(eta, _)| eta as f32),
                distribution: coat.map(|(_, d)| d),
            };
        }
        if let (Some((eta, distribution)), Some((a, _))) = (l.plastic, l.alpha) {
            return MaterialSpec::Plastic {
                rho_d: c(d),
                rho_s: c(s),
                alpha: a as f32,
                eta: Some(eta as f32),
                distribution,
            };
        }
        if let (Some(distribution), Some(_), true, None) =
            (l.microfacet, l.alpha, has_s, &l.texture)
        {
            return MaterialSpec::Microfacet {
                rho_d: c(d),
                rho_s: c(s),
                alpha,
                alpha_x,
                alpha_y,
                theta_deg: None,
                distribution,
            };
        }
        if l.alpha.is_some() && has_s {
            return MaterialSpec::Ward {
                rho_d: c(d),
                rho_s: c(s),
                alpha,
                alpha_x,
                alpha_y,
                theta_deg: None,
            };
        }
        let has_d = d.max_element() > 0.0;
        match (has_d, has_s) {
            (false, false) => MaterialSpec::Black,
            (true, false) => MaterialSpec::Diffuse { rho_d: c(d) },
            (false, true) => MaterialSpec::Mirror { rho_s: c(s) },
            (true, true) => MaterialSpec::DiffuseMirror {
                rho_d: c(d),
                rho_s: c(s),
            },
        }
    }
}

/// The internal diffuse reflectance of a smooth dielectric coat of index η (what Mitsuba's
/// `plastic` calls fdr_int): light from inside, cosine-weighted, reflected back by Fresnel
/// (total internal reflection included), 2∫₀¹ F(μ, 1/η) μ dμ by the midpoint rule.
fn smooth_internal_reflectance(eta: f64) -> f64 {
    const N: usize = 4096;
    (0..N)
        .map(|i| {
            let mu = (i as f64 + 0.5) / N as f64;
            2.0 * mu * crate::render::bsdf::plastic::fresnel_dielectric(mu as f32, (1.0 / eta) as f32)
                as f64
        })
        .sum::<f64>()
        / N as f64
}

/// The coat's internal diffuse reflectance F_int, from its diffuse part 1/(π η² (1 − F_int)).
fn coat_internal_reflectance(coat: &crate::render::bsdf::Coat) -> f64 {
    let t1 = coat.transmittance(1.0) as f64;
    let scale = coat.diffuse(1.0, 1.0) as f64 / (t1 * t1);
    let eta = coat.eta as f64;
    1.0 - 1.0 / (std::f64::consts::PI * eta * eta * scale)
}

/// A `w`×`h` image in Mitsuba's orientation (row 0 at v = 0) whose texel at (u, v) is
/// `f(to_uv · (u, v))`, sampled at texel centres.
fn resample(
    w: usize,
    h: usize,
    f: impl Fn([f64; 2]) -> crate::math::Rgb,
    to_uv: DMat4,
) -> crate::io::image::Image {
    let mut out = crate::io::image::Image::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let uv = DVec3::new(
                (x as f64 + 0.5) / w as f64,
                (y as f64 + 0.5) / h as f64,
                0.0,
            );
            let t = to_uv.transform_point3(uv);
            out.set(x, y, f([t.x, t.y]));
        }
    }
    out
}

/// Mitsuba's bilinear, repeating lookup of `img` at (u, v), v = 0 at the top row.
fn bilinear_mitsuba(img: &crate::io::image::Image, uv: [f64; 2]) -> crate::math::Rgb {
    let (w, h) = (img.width as i64, img.height as i64);
    let x = (uv[0] - uv[0].floor()) * w as f64 - 0.5;
    let y = (uv[1] - uv[1].floor()) * h as f64 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    let at = |i: i64, j: i64| img.get(i.rem_euclid(w) as usize, j.rem_euclid(h) as usize);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx;
    let bottom = at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx;
    top * (1.0 - fy) + bottom * fy
}

/// Segments of a disk's tessellation.
const DISK_SEGMENTS: usize = 256;

/// `name` as a file name: letters, digits, `-` and `_` kept, anything else `_`.
fn sanitize(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// The scene's TOML with each object's material and transform as one inline table, as people
/// write them (`material = { type = "diffuse", rho_d = 0.5 }`).
fn compact(text: &str) -> String {
    let Ok(mut doc) = text.parse::<toml_edit::DocumentMut>() else {
        return text.to_string();
    };
    if let Some(objects) = doc
        .get_mut("object")
        .and_then(|o| o.as_array_of_tables_mut())
    {
        for t in objects.iter_mut() {
            for key in ["transform", "material"] {
                if let Some(item) = t.get_mut(key) {
                    item.make_value();
                    if let Some(v) = item.as_inline_table_mut() {
                        v.fmt();
                    }
                }
                if let Some(mut k) = t.key_mut(key) {
                    k.leaf_decor_mut().set_suffix(" ");
                }
            }
        }
    }
    doc.to_string()
}

/// `v` with the components that are rounding noise of a rotation (under 1e-10 of the largest)
/// set to zero, as f32.
fn f32s(v: DVec3) -> [f32; 3] {
    let m = v.abs().max_element();
    v.to_array()
        .map(|x| if x.abs() <= 1e-10 * m { 0.0 } else { x as f32 })
}

/// True when a linear map keeps axis-aligned boxes axis-aligned: each column along one axis,
/// distinct axes.
fn axis_aligned(l: DMat3) -> bool {
    let cols = [l.x_axis, l.y_axis, l.z_axis];
    let mut used = [false; 3];
    for c in cols {
        let a = c.abs();
        let k = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let off = a.element_sum() - a[k];
        if off > 1e-9 * a[k] || a[k] == 0.0 || used[k] {
            return false;
        }
        used[k] = true;
    }
    true
}

/// m = T·R·S (S diagonal, possibly with one negative entry for a mirroring m) as matfit's
/// transform keys; None when m shears (its columns are not orthogonal) or is not affine.
pub(crate) fn decompose(m: DMat4) -> Option<TransformSpec> {
    if m.row(3) != DVec4::new(0.0, 0.0, 0.0, 1.0) {
        return None;
    }
    let l = DMat3::from_mat4(m);
    let mut s = DVec3::new(l.x_axis.length(), l.y_axis.length(), l.z_axis.length());
    if s.min_element() <= 0.0 {
        return None;
    }
    let mut r = DMat3::from_cols(l.x_axis / s.x, l.y_axis / s.y, l.z_axis / s.z);
    if (r.transpose() * r - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .any(|x| x.abs() > 1e-5)
    {
        return None;
    }
    if r.determinant() < 0.0 {
        s.x = -s.x;
        r.x_axis = -r.x_axis;
    }
    let (z, y, x) = DQuat::from_mat3(&r).to_euler(EulerRot::ZYX);
    let rot = DVec3::new(x, y, z);
    let t = m.w_axis.truncate();
    Some(TransformSpec {
        scale: (s != DVec3::ONE).then(|| Color(s.as_vec3().to_array())),
        rotate_deg: (rot.abs().max_element() > 1e-12)
            .then(|| f32s(rot).map(|a| (a as f64).to_degrees() as f32)),
        translate: (t != DVec3::ZERO).then(|| f32s(t)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mitsuba's fdr_int for a smooth coat: Egan and Hilgeman's fit at 1/η, which Mitsuba
    /// states is within 0.1% for indices up to 1.5.
    #[test]
    fn a_smooth_coat_reflects_back_what_mitsubas_fit_says() {
        for eta in [1.33f64, 1.5] {
            let e = 1.0 / eta;
            let fit = -1.4399 * e * e + 0.7099 * e + 0.6681 + 0.0636 / e;
            let got = smooth_internal_reflectance(eta);
            assert!((got / fit - 1.0).abs() < 1.5e-3, "η {eta}: {got} vs {fit}");
        }
    }

    /// The rough coat a smooth `plastic` imports as lets through what the smooth coat does,
    /// 1 − F(μ), away from grazing, and reflects back from inside about as much: so its ρd
    /// (which divides out the two internal reflectances) gives Mitsuba's diffuse part.
    #[test]
    fn the_narrowest_coat_stands_in_for_a_smooth_one() {
        for eta in [1.33f32, 1.5] {
            let alpha = crate::fit::params::ALPHA_MIN;
            let coat = crate::render::bsdf::Coat::get(alpha, eta, Distribution::Ggx);
            for mu in [0.2f32, 0.4, 0.6, 0.8, 1.0] {
                let smooth = 1.0 - crate::render::bsdf::plastic::fresnel_dielectric(mu, eta);
                let t = coat.transmittance(mu);
                assert!((t / smooth - 1.0).abs() < 5e-3, "η {eta}, μ {mu}: {t} vs {smooth}");
            }
            let (f_c, f_s) = (
                coat_internal_reflectance(coat),
                smooth_internal_reflectance(eta as f64),
            );
            assert!((f_c - f_s).abs() < 0.02, "η {eta}: {f_c} vs {f_s}");
        }
    }

    /// matfit's transform of the keys (as `scene/load.rs` builds it), applied to a point.
    fn apply(t: &TransformSpec, p: DVec3) -> DVec3 {
        let s = t
            .scale
            .map(|c| DVec3::from(c.0.map(f64::from)))
            .unwrap_or(DVec3::ONE);
        let [x, y, z] = t
            .rotate_deg
            .unwrap_or([0.0; 3])
            .map(|a| (a as f64).to_radians());
        let r = DQuat::from_euler(EulerRot::ZYX, z, y, x);
        let tr = t
            .translate
            .map(|v| DVec3::from(v.map(f64::from)))
            .unwrap_or(DVec3::ZERO);
        r * (s * p) + tr
    }

    #[test]
    fn a_rotate_scale_translate_chain_decomposes_exactly() {
        let m = DMat4::from_translation(DVec3::new(1.0, -2.0, 0.5))
            * DMat4::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), 0.7)
            * DMat4::from_scale(DVec3::new(0.3, 2.0, -1.5));
        let t = decompose(m).unwrap();
        for p in [DVec3::ZERO, DVec3::X, DVec3::new(0.3, -4.0, 2.0)] {
            let want = m.transform_point3(p);
            assert!((apply(&t, p) - want).length() < 1e-5, "{p}: {t:?}");
        }
        // A shear has no such form.
        let mut sheared = DMat4::IDENTITY;
        sheared.y_axis.x = 0.5;
        assert!(decompose(sheared).is_none());
    }

    #[test]
    fn cubes_rotated_by_right_angles_stay_boxes() {
        assert!(axis_aligned(DMat3::from_diagonal(DVec3::new(
            1.0, 2.0, 3.0
        ))));
        let quarter = DMat3::from_axis_angle(DVec3::Y, std::f64::consts::FRAC_PI_2);
        let q = DMat3::from_cols(
            quarter.x_axis.round(),
            quarter.y_axis.round(),
            quarter.z_axis.round(),
        );
        assert!(axis_aligned(q));
        assert!(!axis_aligned(DMat3::from_axis_angle(DVec3::Y, 0.3)));
    }

    /// Mitsuba's fov_axis rules: 90° on x of a 2:1 film is atan(½) on y, and so on.
    #[test]
    fn fields_of_view_convert_to_vertical() {
        let xml = |axis: &str| {
            format!(
                r#"<scene version="3.0.0"><sensor type="perspective">
                <float name="fov" value="90"/><string name="fov_axis" value="{axis}"/>
                <film type="hdrfilm"><integer name="width" value="200"/>
                <integer name="height" value="100"/><rfilter type="box"/></film></sensor>
                <shape type="sphere"/></scene>"#
            )
        };
        let fov_y = |axis: &str| {
            let r = import_str(&xml(axis), Path::new("s.xml"), Path::new("o.toml"), &[]).unwrap();
            let f: SceneFile = toml::from_str(&r.toml).unwrap();
            f.camera.fov_y_deg.unwrap() as f64
        };
        let deg = |x: f64| x.to_degrees();
        assert!((fov_y("x") - deg(2.0 * 0.5f64.atan())).abs() < 1e-4);
        assert!((fov_y("y") - 90.0).abs() < 1e-4);
        assert!((fov_y("smaller") - 90.0).abs() < 1e-4);
        assert!((fov_y("larger") - fov_y("x")).abs() < 1e-4);
        // Diagonal 90°: half-diagonal = 1, so half-height = 1/√5.
        assert!((fov_y("diagonal") - deg(2.0 * (1.0 / 5f64.sqrt()).atan())).abs() < 1e-4);
    }

    /// Mitsuba reads a bitmap with v down from the image's top row over a rectangle's
    /// (x + 1, y + 1)/2 (checked with Mitsuba 3.9's Python bindings), also through a mirroring
    /// `to_world`, whose edges matfit swaps: the imported texture, turned, gives every point of
    /// both rectangles Mitsuba's value.
    #[test]
    fn textures_on_rectangles_are_turned_to_read_as_in_mitsuba() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (5usize, 3usize);
        let mut img = crate::io::image::Image::new(w, h);
        for y in 0..h {
            for x in 0..w {
                img.set(
                    x,
                    y,
                    crate::math::Rgb::new(x as f32 / 4.0, y as f32 / 2.0, 0.25),
                );
            }
        }
        img.write(&dir.path().join("t.exr")).unwrap();
        let xml = r#"<scene version="3.0.0">
            <sensor type="perspective"><float name="fov" value="90"/>
                <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0"
                    up="0, 1, 0"/></transform>
                <film type="hdrfilm"><integer name="width" value="8"/>
                <integer name="height" value="8"/><rfilter type="box"/></film></sensor>
            <bsdf type="twosided" id="tex"><bsdf type="diffuse">
                <texture type="bitmap" name="reflectance">
                <string name="filename" value="t.exr"/></texture></bsdf></bsdf>
            <shape type="rectangle"><ref id="tex"/>
                <transform name="to_world"><translate x="-3"/></transform></shape>
            <shape type="rectangle"><ref id="tex"/>
                <transform name="to_world"><scale x="-1"/><translate x="3"/></transform>
            </shape></scene>"#;
        let xml_path = dir.path().join("s.xml");
        let out = dir.path().join("o.toml");
        let r = import_str(xml, &xml_path, &out, &[]).unwrap();
        assert!(r.warnings.is_empty(), "{:?}", r.warnings);
        assert_eq!(r.textures.len(), 2, "one flipped, one transposed");
        for (name, image) in &r.textures {
            let p = dir.path().join(name);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            image.write(&p).unwrap();
        }
        let scene = crate::scene::load::parse_scene(&r.toml, &out).unwrap();
        // Mitsuba's bilinear lookup at (u, v), v = 0 at the top row, repeating (its default).
        let mitsuba = |u: f32, v: f32| {
            let (x, y) = (u * w as f32 - 0.5, v * h as f32 - 0.5);
            let at = |i: f32, j: f32| {
                img.get(
                    (i as i64).rem_euclid(w as i64) as usize,
                    (j as i64).rem_euclid(h as i64) as usize,
                )
            };
            let (x0, y0) = (x.floor(), y.floor());
            let (ax, ay) = (x - x0, y - y0);
            at(x0, y0) * ((1.0 - ax) * (1.0 - ay))
                + at(x0 + 1.0, y0) * (ax * (1.0 - ay))
                + at(x0, y0 + 1.0) * ((1.0 - ax) * ay)
                + at(x0 + 1.0, y0 + 1.0) * (ax * ay)
        };
        for (centre, sx) in [(-3.0f32, 1.0f32), (3.0, -1.0)] {
            for (lx, ly) in [(-0.7f32, -0.6f32), (0.5, -0.2), (-0.1, 0.8), (0.3, 0.35)] {
                let o = crate::math::Vec3::new(centre + sx * lx, ly, 5.0);
                let ray = crate::geometry::Ray::new(o, crate::math::Vec3::new(0.0, 0.0, -1.0));
                let hit = scene.intersect(&ray, f32::INFINITY).unwrap();
                let crate::scene::Material::Textured { texture, .. } =
                    &scene.objects[hit.object as usize].material
                else {
                    panic!("not textured")
                };
                let got = texture.at(&hit);
                let want = mitsuba((lx + 1.0) / 2.0, (ly + 1.0) / 2.0);
                assert!(
                    (got - want).abs().max_element() < 1e-5,
                    "rectangle at x {centre}, local ({lx}, {ly}): {got} vs Mitsuba's {want}"
                );
            }
        }
    }
}
