//! How to read a photo ([`PhotoArgs`], what the `inspect` and `recover` commands' options
//! fill in), and [`prepare`]: photo file + scene → linear photo with its
//! exposure divided out, index buffers and usable-pixel mask.

use crate::math::Rgb;
use crate::photo::{ignore, load_photo, Photo, PhotoOptions, Response};
use crate::prepare::exposure::{self, ExposureCalibration, ExposureSource};
use crate::prepare::pose::{self, Pose};
use crate::prepare::{coverage, mask, UsableMask};
use crate::render::aov::{index_buffers, IndexBuffers};
use crate::scene::{Camera, Scene};
use std::path::{Path, PathBuf};

/// How to read a photograph and choose its usable pixels.
#[derive(Clone, Debug)]
pub struct PhotoArgs {
    /// Response curve of 8/16-bit photos: srgb, linear, gamma:G (linear = code^G) or
    /// table:FILE (the table format: `photo::response`). Float photos are linear.
    pub response: Response,
    /// Exposure factor k: the photo's linear values are k × radiance.
    pub exposure: Option<f32>,
    /// Calibrate the exposure from a group of known diffuse reflectance: GROUP=RHO or
    /// GROUP=R,G,B (e.g. a grey card: --grey-card card=0.18).
    pub grey_card: Option<(String, Rgb)>,
    /// Calibrate the exposure from the light sources seen in the photo (known radiance).
    pub exposure_from_lights: bool,
    /// Half-width in pixels of the band removed around every boundary between objects.
    pub band: usize,
    /// Edge-detector threshold on |∇ ln luminance| per pixel; 0 turns the detector off.
    pub edge_threshold: f32,
    /// Reject pixels of planar groups far from a plane fitted to their intensity (unmodelled
    /// objects on diffuse walls; do not use it on glossy groups, it would drop highlights).
    pub planar_outliers: bool,
    /// Refine the camera's pose so that the model's edges meet the photo's (`photo::pose`);
    /// false: the camera is calibrated, use it as given.
    pub register: bool,
    /// Refine all six degrees of freedom of the pose (`photo::pose::refine`) rather than a
    /// shift of the film (`photo::pose::from_shift`). False here; the command line's default is
    /// true (`--film-shift` makes it false), and `demo`, whose misregistration is a film shift,
    /// keeps false.
    pub refine_pose: bool,
    /// Largest misregistration searched, in pixels (None: [`super::pose::DEFAULT_SHIFT`] for a
    /// film shift, [`super::pose::start_search`] for the pose refinement).
    pub max_shift: Option<i32>,
    /// An image of the photo's size whose marked pixels are ignored (`photo::ignore`).
    pub ignore_mask: Option<PathBuf>,
    /// The lens's vignetting, divided out of the photo first (`photo::vignetting`).
    pub vignetting: Option<crate::photo::vignetting::Vignetting>,
}

impl Default for PhotoArgs {
    fn default() -> Self {
        PhotoArgs {
            response: Response::Srgb,
            exposure: None,
            grey_card: None,
            exposure_from_lights: false,
            band: 2,
            edge_threshold: 0.12,
            planar_outliers: false,
            register: true,
            refine_pose: false,
            max_shift: None,
            ignore_mask: None,
            vignetting: None,
        }
    }
}

/// Parses GROUP=RHO or GROUP=R,G,B.
pub fn parse_grey_card(s: &str) -> Result<(String, Rgb), String> {
    let (g, v) = s
        .split_once('=')
        .ok_or_else(|| format!("'{s}': expected GROUP=RHO or GROUP=R,G,B"))?;
    let nums: Result<Vec<f32>, _> = v.split(',').map(|t| t.trim().parse::<f32>()).collect();
    let nums = nums.map_err(|_| format!("'{v}': the reflectance is not a number"))?;
    let rho = match nums.as_slice() {
        [x] => Rgb::splat(*x),
        [r, g, b] => Rgb::new(*r, *g, *b),
        _ => return Err(format!("'{v}': give one reflectance or three")),
    };
    if !(rho.min_element() > 0.0 && rho.max_element() <= 1.0) {
        return Err(format!("'{v}': a reflectance must be in (0, 1]"));
    }
    Ok((g.trim().to_string(), rho))
}

impl PhotoArgs {
    pub fn photo_options(&self) -> PhotoOptions {
        PhotoOptions {
            response: self.response.clone(),
            exposure: self.exposure,
        }
    }

    pub fn mask_options(&self, scene: &Scene) -> mask::MaskOptions {
        mask::MaskOptions {
            band: self.band,
            edge_threshold: self.edge_threshold,
            planar_groups: if self.planar_outliers {
                mask::planar_groups(scene)
            } else {
                Vec::new()
            },
            ..Default::default()
        }
    }

