//! The `matfit` command line: clap's description of the commands and what each one runs. The
//! library knows nothing of it.

pub mod bench;
pub mod checks;
pub mod composite;
pub mod demo;
pub mod export;
pub mod hdr;
pub mod import;
pub mod info;
pub mod inspect;
pub mod out;
pub mod recover;
pub mod render;
pub mod table;

use crate::outln;
use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use matfit::io::atomic::{check_output_file, prepare_output_dir};
use matfit::math::Rgb;
use matfit::photo::Response;
use matfit::prepare::PhotoArgs;
use matfit::render::aov::Aov;
use matfit::scene::edit::{Edit, EditFlags};
use matfit::scene::{load_scene, Scene};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "matfit",
    version,
    about = "Recover the materials of a scene from one photograph",
    after_help = "Workflow:\n  \
        matfit hdr A.png B.png C.png --times 1/60,1/15,1/4 -o photo.exr   # brackets → one linear photo (optional)\n  \
        matfit inspect SCENE PHOTO -o check/    # does the model line up with the photo? which pixels are usable?\n  \
        matfit recover SCENE PHOTO -o result/   # fit every group's material; result/recovered.toml, report.html\n\n\
        Try it on a bundled scene first: matfit demo"
)]
pub struct Cli {
    /// Worker threads [default: all cores]. Results do not depend on it.
    #[arg(long, global = true, value_name = "N")]
    pub threads: Option<usize>,
    #[command(subcommand)]
    pub command: Command,
}

/// The scene file (TOML: camera, objects with their groups and materials, lights).
const SCENE_HELP: &str =
    "Scene file (TOML): camera, objects with their groups and materials, lights; see docs/USAGE.md";
/// The photograph.
const PHOTO_HELP: &str = "Photograph of the scene taken through the scene's camera: EXR, HDR or \
                          PFM (linear), or PNG/JPEG (8/16-bit, through --response); merge \
                          exposure brackets into one with `matfit hdr`";

#[derive(Subcommand)]
pub enum Command {
    /// Render a scene: a path-traced image, or an index buffer / AOV.
    Render(render::RenderCli),
    /// Render an edited scene into the photo (augmented reality).
    ///
    /// By differential rendering (Debevec 1998): a new object's shadows and reflections fall on
    /// the photographed surfaces.
    Composite(composite::CompositeCli),
    /// Recover the materials of a scene's groups from a photograph.
    Recover(recover::RecoverCli),
    /// Render a scene's photo, recover its materials blind, print true vs recovered values.
    ///
    /// The photo is rendered with the scene's true materials; with the default scene the table
    /// is the course notes' Figure 6.
    Demo(demo::DemoCli),
    /// Merge LDR exposure brackets into one linear photo for `recover`.
    ///
    /// The brackets are 8/16-bit PNG or JPEG of one scene from one viewpoint; the merge is the
    /// weighted average of response⁻¹(code) / time with Debevec & Malik's hat weight (1997,
    /// eq. 6), which drops clipped and black codes.
    #[command(after_help = "Example:\n  \
        matfit hdr a.png b.png c.png --times 1/60,1/15,1/4 -o photo.exr --response-out curve.txt\n  \
        matfit recover scene.toml photo.exr -o out --grey-card card=0.18\n\n\
        A recovered response is known up to one factor (so is the merged radiance): calibrate \
        the exposure in recover with --grey-card or --exposure-from-lights.")]
    Hdr(hdr::HdrCli),
    /// Print a summary of a scene file.
    ///
    /// The camera, render settings, groups with their materials, and lights.
    Info(info::InfoCli),
    /// Check a photo against the model before fitting.
    ///
    /// Writes the group outlines over the photo and the usable-pixel masks, and prints per group
    /// the visible / usable / rejected pixel counts and the exposure.
    Inspect(inspect::InspectCli),
    /// Export a scene to Mitsuba 3 or glTF 2.0.
    ///
    /// `matfit export mitsuba SCENE -o DIR` writes DIR/scene.xml (Mitsuba 3) and
    /// DIR/meshes/*.ply; `matfit export gltf SCENE -o OUT.glb` one binary glTF 2.0 file.
    /// Approximations are printed as warnings and listed in the written file.
    Export(export::ExportCli),
    /// Import a Mitsuba scene (3, or 0.5/0.6 upgraded) as a matfit scene file.
    ///
    /// `matfit import mitsuba SCENE.xml -o scene.toml` writes a matfit scene file (mesh and
    /// texture paths relative to it); approximations are printed as warnings and listed in the
    /// file's header; every refusal is reported at its file and line.
    Import(import::ImportCli),
    /// Measure how fast this machine traces rays (to compare machines or builds; not needed
    /// to use matfit).
    Bench(bench::BenchCli),
}

