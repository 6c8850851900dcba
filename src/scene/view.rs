//! Views: several photos of one scene, each taken through its own camera under its own lights
//! (a photometric-stereo rig turning one light on at a time, a camera walked around an
//! object), so that one set of materials is fitted to all of them (`fit/views.rs`).
//!
//! ```toml
//! [[view]]                     # the first photo given to `recover`
//! name = "east"                # optional (default: "view 1", "view 2", ...)
//! lights = ["sun_east"]        # the lights on: [[light]] names, emitting objects or groups,
//!                              # "environment" (default: every light of the scene)
//!
//! [[view]]                     # the second photo
//! lights = ["sun_west"]
//! camera = { eye = [2, 1, 0], target = [0, 0.5, 0], fov_y_deg = 40 }   # default: [camera]
//! ```
//!
//! Photo k goes with view k; a scene with views may be given fewer photos than it has views
//! (the rest are there for `matfit render --view K`, e.g. to predict a photo not fitted). A light
//! that is off keeps its geometry: an area light's quad still occludes, it only stops emitting.

use super::error::SceneError;
use super::schema::SceneFile;
use super::{Camera, Scene};
use crate::math::Rgb;
use std::path::Path;

/// One photo's view.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    pub name: String,
    pub camera: Camera,
    /// The lights on, by name; None: all.
    pub lights: Option<Vec<String>>,
    /// Line of the view's entry in the scene file (1-based), for messages.
    pub line: usize,
}

impl Scene {
    /// The scene as view `k` sees it: its camera, and only its lights emitting.
    pub fn in_view(&self, k: usize) -> Scene {
        let view = &self.views[k];
        let mut s = self.clone();
        s.camera = view.camera.clone();
        s.view = Some(k);
        if let Some(on) = &view.lights {
            let is_on = |n: &str| on.iter().any(|l| l == n);
            s.punctual_lights.retain(|l| is_on(&l.name));
            for o in s.objects.iter_mut() {
                if o.is_emitter() && !is_on(&o.name) && !is_on(&self.groups[o.group].name) {
                    o.emission = Rgb::ZERO;
                }
            }
            if !is_on("environment") {
                s.environment = None;
            }
        }
        s
    }

    /// The view of a 1-based number or a name, as `--view` takes it.
    pub fn view_index(&self, key: &str) -> Result<usize, crate::error::Error> {
        self.view_key(key).map_err(crate::error::Error::options)
    }

    fn view_key(&self, key: &str) -> Result<usize, String> {
        if self.views.is_empty() {
            return Err(format!(
                "{} has no [[view]]: --view needs a scene with views",
                self.path.display()
            ));
        }
        if let Ok(n) = key.parse::<usize>() {
            if (1..=self.views.len()).contains(&n) {
                return Ok(n - 1);
            }
        }
        self.views
            .iter()
            .position(|v| v.name == key)
            .ok_or_else(|| {
                let names: Vec<&str> = self.views.iter().map(|v| v.name.as_str()).collect();
                format!(
                    "no view '{key}': give 1 to {} or a name ({})",
                    self.views.len(),
                    names.join(", ")
                )
            })
    }
}

/// The scene file's views, checked against the loaded scene's lights.
pub(super) fn build_views(
    file: &SceneFile,
    scene: &Scene,
    text: &str,
    path: &Path,
) -> Result<Vec<View>, SceneError> {
    let mut names: Vec<&str> = scene
        .punctual_lights
        .iter()
        .map(|l| l.name.as_str())
        .collect();
    for o in scene.objects.iter().filter(|o| o.is_emitter()) {
        names.push(&o.name);
        names.push(&scene.groups[o.group].name);
    }
    if scene.environment.is_some() {
        names.push("environment");
    }
    let mut views: Vec<View> = Vec::new();
    for (k, v) in file.views.iter().enumerate() {
        let line = super::context::line_of(text, v.span().start);
        let spec = v.get_ref();
        let name = spec.name.clone().unwrap_or(format!("view {}", k + 1));
        let at = |message: String| SceneError::At {
            path: path.to_owned(),
            line,
            message: format!("[[view]] '{name}': {message}"),
        };
        if views.iter().any(|w| w.name == name) {
            return Err(at("two views have this name".into()));
        }
        let camera = match &spec.camera {
            None => scene.camera.clone(),
            Some(table) => {
                let cam = super::camera_spec::edited_camera(table, &file.camera).map_err(&at)?;
                let alone = SceneFile {
                    render: None,
                    camera: cam,
                    groups: Vec::new(),
                    objects: Vec::new(),
                    lights: Vec::new(),
                    environment: None,
                    stray_light: None,
                    views: Vec::new(),
                };
                super::camera_spec::check_camera(&alone, "", path).map_err(|e| {
                    at(match e {
                        SceneError::Scene { message, .. } | SceneError::At { message, .. } => {
                            message.replace("[camera]", "camera")
                        }
                        other => other.to_string(),
                    })
                })?
            }
        };
        if let Some(on) = &spec.lights {
            if on.is_empty() {
                return Err(at("`lights` is empty: a view needs a light on".into()));
            }
            for l in on {
                if !names.contains(&l.as_str()) {
                    let mut all = names.clone();
                    all.sort_unstable();
                    all.dedup();
                    return Err(at(format!(
                        "no light is named '{l}'; the scene's lights are: {}",
                        all.join(", ")
                    )));
                }
            }
        }
        views.push(View {
            name,
            camera,
            lights: spec.lights.clone(),
            line,
        });
    }
    Ok(views)
}
