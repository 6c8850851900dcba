//! The front door: one call per job, as the command line's commands do them. [`recover`] does
//! all of `matfit recover` (the photos' preparation, the pose refinement, checkpoints and
//! resume, the outputs); [`render`], [`edit`], [`export`] and [`composite`] the other
//! commands' work. What a call has to say (lines, warnings, progress, the recovery's log) goes
//! to an [`Observer`]; every failure is an [`Error`].

pub mod checks;
pub mod composite;
pub mod recover;

use crate::io::image::Image;
use crate::scene::edit::Edit;
use crate::scene::Scene;
use crate::error::{Error, ErrorKind, Kind, Result};
use std::path::{Path, PathBuf};

pub use crate::fit::recovery::LogLine;
pub use crate::io::progress::Progress;
pub use composite::{CompositeOptions, Composited};
pub use recover::Recovery;

/// What a long call reports while it works. Every method has a default that ignores it; the
/// command line prints lines and warnings and draws progress bars. Calls come from the calling
/// thread, except `progress`, which renders report from their worker threads.
pub trait Observer: Sync {
    /// A line for the user (the command line prints it on standard output).
    fn message(&self, _text: &str) {}
    /// Something the user should know that does not stop the work.
    fn warning(&self, _text: &str) {}
    /// Where a render or a recovery is.
    fn progress(&self, _p: &Progress) {}
    /// A line of the recovery's log (log.jsonl), as it happens.
    fn log(&self, _line: &LogLine) {}
    /// Photo `index` (from 0) is prepared: read, registered to the model, its usable pixels
    /// chosen, its exposure set.
    fn prepared(&self, _index: usize, _photo: &crate::prepare::PreparedPhoto) {}
    /// The inputs are checked and the long work starts.
    fn fitting(&self) {}
    /// Asked after every global iteration of a recovery: true stops it there, its checkpoint
    /// written, with an [`ErrorKind::Interrupted`] error. A render asks it before each row,
    /// from its worker threads, and stops with the same error.
    fn cancelled(&self) -> bool {
        false
    }
}

/// A camera response as `--response` names it: `linear`, `srgb`, `gamma:G`, `table:FILE`.
pub fn parse_response(s: &str) -> Result<crate::photo::Response> {
    crate::photo::Response::parse(s).map_err(|m| Error::new(ErrorKind::Options, m))
}

/// A grey card as `--grey-card` names it: `GROUP=RHO` or `GROUP=R,G,B`.
pub fn parse_grey_card(s: &str) -> Result<(String, crate::math::Rgb)> {
    crate::prepare::args::parse_grey_card(s).map_err(|m| Error::new(ErrorKind::Options, m))
}

/// The error of a render its observer stopped.
fn interrupted_render() -> Error {
    Error::new(ErrorKind::Interrupted, "interrupted: the render was stopped")
}

/// An observer that ignores everything.
pub struct Silent;

impl Observer for Silent {}

/// A photograph given to [`recover`]: a file (EXR, HDR, PFM linear; PNG, JPEG, TIFF through
/// the response curve), or linear RGB values already in memory, row-major, the camera's size.
#[derive(Clone, Debug)]
pub enum PhotoInput {
    Path(PathBuf),
    Linear(Image),
}

impl From<&Path> for PhotoInput {
    fn from(p: &Path) -> PhotoInput {
        PhotoInput::Path(p.to_path_buf())
    }
}

impl From<PathBuf> for PhotoInput {
    fn from(p: PathBuf) -> PhotoInput {
        PhotoInput::Path(p)
    }
}

impl From<&str> for PhotoInput {
    fn from(p: &str) -> PhotoInput {
        PhotoInput::Path(p.into())
    }
}

/// Everything [`recover`] takes besides the scene and the photos; the defaults are the
/// command line's.
#[derive(Clone, Debug)]
pub struct RecoverOptions {
    /// The fitting engine's options (`--seed`, `--max-iterations`, ...).
    pub fit: crate::fit::RecoverOptions,
    /// How to read the photos and choose their usable pixels (`--response`, `--exposure`, ...).
    pub photo: crate::prepare::PhotoArgs,
    /// The `[[view]]` each photo is taken through, numbers from 1 or names (empty: photo K
    /// through view K).
    pub views: Vec<String>,
    /// The folder to write log.jsonl, checkpoint.json and the outputs into (None: nothing is
    /// written).
    pub output: Option<PathBuf>,
    /// Continue the run in `output` from its checkpoint.
    pub resume: bool,
}

impl Default for RecoverOptions {
    fn default() -> Self {
        RecoverOptions {
            fit: crate::fit::RecoverOptions::default(),
            photo: crate::prepare::PhotoArgs {
                refine_pose: true,
                ..Default::default()
            },
            views: Vec::new(),
            output: None,
            resume: false,
        }
    }
}

/// Loads a scene file (TOML; docs/USAGE.md, "Scene files").
pub fn load(path: impl AsRef<Path>) -> Result<Scene> {
    Ok(crate::scene::load_scene(path.as_ref())?)
}

/// Reads a linear image file (EXR, HDR, PFM; a recovery's synthetic.exr).
pub fn read_image(path: impl AsRef<Path>) -> Result<Image> {
    crate::io::image::read_linear(path.as_ref()).kind(ErrorKind::Photo)
}

/// Recovers the materials of `scene`'s groups from `photos`, as `matfit recover` does: each
/// photo prepared against the scene (photo K through the scene's `[[view]]` K, or
/// `options.views`), the camera's pose refined and refined again against a quick fit's
/// materials, the recovery with a checkpoint after every global iteration when
/// `options.output` is given (and resumed from it with `options.resume`), and the outputs
/// (recovered.toml, results.json, report.html, images) written there.
pub fn recover(
    scene: &Scene,
    photos: &[PhotoInput],
    options: &RecoverOptions,
    observer: &dyn Observer,
) -> Result<Recovery> {
    recover::recover(scene, photos, options, observer)
}