/// What `render --aov` writes.
#[derive(Clone, Copy, ValueEnum)]
pub enum AovArg {
    Beauty,
    Group,
    Object,
    MirrorGroup,
    MirrorObject,
    Normal,
    Depth,
    Uv,
}

impl From<AovArg> for Aov {
    fn from(a: AovArg) -> Aov {
        match a {
            AovArg::Beauty => Aov::Beauty,
            AovArg::Group => Aov::Group,
            AovArg::Object => Aov::Object,
            AovArg::MirrorGroup => Aov::MirrorGroup,
            AovArg::MirrorObject => Aov::MirrorObject,
            AovArg::Normal => Aov::Normal,
            AovArg::Depth => Aov::Depth,
            AovArg::Uv => Aov::Uv,
        }
    }
}

/// Edits of the scene before rendering (`render` and `composite`): edit files and flags,
/// applied in that order (edit file format: docs/USAGE.md, "Edits").
#[derive(clap::Args, Clone, Debug, Default)]
pub struct EditCli {
    /// Apply the edit file FILE (TOML: remove, camera, object, material, move, light);
    /// repeatable, applied in order [default: none].
    #[arg(long = "edit", value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// Remove an object, or every object of a group (repeatable) [default: none].
    #[arg(long, value_name = "NAME")]
    pub remove: Vec<String>,
    /// Translate an object or group: NAME=DX,DY,DZ (scene units; repeatable) [default: none].
    #[arg(long = "move", value_name = "NAME=DX,DY,DZ")]
    pub moves: Vec<String>,
    /// Rescale a light's emission: NAME=K or NAME=R,G,B (repeatable) [default: none].
    #[arg(long, value_name = "NAME=K")]
    pub scale_light: Vec<String>,
    /// Replace a group's material: GROUP='{ type = "diffuse", rho_d = 0.5 }' (repeatable) [default: none].
    #[arg(long, value_name = "GROUP={...}")]
    pub material: Vec<String>,
    /// Add an object, as an inline TOML table of a scene file's [[object]] keys
    /// ('{ name = "ball", group = "ball", shape = "sphere", center = [0, 0.3, 0], radius = 0.3 }') [default: none].
    #[arg(long, value_name = "{...}")]
    pub add: Vec<String>,
    /// A new look-at camera from this point (with --look-at; size kept) [default: the scene's camera].
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3)]
    pub look_from: Option<[f32; 3]>,
    /// The point the new camera looks at (with --look-from) [default: none].
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3)]
    pub look_at: Option<[f32; 3]>,
    /// Vertical field of view of the new camera, degrees [default: 40].
    #[arg(long, value_name = "DEG")]
    pub fov: Option<f32>,
}

impl EditCli {
    /// The edits: files first, then the flags as one more edit.
    pub fn edits(&self) -> Result<Vec<Edit>> {
        let mut v = Vec::new();
        for f in &self.files {
            v.push(Edit::read(f)?);
        }
        let flags = EditFlags {
            remove: self.remove.clone(),
            moves: self.moves.clone(),
            scale_lights: self.scale_light.clone(),
            materials: self.material.clone(),
            add: self.add.clone(),
            look_from: self.look_from,
            look_at: self.look_at,
            fov_y_deg: self.fov,
        };
        v.extend(flags.to_edit()?);
        Ok(v)
    }
}

/// The formats `export` writes.
#[derive(Clone, Copy, ValueEnum)]
pub enum FormatArg {
    /// Mitsuba 3 scene (XML, version 3.0.0) with one binary PLY per object.
    Mitsuba,
    /// glTF 2.0 binary (.glb): meshes, metallic-roughness materials, textures, the camera.
    Gltf,
}

/// The formats `import` reads.
#[derive(Clone, Copy, ValueEnum)]
pub enum ImportFormatArg {
    /// Mitsuba 3 scene (XML): the subset matfit renders (src/import/mitsuba.rs).
    Mitsuba,
}

/// `NAME=VALUE`.
fn parse_param(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((k, v)) if !k.is_empty() => Ok((k.to_string(), v.to_string())),
        _ => Err(format!("expected NAME=VALUE, got {s:?}")),
    }
}