    pub fn exposure_source(&self) -> ExposureSource {
        match (&self.grey_card, self.exposure_from_lights) {
            (Some((group, rho)), _) => ExposureSource::GreyCard {
                group: group.clone(),
                rho: *rho,
            },
            (None, true) => ExposureSource::Lights,
            (None, false) => ExposureSource::Given(self.exposure.unwrap_or(1.0)),
        }
    }
}

/// A photo ready for fitting.
#[derive(Clone, Debug)]
pub struct PreparedPhoto {
    /// Linear radiance: the exposure (given or calibrated) is divided out.
    pub photo: Photo,
    /// The scene's camera corrected by `registration`: render the synthetic images with it,
    /// so that they line up with the photo pixel for pixel.
    pub camera: Camera,
    /// The pose correction found between model and photo (None when registration is off).
    pub registration: Option<Pose>,
    /// The index buffers through `camera`.
    pub index: IndexBuffers,
    pub mask: UsableMask,
    /// Set when the exposure was calibrated rather than given.
    pub calibration: Option<ExposureCalibration>,
}

/// Loads the photo for `scene`'s camera, renders the index buffers, selects the usable pixels
/// and calibrates the exposure if asked. The mask does not depend on the exposure (the edge
/// detector and the planar test work on ln-intensity), so it is computed once, before.
pub fn prepare(scene: &Scene, path: &Path, args: &PhotoArgs) -> Result<PreparedPhoto, String> {
    prepare_at(scene, path, args, None)
}

/// [`prepare`] with the registration already found (`pose`, relative to `scene.camera`): no
/// search, the pose applied as [`prepare`] would apply it. The `recover` command prepares
/// again this way once a quick fit's materials have refined the pose
/// ([`pose::Shading::QuickFit`]).
pub fn prepare_at(
    scene: &Scene,
    path: &Path,
    args: &PhotoArgs,
    pose: Option<Pose>,
) -> Result<PreparedPhoto, String> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let photo = load_photo(path, w, h, &args.photo_options())?;
    prepare_loaded(scene, photo, path, args, pose)
}

/// [`prepare_at`] on a photo already loaded (`path` names it in messages).
pub fn prepare_loaded(
    scene: &Scene,
    mut photo: Photo,
    path: &Path,
    args: &PhotoArgs,
    pose: Option<Pose>,
) -> Result<PreparedPhoto, String> {
    let mut camera = scene.camera.clone();
    if let Some(v) = &args.vignetting {
        let dark = crate::photo::vignetting::correct(&mut photo, v, camera.cx, camera.cy)?;
        if dark > 0 {
            tracing::warn!(
                "{}: {dark} pixels too dark in the flat field to correct; not used",
                path.display()
            );
        }
    }
    if let Some(m) = &args.ignore_mask {
        let n = photo.set_ignored(ignore::load_ignore_mask(m, camera.width, camera.height)?);
        tracing::info!("{}: {n} pixels masked by the user", m.display());
    }
    let mut index = index_buffers(scene, &camera);
    let mut registration = None;
    if args.register {
        let r = if let Some(p) = pose {
            p
        } else if args.refine_pose {
            let m = args
                .max_shift
                .unwrap_or_else(|| pose::start_search(&camera));
            pose::refine(scene, &camera, &photo, m)
        } else {
            let m = args.max_shift.unwrap_or(pose::DEFAULT_SHIFT);
            pose::from_shift(&camera, &index, &photo, m)
        };
        if r.applied {
            camera = r.camera.clone();
            index = index_buffers(scene, &camera);
            tracing::info!(
                "{}: {}{}",
                path.display(),
                r.found(),
                match r.shading {
                    pose::Shading::SceneFile => "",
                    pose::Shading::QuickFit => ", against a quick fit's materials",
                }
            );
        }
        registration = Some(r);
    }
    let scene_reg;
    let scene = if camera != scene.camera {
        scene_reg = Scene {
            camera: camera.clone(),
            ..scene.clone()
        };
        &scene_reg
    } else {
        scene
    };
    let pure = coverage::pure_pixels(scene, &camera, &index);
    let mask = mask::usable_pixels_covered(
        &index,
        Some(&pure),
        &photo,
        scene.groups.len(),
        &args.mask_options(scene),
    );
    let calibration = match args.exposure_source() {
        ExposureSource::Given(_) => None,
        ExposureSource::GreyCard { group, rho } => Some(
            exposure::from_grey_card(scene, &photo, &mask, &group, rho, 4096)
                .map_err(|e| format!("{}: {e}", path.display()))?,
        ),
        ExposureSource::Lights => Some(
            exposure::from_lights(scene, &photo, &index, &mask)
                .map_err(|e| format!("{}: {e}", path.display()))?,
        ),
    };
    if let Some(c) = &calibration {
        photo.apply_exposure(c.factor);
    }
    Ok(PreparedPhoto {
        photo,
        camera,
        registration,
        index,
        mask,
        calibration,
    })
}
