//! The `matfit` command line: clap's description of the commands and what each one runs. The
//! library knows nothing of it.

pub mod bench;
pub mod checks;
pub mod composite;
pub mod demo;
pub mod hdr;
pub mod out;
pub mod recover;
pub mod table;

use crate::outln;
use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use matfit::io::atomic::{check_output_file, prepare_output_dir};
use matfit::io::image::Image;
use matfit::math::Rgb;
use matfit::photo::{PhotoArgs, Response};
use matfit::render::aov::{aov_image, Aov};
use matfit::render::film::{render, RenderOptions};
use matfit::scene::edit::{load_edited, Edit, EditFlags};
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
    "Scene file (TOML): camera, objects with their groups and materials, lights; see README";
/// The photograph.
const PHOTO_HELP: &str = "Photograph of the scene taken through the scene's camera: EXR, HDR or \
                          PFM (linear), or PNG/JPEG (8/16-bit, through --response); merge \
                          exposure brackets into one with `matfit hdr`";

#[derive(Subcommand)]
pub enum Command {
    /// Render a scene: a path-traced image, or an index buffer / AOV.
    Render {
        #[arg(help = SCENE_HELP)]
        scene: PathBuf,
        /// Output image: .exr, .hdr, .pfm (linear) or .png (sRGB preview).
        #[arg(short, long)]
        output: PathBuf,
        /// Samples per pixel, at least 1 [default: the scene's [render] spp].
        #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
        spp: Option<u32>,
        /// Random seed [default: the scene's [render] seed].
        #[arg(long, value_name = "S")]
        seed: Option<u64>,
        /// What to write: the image, or per pixel the group / object seen (directly or through a
        /// mirror), the normal, the depth (scene units) or the UV.
        #[arg(long, value_enum, default_value = "beauty")]
        aov: AovArg,
        /// Render the scene as one of its [[view]]s sees it (its camera and lights): a number
        /// from 1 or a view's name [default: the scene's [camera] and every light].
        #[arg(long, value_name = "VIEW")]
        view: Option<String>,
        #[command(flatten)]
        edits: EditCli,
    },
    /// Render an edited scene into the photo by differential rendering (Debevec 1998): a new
    /// object's shadows and reflections fall on the photographed surfaces.
    Composite {
        /// The recovered scene (`recover`'s recovered.toml), whose camera is the photo's.
        #[arg(
            help = "Scene file (TOML): the recovered scene (recover's recovered.toml), whose camera is the photo's"
        )]
        scene: PathBuf,
        #[arg(help = PHOTO_HELP)]
        photo: PathBuf,
        /// Output image: .png (sRGB), or .exr, .hdr, .pfm (linear, the photo's units).
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        edits: EditCli,
        /// Samples per pixel of each of the two renders [default: the scene's [render] spp].
        #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
        spp: Option<u32>,
        /// Random seed of both renders [default: the scene's [render] seed].
        #[arg(long, value_name = "S")]
        seed: Option<u64>,
        /// Response curve of an 8/16-bit photo: srgb, linear, gamma:G or table:FILE.
        #[arg(long, default_value = "srgb", value_parser = Response::parse)]
        response: Response,
        /// Exposure factor k of the photo (its linear values = k × radiance) [default: the one
        /// in results.json beside SCENE, else 1].
        #[arg(long, value_name = "K")]
        exposure: Option<f32>,
    },
    /// Recover the materials of a scene's groups from a photograph.
    Recover {
        #[arg(help = SCENE_HELP)]
        scene: PathBuf,
        /// Photograph of the scene: EXR, HDR or PFM (linear), or PNG/JPEG/TIFF (8/16-bit,
        /// through --response). Several photos are fitted together, photo K through the scene's
        /// [[view]] K (its camera and lights), each with its own fitted exposure factor.
        #[arg(required = true, num_args = 1.., value_name = "PHOTO")]
        photos: Vec<PathBuf>,
        /// The [[view]] each photo is taken through, in the photos' order: numbers from 1 or
        /// names, comma-separated [default: 1, 2, 3, ...].
        #[arg(long, value_name = "V1,V2,...", value_delimiter = ',')]
        views: Vec<String>,
        /// Output folder (created if needed; a folder with other files is refused unless --force).
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        fit: FitArgs,
        #[command(flatten)]
        photo_args: PhotoCli,
        /// Continue a run in OUTPUT that was interrupted, from its last checkpoint.
        #[arg(long)]
        resume: bool,
        /// Write into OUTPUT even if it holds files that are not a matfit output.
        #[arg(long)]
        force: bool,
    },
    /// Render a scene's photo with its true materials, recover them blind, print true vs
    /// recovered values (the course notes' Figure 6 with the default scene).
    Demo {
        /// Scene whose materials are the truth [default: scenes/figure6/scene.toml].
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Output folder; the photo is kept there for the next run.
        #[arg(short, long, default_value = "out/demo")]
        output: PathBuf,
        /// Samples per pixel of the photo.
        #[arg(long, value_name = "N", default_value_t = 512, value_parser = clap::value_parser!(u32).range(1..))]
        photo_spp: u32,
        /// Relative Gaussian noise added to the photo, as a standard deviation (0.01 = 1%).
        #[arg(long, value_name = "SIGMA", default_value_t = 0.0)]
        noise: f32,
        /// Misregister the model: shift the camera given to the recovery by DX,DY pixels.
        #[arg(long, value_name = "DX,DY", value_parser = parse_shift, default_value = "0,0")]
        shift: (f32, f32),
        /// Give the recovery the camera as it is, without refining its pose (as `recover
        /// --camera-is-calibrated`).
        #[arg(long)]
        camera_is_calibrated: bool,
        /// Write into OUTPUT even if it holds files that are not a matfit output.
        #[arg(long)]
        force: bool,
        #[command(flatten)]
        fit: FitArgs,
    },
    /// Merge LDR exposure brackets (8/16-bit PNG or JPEG of one scene from one viewpoint) into
    /// one linear image for `recover`: the weighted average of response⁻¹(code) / time with
    /// Debevec & Malik's hat weight (1997, eq. 6), which drops clipped and black codes.
    #[command(after_help = "Example:\n  \
        matfit hdr a.png b.png c.png --times 1/60,1/15,1/4 -o photo.exr --response-out curve.txt\n  \
        matfit recover scene.toml photo.exr -o out --grey-card card=0.18\n\n\
        A recovered response is known up to one factor (so is the merged radiance): calibrate \
        the exposure in recover with --grey-card or --exposure-from-lights.")]
    Hdr {
        /// The brackets, in any order, all of one size and bit depth.
        #[arg(required = true, num_args = 2.., value_name = "IMAGE")]
        images: Vec<PathBuf>,
        /// Exposure time of each image, in the images' order, fractions or decimals; required
        /// (e.g. 1/60,1/15,0.25). Only their ratios matter to the merge.
        #[arg(long, value_name = "T1,T2,...", value_parser = hdr::parse_times)]
        times: hdr::Times,
        /// Output image: .exr, .pfm or .hdr (linear).
        #[arg(short, long)]
        output: PathBuf,
        /// Response curve of the brackets: recover (from the brackets themselves, Debevec &
        /// Malik's least squares on a smooth curve), srgb, linear, gamma:G (linear = code^G) or
        /// table:FILE.
        #[arg(long, value_name = "R", default_value = "recover", value_parser = hdr::parse_response)]
        response: hdr::HdrResponse,
        /// Write the recovered response here, as a table that --response table:FILE reads
        /// (linear values, one row per code) [default: not written].
        #[arg(long, value_name = "FILE")]
        response_out: Option<PathBuf>,
    },
    /// Print a summary of a scene file: camera, render settings, groups with their materials,
    /// lights.
    Info {
        #[arg(help = SCENE_HELP)]
        scene: PathBuf,
    },
    /// Check a photo against the model before fitting: group outlines over the photo, the
    /// usable-pixel masks, per-group visible / usable / rejected pixel counts, the exposure.
    Inspect {
        #[arg(help = SCENE_HELP)]
        scene: PathBuf,
        #[arg(help = PHOTO_HELP)]
        photo: PathBuf,
        /// Output folder for outlines.png, usable.png, edges.png.
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        photo_args: PhotoCli,
        /// Write into OUTPUT even if it holds files that are not a matfit output.
        #[arg(long)]
        force: bool,
    },
    /// Export a scene to another renderer: `matfit export mitsuba SCENE -o DIR` writes
    /// DIR/scene.xml (Mitsuba 3) and DIR/meshes/*.ply; `matfit export gltf SCENE -o OUT.glb`
    /// one binary glTF 2.0 file. Approximations are printed as warnings.
    Export {
        /// Target renderer.
        format: FormatArg,
        #[arg(help = SCENE_HELP)]
        scene: PathBuf,
        /// Output folder (mitsuba; created if needed) or .glb file (gltf).
        #[arg(short, long)]
        output: PathBuf,
        /// Write into OUTPUT even if it holds files that are not a matfit output (mitsuba).
        #[arg(long)]
        force: bool,
        /// Export the scene as one of its [[view]]s sees it (its camera and lights): a number
        /// from 1 or a view's name [default: the scene's [camera] and every light].
        #[arg(long, value_name = "VIEW")]
        view: Option<String>,
    },
    /// Import another renderer's scene: `matfit import mitsuba SCENE.xml -o scene.toml` writes a
    /// matfit scene file (mesh and texture paths relative to it); approximations are printed as
    /// warnings and listed in the file's header.
    Import {
        /// Source renderer.
        format: ImportFormatArg,
        /// The scene file to read (Mitsuba 3 XML).
        input: PathBuf,
        /// Output scene file (.toml).
        #[arg(short, long)]
        output: PathBuf,
        /// Set a scene parameter ($NAME in the XML), overriding its <default> (e.g. -D spp=256;
        /// repeatable).
        #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_param)]
        define: Vec<(String, String)>,
    },
    /// Measure how fast this machine traces rays (to compare machines or builds; not needed
    /// to use matfit).
    Bench {
        #[command(subcommand)]
        which: BenchCommand,
    },
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
/// applied in that order (edit file format: `matfit::scene::edit`, README "Editing").
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
    /// table:FILE (format in README, "Photographs"). EXR/HDR/PFM photos are linear.
    #[arg(long, default_value = "srgb", value_parser = Response::parse)]
    pub response: Response,
    /// Exposure factor k, the photo's linear values = k × radiance [default: 1, unless
    /// calibrated by --grey-card or --exposure-from-lights].
    #[arg(long, value_name = "K", conflicts_with_all = ["grey_card", "exposure_from_lights"])]
    pub exposure: Option<f32>,
    /// Calibrate the exposure from a group of known diffuse reflectance: GROUP=RHO or
    /// GROUP=R,G,B (e.g. a grey card: --grey-card card=0.18).
    #[arg(long, value_name = "GROUP=RHO", value_parser = matfit::photo::args::parse_grey_card,
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
    /// Samples per pixel of the final render (at least 2: its two halves give the noise floor).
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
    /// Texture threshold on fine detail: a group whose best uniform model leaves coherent
    /// detail of at least this fraction of its radiance (averaged away in ε's tiles) tries
    /// level 7 even with a small ε.
    #[arg(long, value_name = "D", default_value_t = 0.02, value_parser = positive_f32)]
    texture_detail: f32,
    /// Never climb to level 7 (textures): uniform materials only, as before textures existed.
    #[arg(long)]
    no_textures: bool,
    /// Never try levels 8, 9 and 10, the microfacet lobes (isotropic, plastic, anisotropic): the
    /// Ward lobes alone, as before they existed (to measure what they gain).
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
            hierarchy: matfit::fit::hierarchy::HierarchyOptions {
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

#[derive(Subcommand)]
pub enum BenchCommand {
    /// Primary rays per second on a scene and on a generated mesh of ≥ 1M triangles.
    Rays {
        /// Scene to trace.
        #[arg(long, default_value = "scenes/figure6/scene.toml")]
        scene: PathBuf,
        /// Triangles of the generated mesh.
        #[arg(long, value_name = "N", default_value_t = 1_000_000)]
        triangles: usize,
        /// Repetitions (the median is reported).
        #[arg(long, value_name = "N", default_value_t = 5)]
        repeat: usize,
        /// Instead: time one thread's closest-hit and shadow queries on the rays of this file
        /// (little-endian f32 records: origin xyz, direction xyz, shadow-ray length; written
        /// by bench/rays.py, which times Mitsuba 3 on the same rays).
        #[arg(long)]
        ray_file: Option<PathBuf>,
    },
}

/// Loads a scene and prints its warnings (group names that look like typos).
fn load(path: &Path) -> Result<(Scene, matfit::scene::lint::Lighting)> {
    let sc = load_scene(path)?;
    let l = checks::scene_warnings(&sc);
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

pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Render {
            scene,
            output,
            spp,
            seed,
            aov,
            view,
            edits,
        } => {
            let edits = edits.edits()?;
            let (mut sc, mut lighting) = if edits.is_empty() {
                load(&scene)?
            } else {
                let sc = load_edited(&scene, &edits)?;
                let l = checks::scene_warnings(&sc);
                (sc, l)
            };
            if let Some(v) = &view {
                let k = sc.view_index(v).map_err(anyhow::Error::msg)?;
                sc = sc.in_view(k);
                lighting = matfit::scene::lint::lighting(&sc);
            }
            let ext = output
                .extension()
                .and_then(|e| e.to_str())
                .unwrap_or("")
                .to_ascii_lowercase();
            if !["exr", "hdr", "pfm", "png"].contains(&ext.as_str()) {
                bail!(
                    "{}: output must end in .exr, .hdr, .pfm or .png",
                    output.display()
                );
            }
            // Before minutes of rendering: the file must be writable.
            check_output_file(&output).map_err(anyhow::Error::msg)?;
            let t = Instant::now();
            let aov = Aov::from(aov);
            let (img, what): (Image, String) = match aov {
                Aov::Beauty => {
                    checks::require_light(&sc, &lighting)?;
                    let spp = spp.unwrap_or(sc.render.spp).max(1);
                    let opts = RenderOptions {
                        spp,
                        seed: seed.unwrap_or(sc.render.seed),
                        progress: true,
                    };
                    let t = Instant::now();
                    let img = render(&sc, &sc.camera, &opts);
                    // bench/ reads this (MATFIT_LOG=info): the render alone, to 10 ms.
                    tracing::info!("rendered in {:.2} s", t.elapsed().as_secs_f64());
                    (img, format!("{spp} spp"))
                }
                other => (
                    aov_image(&sc, &sc.camera, other, ext == "png"),
                    format!("{other:?} AOV").to_lowercase(),
                ),
            };
            img.write(&output).map_err(anyhow::Error::msg)?;
            outln!(
                "wrote {} ({}×{}, {what}) in {:.1} s",
                output.display(),
                img.width,
                img.height,
                t.elapsed().as_secs_f64()
            );
            Ok(())
        }
        Command::Composite {
            scene,
            photo,
            output,
            edits,
            spp,
            seed,
            response,
            exposure,
        } => composite::run(&composite::CompositeArgs {
            scene,
            photo,
            output,
            edits: edits.edits()?,
            spp,
            seed,
            response,
            exposure,
        }),
        Command::Recover {
            scene,
            photos,
            views: view_keys,
            output,
            fit,
            photo_args,
            resume,
            force,
        } => {
            let (sc, lighting) = load(&scene)?;
            checks::require_light(&sc, &lighting)?;
            let photo_args = PhotoArgs::from(photo_args);
            // Photo k through view k (or --views); one photo of a scene without views: the
            // scene itself.
            if !view_keys.is_empty() && view_keys.len() != photos.len() {
                bail!(
                    "--views names {} view(s) for {} photo(s): give one per photo",
                    view_keys.len(),
                    photos.len()
                );
            }
            let chosen: Vec<usize> = if view_keys.is_empty() {
                if photos.len() > sc.views.len().max(1) {
                    bail!(
                        "{} photos given but {} has {} [[view]] table(s): photo K is taken \
                         through view K (its camera and lights), so give a [[view]] for every \
                         photo",
                        photos.len(),
                        scene.display(),
                        sc.views.len()
                    );
                }
                (0..photos.len()).collect()
            } else {
                view_keys
                    .iter()
                    .map(|k| sc.view_index(k))
                    .collect::<Result<_, _>>()
                    .map_err(anyhow::Error::msg)?
            };
            let mut scenes: Vec<Scene> = if sc.views.is_empty() {
                vec![sc.clone()]
            } else {
                chosen.iter().map(|&k| sc.in_view(k)).collect()
            };
            // Before any work: the output folder must be usable.
            if !resume {
                checks::output_folder(&output, force)?;
            }
            prepare_output_dir(&output).map_err(anyhow::Error::msg)?;
            let mut prepared = Vec::new();
            for (view, photo) in scenes.iter().zip(&photos) {
                let p =
                    matfit::photo::prepare(view, photo, &photo_args).map_err(anyhow::Error::msg)?;
                // Once the photo is known to be readable (an unreadable one gets only its error).
                checks::exposure_warning(photo, &photo_args, &lighting);
                prepared.push(p);
            }
            checks::on_interrupt_say_resume(resume_command());
            let mut opts = fit.options();
            if prepared[0].calibration.is_some() {
                opts.grey_card = photo_args
                    .grey_card
                    .clone()
                    .map(|(group, rho)| matfit::fit::recover::GreyCard { group, rho });
            }
            if photo_args.register && photo_args.refine_pose {
                let names: Vec<String> = chosen[1..]
                    .iter()
                    .map(|&k| sc.views[k].name.clone())
                    .collect();
                let quick = recover::refine_poses_with_a_quick_fit(
                    &scenes,
                    &photos,
                    &mut prepared,
                    &names,
                    &photo_args,
                    &opts,
                )
                .map_err(anyhow::Error::msg)?;
                if let Some((n, s)) = quick {
                    outln!(
                        "pose refined again against a quick fit's materials ({n} round{}, \
                         {s:.1} s): {}",
                        if n == 1 { "" } else { "s" },
                        prepared
                            .iter()
                            .filter_map(|p| p.registration.as_ref())
                            .map(|r| format!(
                                "turned {:.3}°, moved {:.4} units",
                                r.rotation_deg,
                                r.translation.length()
                            ))
                            .collect::<Vec<_>>()
                            .join("; ")
                    );
                }
            }
            for ((view, photo), p) in scenes.iter_mut().zip(&photos).zip(&prepared) {
                checks::exposure_report(view, photo, &photo_args, p);
                if let Some(m) = &photo_args.ignore_mask {
                    outln!("{}", checks::masked_summary(view, m, p));
                }
                // Render through the camera registered to the photo.
                view.camera = p.camera.clone();
            }
            let mut inputs = recover::inputs(
                &scene,
                &photos[0],
                &prepared[0],
                photo_args.exposure.is_some(),
                photo_args.ignore_mask.as_deref(),
                &opts,
            );
            if photos.len() > 1 {
                inputs.photos = photos.iter().map(|p| p.display().to_string()).collect();
            }
            let (first, rest) = scenes.split_first().expect("one photo at least");
            let views: Vec<matfit::fit::recover::PhotoView> = rest
                .iter()
                .zip(&prepared[1..])
                .enumerate()
                .map(|(k, (s, p))| matfit::fit::recover::PhotoView {
                    name: sc.views[chosen[k + 1]].name.clone(),
                    scene: s,
                    photo: &p.photo,
                    mask: &p.mask,
                })
                .collect();
            let rec = recover::run_recover(
                first,
                &prepared[0].photo,
                &prepared[0].mask,
                &views,
                &opts,
                &output,
                resume,
                &inputs,
            )
            .map_err(anyhow::Error::msg)?;
            outln!();
            out::print(format_args!("{}", table::recovered(&rec)));
            if !rec.views.is_empty() {
                outln!("photos fitted together (exposure factor k: photo = k × the recovered scene's radiance; geometric mean 1):");
                for (v, p) in rec.views.iter().zip(&photos) {
                    outln!(
                        "  {:<12} {}  k = {:.4}  residual {:.2}% over {} px",
                        v.name,
                        p.display(),
                        v.exposure,
                        100.0 * v.residual,
                        v.pixels
                    );
                }
            }
            if let Some(s) = &rec.stray_light {
                outln!("{}", s.describe());
            }
            if let Some(card) = opts
                .grey_card
                .as_ref()
                .filter(|_| rec.exposure_factor != 1.0)
            {
                outln!(
                    "exposure k = {:.6} recalibrated from grey card '{}' with the recovered \
                     materials around it (before the fit: {:.6}, the others' materials unknown)",
                    prepared[0].photo.exposure * rec.exposure_factor,
                    card.group,
                    prepared[0].photo.exposure
                );
            }
            outln!(
                "outputs in {} ({:.1} s): recovered.toml, results.json, report.html",
                output.display(),
                rec.total_s
            );
            for g in rec.groups.iter() {
                if let Some(n) = &g.note {
                    outln!("note: {}: {n}", g.name);
                }
            }
            out::repeat_warnings();
            Ok(())
        }
        Command::Demo {
            scene,
            output,
            photo_spp,
            noise,
            shift,
            camera_is_calibrated,
            force,
            fit,
        } => {
            checks::output_folder(&output, force)?;
            let opts = demo::DemoOptions {
                scene,
                out: output,
                photo_spp,
                noise,
                shift,
                register: !camera_is_calibrated,
                recover: fit.options(),
            };
            demo::run(&opts).map_err(anyhow::Error::msg)?;
            out::repeat_warnings();
            Ok(())
        }
        Command::Hdr {
            images,
            times,
            output,
            response,
            response_out,
        } => hdr::run(&hdr::HdrArgs {
            images,
            times: times.0,
            output,
            response,
            response_out,
        }),
        Command::Info { scene } => {
            let (sc, lighting) = load(&scene)?;
            info(&sc, &lighting);
            Ok(())
        }
        Command::Inspect {
            scene,
            photo,
            output,
            photo_args,
            force,
        } => {
            let (sc, lighting) = load(&scene)?;
            let photo_args = PhotoArgs::from(photo_args);
            checks::output_folder(&output, force)?;
            prepare_output_dir(&output).map_err(anyhow::Error::msg)?;
            let report = matfit::photo::inspect::inspect(&sc, &photo, &photo_args, &output)
                .map_err(anyhow::Error::msg)?;
            out::print(format_args!("{report}"));
            checks::exposure_warning(&photo, &photo_args, &lighting);
            Ok(())
        }
        Command::Export {
            format,
            scene,
            output,
            force,
            view,
        } => {
            let (mut sc, _) = load(&scene)?;
            if let Some(v) = &view {
                sc = sc.in_view(sc.view_index(v).map_err(anyhow::Error::msg)?);
            }
            let report = match format {
                FormatArg::Mitsuba => {
                    checks::output_folder(&output, force)?;
                    prepare_output_dir(&output).map_err(anyhow::Error::msg)?;
                    matfit::export::mitsuba::export(&sc, &output).map_err(anyhow::Error::msg)?
                }
                FormatArg::Gltf => {
                    let ext = output.extension().and_then(|e| e.to_str()).unwrap_or("");
                    if !ext.eq_ignore_ascii_case("glb") {
                        bail!("{}: output must end in .glb", output.display());
                    }
                    check_output_file(&output).map_err(anyhow::Error::msg)?;
                    matfit::export::gltf::export(&sc, &output).map_err(anyhow::Error::msg)?
                }
            };
            for w in &report.warnings {
                out::warn(w.clone());
            }
            match report.files.len() {
                1 => outln!("wrote {}", report.files[0].display()),
                n => outln!("wrote {} ({n} files)", report.files[0].display()),
            }
            Ok(())
        }
        Command::Import {
            format,
            input,
            output,
            define,
        } => {
            let ext = output.extension().and_then(|e| e.to_str()).unwrap_or("");
            if !ext.eq_ignore_ascii_case("toml") {
                bail!(
                    "{}: the output scene file must end in .toml",
                    output.display()
                );
            }
            check_output_file(&output).map_err(anyhow::Error::msg)?;
            let report = match format {
                ImportFormatArg::Mitsuba => {
                    matfit::import::mitsuba::import(&input, &output, &define)
                        .map_err(anyhow::Error::msg)?
                }
            };
            let folder = match output.parent() {
                Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
                _ => std::path::PathBuf::from("."),
            };
            report.write_files(&folder).map_err(anyhow::Error::msg)?;
            // The written file must be a scene that loads (its meshes found from its folder).
            matfit::scene::load::parse_scene(&report.toml, &output)
                .map_err(|e| anyhow::anyhow!("the imported scene does not load: {e}"))?;
            matfit::io::atomic::write_atomic(&output, report.toml.as_bytes())
                .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", output.display()))?;
            for w in &report.warnings {
                out::warn(w.clone());
            }
            outln!(
                "wrote {} ({} warning{}){}",
                output.display(),
                report.warnings.len(),
                if report.warnings.len() == 1 { "" } else { "s" },
                match report.textures.len() {
                    0 => String::new(),
                    n => format!(
                        " and {n} texture{} turned to matfit's texture coordinates in {}",
                        if n == 1 { "" } else { "s" },
                        folder.join("textures").display()
                    ),
                }
            );
            Ok(())
        }
        Command::Bench { which } => match which {
            BenchCommand::Rays {
                scene,
                triangles,
                repeat,
                ray_file,
            } => {
                let sc = load_scene(&scene).with_context(|| "loading the benchmark scene")?;
                match ray_file {
                    Some(f) => bench::ray_file(&sc, &f, repeat)?,
                    None => bench::rays(&sc, triangles, repeat),
                }
                Ok(())
            }
        },
    }
}