/// How to read the photo and choose its usable pixels (`inspect` and `recover`).
#[derive(clap::Args, Clone, Debug)]
pub struct PhotoCli {
    /// Response curve of 8/16-bit photos: srgb, linear, gamma:G (linear = code^G) or
    /// table:FILE (format in docs/USAGE.md, "Photographs"). EXR/HDR/PFM photos are linear.
    #[arg(long, default_value = "srgb", value_parser = Response::parse)]
    pub response: Response,
    /// Exposure factor k, the photo's linear values = k × radiance [default: 1, unless
    /// calibrated by --grey-card or --exposure-from-lights].
    #[arg(long, value_name = "K", conflicts_with_all = ["grey_card", "exposure_from_lights"])]
    pub exposure: Option<f32>,
    /// Calibrate the exposure from a group of known diffuse reflectance: GROUP=RHO or
    /// GROUP=R,G,B (e.g. a grey card: --grey-card card=0.18).
    #[arg(long, value_name = "GROUP=RHO", value_parser = matfit::prepare::args::parse_grey_card,
          conflicts_with = "exposure_from_lights")]
    pub grey_card: Option<(String, Rgb)>,
    /// Calibrate the exposure from the light sources seen in the photo (their radiance is known).
    #[arg(long)]
    pub exposure_from_lights: bool,
    /// Half-width, in pixels, of the band removed around every boundary between objects.
    #[arg(long, value_name = "PIXELS", default_value_t = 2)]
    pub band: usize,
    /// Edge-detector threshold on |∇ ln luminance| per pixel (unitless); 0 turns it off.
    #[arg(long, value_name = "T", default_value_t = 0.12)]
    pub edge_threshold: f32,
    /// Reject pixels of planar groups far from a plane fitted to their intensity (unmodelled
    /// objects on diffuse walls; do not use it on glossy groups, it would drop highlights).
    #[arg(long)]
    pub planar_outliers: bool,
    /// The camera is calibrated: use it exactly as given [default: register the model to the
    /// photo by refining the camera's pose, a small rotation and translation (6 degrees of
    /// freedom), applied when it moves the model's edges by 0.1 px or more; where it does, the
    /// pose is refined again against a quick fit's materials (up to 3 rounds)].
    #[arg(long = "camera-is-calibrated", alias = "no-register", action = clap::ArgAction::SetFalse)]
    pub register: bool,
    /// Register by a shift of the film that aligns the model's outlines and creases with the
    /// photo's edges, applied from half a pixel on, instead of refining the pose: cheaper, but it
    /// cannot follow a turn or a move of the camera.
    #[arg(long, conflicts_with = "register")]
    pub film_shift: bool,
    /// The default registration (the pose refinement); the flag is kept for scripts.
    #[arg(long, hide = true, conflicts_with_all = ["register", "film_shift"])]
    pub refine_pose: bool,
    /// Largest misregistration searched, in pixels: by the film shift [default: 4], or by the
    /// pose refinement's first, film-shift step [default: 2% of the image diagonal, at least 4:
    /// a camera turned by 1° moves a 512×384 image by about 10 px].
    #[arg(long, value_name = "PIXELS")]
    pub max_shift: Option<i32>,
    /// Ignore the pixels this image marks (a person, an object the scene does not model): a
    /// PNG of the photo's size, any bit depth; with alpha, pixels of non-zero alpha are ignored,
    /// without, pixels of any non-zero channel [default: none].
    #[arg(long, value_name = "FILE")]
    pub ignore_mask: Option<PathBuf>,
    /// The lens's vignetting as Lensfun's radial model V = 1 + A1 r² + A2 r⁴ + A3 r⁶ (r = 1 at
    /// the half-diagonal, from the principal point): the photo is divided by V [default: none].
    #[arg(long, value_name = "A1,A2,A3", value_parser = matfit::photo::vignetting::parse_radial,
          conflicts_with = "flat_field", allow_hyphen_values = true)]
    pub vignetting: Option<[f32; 3]>,
    /// A flat-field image (a uniform white target through the same lens, the photo's size): the
    /// photo is divided by its luminance over its largest [default: none].
    #[arg(long, value_name = "FILE")]
    pub flat_field: Option<PathBuf>,
}