/// What [`render`] makes.
#[derive(Clone, Debug)]
pub struct RenderRequest {
    /// Samples per pixel (None: the scene's `[render]` spp).
    pub spp: Option<u32>,
    /// Random seed (None: the scene's `[render]` seed).
    pub seed: Option<u64>,
    /// The image, or an index buffer or other AOV.
    pub aov: crate::render::aov::Aov,
    /// An AOV's values as false colours (for a PNG) rather than the values themselves.
    pub false_colour: bool,
    /// Render as one of the scene's `[[view]]`s sees it: a number from 1 or a name.
    pub view: Option<String>,
}

impl Default for RenderRequest {
    fn default() -> Self {
        RenderRequest {
            spp: None,
            seed: None,
            aov: crate::render::aov::Aov::Beauty,
            false_colour: false,
            view: None,
        }
    }
}

/// The scene as its `[[view]]` `view` sees it (a number from 1 or a name).
pub fn in_view(scene: &Scene, view: &str) -> Result<Scene> {
    let k = scene.view_index(view)?;
    Ok(scene.in_view(k))
}

/// Renders `scene` as `matfit render` does: the path-traced image (refused when no light
/// reaches what the camera sees) or an AOV, rendering on every core.
pub fn render(scene: &Scene, request: &RenderRequest, observer: &dyn Observer) -> Result<Image> {
    let viewed;
    let sc = match &request.view {
        Some(v) => {
            viewed = in_view(scene, v)?;
            &viewed
        }
        None => scene,
    };
    use crate::render::aov::Aov;
    match request.aov {
        Aov::Beauty => {
            checks::require_light(sc, &crate::scene::lint::lighting(sc), observer)?;
            let opts = crate::render::film::RenderOptions {
                spp: request.spp.unwrap_or(sc.render.spp).max(1),
                seed: request.seed.unwrap_or(sc.render.seed),
                progress: true,
            };
            crate::render::film::render_image(
                sc,
                &sc.camera,
                &opts,
                |p| observer.progress(p),
                &|| observer.cancelled(),
            )
            .ok_or_else(interrupted_render)
        }
        other => Ok(crate::render::aov::aov_image(
            sc,
            &sc.camera,
            other,
            request.false_colour,
        )),
    }
}

/// An edit of a scene: an edit file's text (TOML: remove, camera, object, material, move,
/// light; docs/USAGE.md, "Edits"), or the command line's flags.
pub type EditFlags = crate::scene::edit::EditFlags;

/// Reads an edit file.
pub fn read_edit(path: impl AsRef<Path>) -> Result<Edit> {
    Ok(Edit::read(path.as_ref())?)
}

/// The command line's edit flags (`--remove`, `--move`, `--material`, ...) as one edit
/// (None when they say nothing).
pub fn edit_from_flags(flags: &EditFlags) -> Result<Option<Edit>> {
    Ok(flags.to_edit()?)
}

/// `scene` with `edits` applied in order, as `matfit render --edit ...` renders it (the edits
/// apply to its scene file, read again).
pub fn edit(scene: &Scene, edits: &[Edit]) -> Result<Scene> {
    if edits.is_empty() {
        return Ok(scene.clone());
    }
    load_edited(&scene.path, edits)
}

/// The scene file at `path` with `edits` applied in order.
pub fn load_edited(path: impl AsRef<Path>, edits: &[Edit]) -> Result<Scene> {
    Ok(crate::scene::edit::load_edited(path.as_ref(), edits)?)
}

/// Writes `scene` for another renderer, as `matfit export` does: Mitsuba 3 into the folder
/// `output`, or glTF 2.0 into the file `output` (.glb). The report lists what was written and
/// every approximation.
pub fn export(
    scene: &Scene,
    format: crate::export::Format,
    output: &Path,
) -> Result<crate::export::ExportReport> {
    use crate::export::Format;
    let kind = ErrorKind::Export;
    match format {
        Format::Mitsuba => {
            crate::io::atomic::prepare_output_dir(output).kind(ErrorKind::Io)?;
            crate::export::mitsuba::export(scene, output).kind(kind)
        }
        Format::Gltf => {
            let ext = output.extension().and_then(|e| e.to_str()).unwrap_or("");
            if !ext.eq_ignore_ascii_case("glb") {
                return Err(Error::options(format!(
                    "{}: output must end in .glb",
                    output.display()
                )));
            }
            crate::io::atomic::check_output_file(output).kind(ErrorKind::Io)?;
            crate::export::gltf::export(scene, output).kind(kind)
        }
    }
}

/// Renders `edits` of the recovered `scene` into its photo, as `matfit composite` does
/// (differential rendering).
pub fn composite(
    scene: &Scene,
    photo: &PhotoInput,
    edits: &[Edit],
    options: &CompositeOptions,
    observer: &dyn Observer,
) -> Result<Composited> {
    composite::composite(scene, photo, edits, options, observer)
}

impl From<crate::scene::SceneError> for Error {
    fn from(e: crate::scene::SceneError) -> Error {
        use crate::scene::SceneError as S;
        let (path, line) = match &e {
            S::Io { path, .. } | S::Toml { path, .. } | S::Scene { path, .. } => {
                (path.clone(), None)
            }
            S::At { path, line, .. } => (path.clone(), Some(*line)),
        };
        Error::scene(e.to_string()).at(path, line)
    }
}

impl From<crate::fit::RecoverError> for Error {
    fn from(e: crate::fit::RecoverError) -> Error {
        Error::recover(e.to_string())
    }
}