/// `info`: the camera, render settings, groups with their objects and materials, lights.
fn info(sc: &Scene, lighting: &matfit::scene::lint::Lighting) {
    use table::{num, rgb, vec3};
    let c = &sc.camera;
    outln!("scene {}", sc.path.display());
    outln!(
        "camera {}×{} px, eye {}, looking along {}, {}, fx {} fy {} px{}",
        c.width,
        c.height,
        vec3(c.eye()),
        vec3(
            c.ray(matfit::math::Vec2::new(
                c.width as f32 / 2.0,
                c.height as f32 / 2.0
            ))
            .d
        ),
        match (c.fov_y_deg(), c.film_size_m()) {
            (Some(fov), _) => format!("fov_y {}°", num(fov, 3)),
            (None, Some(s)) => format!(
                "orthographic, film {} × {} scene units",
                num(s.x, 4),
                num(s.y, 4)
            ),
            (None, None) => unreachable!("a camera is perspective or orthographic"),
        },
        num(c.fx, 2),
        num(c.fy, 2),
        if c.is_orthographic() { " per unit" } else { "" }
    );
    let r = &sc.render;
    outln!(
        "render spp {}, max_depth {}, rr_depth {}, seed {}, ward_variant {}",
        r.spp,
        r.max_depth,
        r.rr_depth,
        r.seed,
        r.ward_variant.name()
    );
    outln!("triangles {}", sc.triangle_count());
    for g in &sc.groups {
        let names: Vec<&str> = g
            .objects
            .iter()
            .map(|&o| sc.objects[o].name.as_str())
            .collect();
        let mats: Vec<String> = {
            let mut m: Vec<String> = g
                .objects
                .iter()
                .filter(|&&o| !sc.objects[o].is_emitter())
                .map(|&o| table::material(&sc.objects[o].material))
                .collect();
            m.dedup();
            m
        };
        outln!(
            "group {}{}: {}{}",
            g.name,
            if g.fixed { " (fixed)" } else { "" },
            names.join(", "),
            if mats.is_empty() {
                String::new()
            } else {
                format!("; {}", mats.join(" | "))
            }
        );
    }
    for (i, o) in sc
        .objects
        .iter()
        .enumerate()
        .filter(|(_, o)| o.is_emitter())
    {
        outln!(
            "light {}: radiance {}, area {}{}",
            o.name,
            rgb(o.emission),
            num(o.area, 4),
            if lighting.facing_away.contains(&i) {
                " (faces away from everything in view)"
            } else {
                ""
            }
        );
    }
    for l in &sc.punctual_lights {
        use matfit::scene::Punctual;
        outln!(
            "light {}: {}",
            l.name,
            match l.kind {
                Punctual::Directional {
                    direction,
                    irradiance,
                    angle,
                } => format!(
                    "directional, travelling along {}, irradiance {}{}",
                    vec3(direction),
                    rgb(irradiance),
                    if angle > 0.0 {
                        format!(", {}° wide", num(angle.to_degrees(), 3))
                    } else {
                        String::new()
                    }
                ),
                Punctual::Point {
                    position,
                    intensity,
                } => format!("point at {}, intensity {}", vec3(position), rgb(intensity)),
                Punctual::Spot {
                    position,
                    direction,
                    intensity,
                    cutoff,
                    beam_width,
                } => format!(
                    "spot at {} along {}, intensity {}, beam {}°, cutoff {}°",
                    vec3(position),
                    vec3(direction),
                    rgb(intensity),
                    num(beam_width.to_degrees(), 3),
                    num(cutoff.to_degrees(), 3)
                ),
            }
        );
    }
    if let Some(e) = &sc.environment {
        outln!("environment: {e:?}");
    }
    for (k, v) in sc.views.iter().enumerate() {
        outln!(
            "view {} '{}': lights {}; camera {}",
            k + 1,
            v.name,
            v.lights
                .as_ref()
                .map_or("all".to_string(), |l| l.join(", ")),
            if v.camera == sc.camera {
                "[camera]".to_string()
            } else {
                format!(
                    "eye {}, {}×{} px",
                    vec3(v.camera.eye()),
                    v.camera.width,
                    v.camera.height
                )
            }
        );
    }
    if lighting.none() {
        out::warn(format!("{}: nothing emits light", sc.path.display()));
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