impl From<PhotoCli> for PhotoArgs {
    fn from(a: PhotoCli) -> PhotoArgs {
        PhotoArgs {
            response: a.response,
            exposure: a.exposure,
            grey_card: a.grey_card,
            exposure_from_lights: a.exposure_from_lights,
            band: a.band,
            edge_threshold: a.edge_threshold,
            planar_outliers: a.planar_outliers,
            register: a.register,
            refine_pose: !a.film_shift,
            max_shift: a.max_shift,
            ignore_mask: a.ignore_mask,
            vignetting: match (a.vignetting, a.flat_field) {
                (Some(r), _) => Some(matfit::photo::vignetting::Vignetting::Radial(r)),
                (None, Some(f)) => Some(matfit::photo::vignetting::Vignetting::FlatField(f)),
                (None, None) => None,
            },
        }
    }
}

/// Options of the fitting engine shared by `recover` and `demo`.
#[derive(clap::Args, Clone)]
pub struct FitArgs {
    /// Random seed of the caches and the final render.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
    /// At most this many global iterations (each re-renders the light every group receives).
    #[arg(long, value_name = "N", default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..))]
    max_iterations: u32,
    /// Light samples per cached pixel.
    #[arg(long, value_name = "N", default_value_t = 32, value_parser = clap::value_parser!(u32).range(2..))]
    light_samples: u32,
    /// Indirect samples per cached pixel.
    #[arg(long, value_name = "N", default_value_t = 32, value_parser = clap::value_parser!(u32).range(2..))]
    indirect_samples: u32,
    /// At most this many cached pixels per group.
    #[arg(long, value_name = "N", default_value_t = 12000)]
    max_pixels: usize,
    /// Cached pixels per group in the first global iteration, doubling each iteration up to
    /// --max-pixels (0: --max-pixels from the start).
    #[arg(long, value_name = "N", default_value_t = 1500)]
    first_pixels: usize,
    /// Samples per pixel of the final render (at least 2: its two halves give the noise floor)
    /// [default: 64 up to 960×540 pixels; above, the same 2^25 samples in all, at least 16]
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(2..))]
    final_spp: Option<u32>,
    /// Give groups no usable pixel shows (a ceiling out of view) white, ρd 1 (the notes'
    /// footnote 5), instead of estimating their diffuse reflectance from the light they reflect
    /// onto the seen groups (the default).
    #[arg(long)]
    white_unseen: bool,
    /// The default since the estimate became reliable; kept so that older commands still run.
    #[arg(long, hide = true, conflicts_with = "white_unseen")]
    estimate_unseen: bool,
    /// Texture threshold on ε (Algorithm 1 of the notes): a group whose best uniform model
    /// misses by at least this much tries level 7, a texture.
    #[arg(long, value_name = "E", default_value_t = 0.15, value_parser = positive_f32)]
    texture_error: f32,
    /// Texture threshold on fine detail: a group whose best uniform model leaves texel-scale
    /// structure of at least this RMS fraction of its radiance (z ≥ 4, after registration and
    /// highlight misfit are regressed out; averaged away in ε's tiles) tries level 7 even with
    /// a small ε.
    #[arg(long, value_name = "D", default_value_t = 0.02, value_parser = positive_f32)]
    texture_detail: f32,
    /// Never climb to level 7 (textures): uniform materials only.
    #[arg(long)]
    no_textures: bool,
    /// Never try levels 8, 9 and 10, the microfacet lobes (isotropic, plastic, anisotropic): the
    /// Ward lobes alone, to measure what those lobes gain.
    #[arg(long)]
    no_microfacet: bool,
    /// Fit mirrors only against a render of what they reflect, never against the photo's
    /// image of a group still being analysed (§5.1 of the notes' pseudo-textures, on by
    /// default; log.jsonl's `hypotheses` events show what they chose).
    #[arg(long)]
    no_pseudo_textures: bool,
    /// Fit a textured group from its own pixels only, never also from its image in a confirmed
    /// mirror (on by default; log.jsonl's `mirror_view` events show each mirror's pixels and
    /// the level factor applied to them).
    #[arg(long)]
    no_mirror_views: bool,
    /// Fit a stray light with the materials: a constant environment lighting what every ray
    /// leaving the scene sees, for captures whose shadows are not black (off by default: it
    /// is one more unknown). The summary, results.json and recovered.toml's [stray_light]
    /// give it.
    #[arg(long)]
    stray_light: bool,
    /// Fit every group as Lambertian (level 1) and never climb: a baseline to compare the
    /// hierarchy's models against.
    #[arg(long)]
    lambert: bool,
    /// Only models that this format expresses exactly: `mitsuba` skips levels 5 and 6 (Ward,
    /// which Mitsuba lacks; the microfacet lobes stand in), so that `export mitsuba` of the
    /// result says "Approximations: none" [default: none, every level].
    #[arg(long, value_name = "FORMAT")]
    exportable: Option<recover::Exportable>,
}

/// A finite number > 0, for thresholds.
fn positive_f32(s: &str) -> Result<f32, String> {
    let v: f32 = s.parse().map_err(|_| format!("'{s}' is not a number"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("must be a finite number > 0, got {s}"))
    }
}

impl FitArgs {
    fn options(&self) -> matfit::fit::RecoverOptions {
        let d = matfit::fit::RecoverOptions::default();
        // --no-textures: thresholds no group can reach.
        let textures_off = (self.no_textures || self.lambert).then_some(f32::MAX);
        matfit::fit::RecoverOptions {
            seed: self.seed,
            max_iterations: self.max_iterations.max(1),
            final_spp: self.final_spp.map(|n| n.max(2)),
            first_pixels: self.first_pixels,
            pseudo_textures: !self.no_pseudo_textures,
            mirror_views: !self.no_mirror_views,
            stray_light: self.stray_light,
            unseen: matfit::fit::unseen::UnseenOptions {
                enabled: !self.white_unseen,
                ..d.unseen.clone()
            },
            hierarchy: matfit::fit::HierarchyOptions {
                thresholds: matfit::fit::level::Thresholds {
                    // --lambert: level 1's threshold met by every fit.
                    diffuse: if self.lambert {
                        f32::MAX
                    } else {
                        d.hierarchy.thresholds.diffuse
                    },
                    texture_error: textures_off.unwrap_or(self.texture_error),
                    texture_detail: textures_off.unwrap_or(self.texture_detail),
                    ..d.hierarchy.thresholds.clone()
                },
                microfacet: !self.no_microfacet,
                ward: self.exportable != Some(recover::Exportable::Mitsuba),
                ..d.hierarchy.clone()
            },
            cache: matfit::fit::cache::CacheOptions {
                light_samples: self.light_samples.max(2),
                indirect_samples: self.indirect_samples.max(2),
                max_pixels: self.max_pixels.max(16),
                ..d.cache.clone()
            },
            ..d
        }
    }
}

/// Loads a scene and prints its warnings (group names that look like typos).
fn load(path: &Path) -> Result<(Scene, matfit::scene::lint::Lighting)> {
    let sc = load_scene(path)?;
    let l = matfit::api::checks::scene_warnings(&sc, &out::TERM);
    Ok((sc, l))
}

/// The command line that continues an interrupted `recover`.
fn resume_command() -> String {
    let mut args: Vec<String> = std::env::args()
        .map(|a| {
            if a.contains(|c: char| c.is_whitespace() || c == '\'') {
                format!("'{}'", a.replace('\'', "'\\''"))
            } else {
                a
            }
        })
        .collect();
    if !args.iter().any(|a| a == "--resume") {
        args.push("--resume".into());
    }
    args.join(" ")
}

/// Runs one command.
pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Render(a) => render::command(a),
        Command::Composite(a) => composite::command(a),
        Command::Recover(a) => recover::command(a),
        Command::Demo(a) => demo::command(a),
        Command::Hdr(a) => hdr::command(a),
        Command::Info(a) => info::command(a),
        Command::Inspect(a) => inspect::command(a),
        Command::Export(a) => export::command(a),
        Command::Import(a) => import::command(a),
        Command::Bench(a) => bench::command(a),
    }
}

/// `DX,DY` in pixels.
fn parse_vec3(s: &str) -> Result<[f32; 3], String> {
    let bad = || format!("expected X,Y,Z (e.g. 0,1.5,3), got {s:?}");
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad())?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(bad()),
    }
}

fn parse_shift(s: &str) -> Result<(f32, f32), String> {
    let bad = || format!("expected DX,DY in pixels (e.g. 2,0), got {s:?}");
    let (a, b) = s.split_once(',').ok_or_else(bad)?;
    let dx: f32 = a.trim().parse().map_err(|_| bad())?;
    let dy: f32 = b.trim().parse().map_err(|_| bad())?;
    if !(dx.is_finite() && dy.is_finite()) {
        return Err(bad());
    }
    Ok((dx, dy))
}
