//! matfit's Python module (`matfit._matfit`): a thin layer over the library's front door. The
//! Python package (`python/matfit/__init__.py`) wraps it; every call releases the GIL while it
//! renders or fits, and every matfit error becomes a Python exception of its kind.

// Python's keyword arguments are the command line's options, one Rust parameter each.
#![allow(clippy::too_many_arguments)]

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::{PyException, PyKeyboardInterrupt, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::mpsc::RecvTimeoutError;
use std::sync::Mutex;
use std::time::{Duration, Instant};

pyo3::create_exception!(matfit, MatfitError, PyException, "Any matfit error.");
pyo3::create_exception!(matfit, SceneError, MatfitError, "A scene file or an edit.");
pyo3::create_exception!(matfit, PhotoError, MatfitError, "A photograph.");
pyo3::create_exception!(matfit, RecoverError, MatfitError, "The recovery.");
pyo3::create_exception!(matfit, ExportError, MatfitError, "An export.");
pyo3::create_exception!(matfit, OptionsError, MatfitError, "An option or argument.");

/// A matfit error as the Python exception of its kind, with the same message.
fn py_err(e: matfit::Error) -> PyErr {
    use matfit::ErrorKind as K;
    let m = e.message().to_string();
    match e.kind() {
        K::Scene => SceneError::new_err(m),
        K::Photo => PhotoError::new_err(m),
        K::Recover => RecoverError::new_err(m),
        K::Export => ExportError::new_err(m),
        K::Options => OptionsError::new_err(m),
        K::Interrupted => PyKeyboardInterrupt::new_err(m),
        _ => MatfitError::new_err(m),
    }
}

/// The front door's observer for Python: progress to a Python callable (at most ten times a
/// second, and at the end), warnings to `warnings.warn`, the log kept, and Ctrl-C passed on as
/// the library's cancellation (see [`PyObserver::run`]).
struct PyObserver {
    progress: Option<Py<PyAny>>,
    last: Mutex<Option<Instant>>,
    log: Mutex<Vec<String>>,
    interrupt: Mutex<Option<PyErr>>,
    stop: AtomicBool,
}

impl PyObserver {
    fn new(progress: Option<Py<PyAny>>) -> PyObserver {
        PyObserver {
            progress,
            last: Mutex::new(None),
            log: Mutex::new(Vec::new()),
            interrupt: Mutex::new(None),
            stop: AtomicBool::new(false),
        }
    }

    /// Runs `work` without the GIL on a thread of its own, while this thread looks for signals
    /// every 50 ms: Python runs signal handlers only on its main thread, and the library asks
    /// `cancelled` from its own threads (a render between rows, a recovery between
    /// iterations). A KeyboardInterrupt sets the flag `cancelled` reads and is kept to be
    /// raised when the work has stopped.
    fn run<T: Send>(&self, py: Python<'_>, work: impl FnOnce() -> T + Send) -> T {
        py.detach(|| {
            std::thread::scope(|s| {
                let (done, finished) = std::sync::mpsc::channel();
                let worker = s.spawn(move || {
                    let out = work();
                    let _ = done.send(());
                    out
                });
                while let Err(RecvTimeoutError::Timeout) =
                    finished.recv_timeout(Duration::from_millis(50))
                {
                    if self.stop.load(Relaxed) {
                        continue;
                    }
                    if let Err(e) = Python::attach(|py| py.check_signals()) {
                        *self.interrupt.lock().unwrap() = Some(e);
                        self.stop.store(true, Relaxed);
                    }
                }
                worker
                    .join()
                    .unwrap_or_else(|p| std::panic::resume_unwind(p))
            })
        })
    }

    /// The error to raise for `e`: the KeyboardInterrupt caught, if that is what stopped it.
    fn error(&self, e: matfit::Error) -> PyErr {
        if e.kind() == matfit::ErrorKind::Interrupted {
            if let Some(k) = self.interrupt.lock().unwrap().take() {
                return k;
            }
        }
        py_err(e)
    }
}

impl matfit::Observer for PyObserver {
    fn warning(&self, text: &str) {
        Python::attach(|py| {
            let r = py
                .import("warnings")
                .and_then(|w| w.call_method1("warn", (text,)));
            if let Err(e) = r {
                e.restore(py);
            }
        });
    }
    fn progress(&self, p: &matfit::Progress) {
        let Some(cb) = &self.progress else { return };
        {
            let mut last = self.last.lock().unwrap();
            let now = Instant::now();
            let due = last.is_none_or(|t| now - t >= Duration::from_millis(100));
            if !(due || p.finished || p.done == 0) {
                return;
            }
            *last = Some(now);
        }
        Python::attach(|py| {
            let r = cb.call1(py, (p.task, p.done, p.total, p.message, p.finished));
            if let Err(e) = r {
                e.write_unraisable(py, None);
            }
        });
    }
    fn log(&self, line: &matfit::LogLine) {
        if let Ok(s) = serde_json::to_string(line) {
            self.log.lock().unwrap().push(s);
        }
    }
    fn cancelled(&self) -> bool {
        self.stop.load(Relaxed)
    }
}

/// An image as a float32 (H, W, 3) array.
fn rgb_array<'py>(py: Python<'py>, img: &matfit::Image) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f32> = img.data.iter().flat_map(|c| [c.x, c.y, c.z]).collect();
    Ok(PyArray1::from_vec(py, flat)
        .reshape([img.height, img.width, 3])?
        .into_any())
}

/// A float (H, W, 3) array of linear RGB as an image.
fn image_from(array: PyReadonlyArray3<'_, f32>) -> PyResult<matfit::Image> {
    let shape = array.shape();
    if shape[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "a photo array must be (H, W, 3), got {shape:?}"
        )));
    }
    let (h, w) = (shape[0], shape[1]);
    let a = array.as_array();
    let mut img = matfit::Image::new(w, h);
    for y in 0..h {
        for x in 0..w {
            img.data[y * w + x] = matfit::Rgb::new(a[[y, x, 0]], a[[y, x, 1]], a[[y, x, 2]]);
        }
    }
    Ok(img)
}

/// A photo: a path (str or os.PathLike) or a float32 (H, W, 3) array of linear RGB.
fn photo_input(obj: &Bound<'_, PyAny>) -> PyResult<matfit::PhotoInput> {
    if let Ok(a) = obj.extract::<PyReadonlyArray3<'_, f32>>() {
        return Ok(matfit::PhotoInput::Linear(image_from(a)?));
    }
    let p: PathBuf = obj.extract()?;
    Ok(matfit::PhotoInput::Path(p))
}

/// A scene: loaded from its file, rendered, edited.
#[pyclass(module = "matfit._matfit", frozen)]
struct Scene {
    inner: matfit::Scene,
}

const AOVS: &[(&str, matfit::Aov)] = &[
    ("beauty", matfit::Aov::Beauty),
    ("group", matfit::Aov::Group),
    ("object", matfit::Aov::Object),
    ("mirror-group", matfit::Aov::MirrorGroup),
    ("mirror-object", matfit::Aov::MirrorObject),
    ("normal", matfit::Aov::Normal),
    ("depth", matfit::Aov::Depth),
    ("uv", matfit::Aov::Uv),
];

#[pymethods]
impl Scene {
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Scene> {
        let inner = py.detach(|| matfit::load(&path)).map_err(py_err)?;
        Ok(Scene { inner })
    }

    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.path.clone()
    }

    /// The groups' names, in the scene's order.
    #[getter]
    fn groups(&self) -> Vec<String> {
        self.inner.groups.iter().map(|g| g.name.clone()).collect()
    }

    #[getter]
    fn width(&self) -> u32 {
        self.inner.camera.width
    }

    #[getter]
    fn height(&self) -> u32 {
        self.inner.camera.height
    }

    #[pyo3(signature = (spp=None, seed=None, aov="beauty", view=None, progress=None))]
    fn render<'py>(
        &self,
        py: Python<'py>,
        spp: Option<u32>,
        seed: Option<u64>,
        aov: &str,
        view: Option<String>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let Some(&(_, aov)) = AOVS.iter().find(|(n, _)| *n == aov) else {
            let names: Vec<&str> = AOVS.iter().map(|(n, _)| *n).collect();
            return Err(OptionsError::new_err(format!(
                "aov must be one of {}, got {aov:?}",
                names.join(", ")
            )));
        };
        let request = matfit::RenderRequest {
            spp,
            seed,
            aov,
            false_colour: false,
            view,
        };
        let obs = PyObserver::new(progress);
        let img = obs
            .run(py, || matfit::render(&self.inner, &request, &obs))
            .map_err(|e| obs.error(e))?;
        use matfit::Aov as A;
        if matches!(aov, A::Group | A::Object | A::MirrorGroup | A::MirrorObject) {
            let ids: Vec<i32> = img.data.iter().map(|c| c.x as i32).collect();
            return Ok(PyArray1::from_vec(py, ids)
                .reshape([img.height, img.width])?
                .into_any());
        }
        rgb_array(py, &img)
    }

    /// The scene with the edits applied (the command line's edit flags and edit files).
    #[pyo3(signature = (*, edit_files=Vec::new(), remove=Vec::new(), moves=Vec::new(),
        scale_light=Vec::new(), material=Vec::new(), add=Vec::new(), look_from=None,
        look_at=None, fov=None))]
    fn edit(
        &self,
        py: Python<'_>,
        edit_files: Vec<PathBuf>,
        remove: Vec<String>,
        moves: Vec<String>,
        scale_light: Vec<String>,
        material: Vec<String>,
        add: Vec<String>,
        look_from: Option<[f32; 3]>,
        look_at: Option<[f32; 3]>,
        fov: Option<f32>,
    ) -> PyResult<Scene> {
        let edits = edits(
            edit_files,
            matfit::EditFlags {
                remove,
                moves,
                scale_lights: scale_light,
                materials: material,
                add,
                look_from,
                look_at,
                fov_y_deg: fov,
            },
        )?;
        let inner = py
            .detach(|| matfit::edit(&self.inner, &edits))
            .map_err(py_err)?;
        Ok(Scene { inner })
    }

    fn __repr__(&self) -> String {
        format!(
            "Scene({:?}, {}×{}, {} groups)",
            self.inner.path.display().to_string(),
            self.inner.camera.width,
            self.inner.camera.height,
            self.inner.groups.len()
        )
    }
}

fn edits(files: Vec<PathBuf>, flags: matfit::EditFlags) -> PyResult<Vec<matfit::Edit>> {
    let mut v = Vec::new();
    for f in files {
        v.push(matfit::read_edit(&f).map_err(py_err)?);
    }
    v.extend(matfit::edit_from_flags(&flags).map_err(py_err)?);
    Ok(v)
}

/// Sets a field of the engine's options from a Python value, through their serde form (the
/// names are results.json's `inputs.options`).
fn set_option(
    options: &mut matfit::RecoverOptions,
    key: &str,
    value: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let json: String = value
        .py()
        .import("json")?
        .call_method1("dumps", (value,))?
        .extract()?;
    let v: serde_json::Value =
        serde_json::from_str(&json).map_err(|e| PyValueError::new_err(e.to_string()))?;
    let p = &mut options.photo;
    let bad = |what: &str| OptionsError::new_err(format!("{key}: expected {what}, got {json}"));
    match key {
        "exposure" => p.exposure = Some(v.as_f64().ok_or_else(|| bad("a number"))? as f32),
        "grey_card" => {
            let s = v.as_str().ok_or_else(|| bad("'GROUP=RHO'"))?;
            p.grey_card = Some(matfit::parse_grey_card(s).map_err(py_err)?);
        }
        "exposure_from_lights" => {
            p.exposure_from_lights = v.as_bool().ok_or_else(|| bad("a bool"))?
        }
        "camera_is_calibrated" => p.register = !v.as_bool().ok_or_else(|| bad("a bool"))?,
        "film_shift" => p.refine_pose = !v.as_bool().ok_or_else(|| bad("a bool"))?,
        "ignore_mask" => {
            p.ignore_mask = Some(PathBuf::from(v.as_str().ok_or_else(|| bad("a path"))?))
        }
        "response" => {
            let s = v.as_str().ok_or_else(|| bad("a response"))?;
            p.response = matfit::parse_response(s).map_err(py_err)?;
        }
        "views" => options.views = serde_json::from_value(v).map_err(|_| bad("a list of views"))?,
        "output" => options.output = Some(PathBuf::from(v.as_str().ok_or_else(|| bad("a path"))?)),
        "resume" => options.resume = v.as_bool().ok_or_else(|| bad("a bool"))?,
        _ => {
            // The engine's options: any field of results.json's inputs.options, at its top
            // level or in one of its tables (`max_pixels` is `cache.max_pixels`).
            let mut fit = serde_json::to_value(&options.fit).expect("options serialise");
            let top = fit.as_object_mut().expect("options are a table");
            let slot = if top.contains_key(key) {
                top.get_mut(key)
            } else {
                top.values_mut()
                    .filter_map(|t| t.as_object_mut())
                    .find_map(|t| t.get_mut(key))
            };
            let slot =
                slot.ok_or_else(|| OptionsError::new_err(format!("unknown option {key:?}")))?;
            *slot = v;
            options.fit = serde_json::from_value(fit)
                .map_err(|e| OptionsError::new_err(format!("{key}: {e}")))?;
        }
    }
    Ok(())
}

/// `matfit.recover`: the front door's recovery. Returns a dict the Python package wraps.
#[pyfunction]
#[pyo3(signature = (scene, photos, options, progress=None))]
fn recover<'py>(
    py: Python<'py>,
    scene: &Scene,
    photos: Vec<Bound<'py, PyAny>>,
    options: &Bound<'py, PyDict>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let inputs = photos
        .iter()
        .map(photo_input)
        .collect::<PyResult<Vec<_>>>()?;
    let mut opts = matfit::RecoverOptions::default();
    for (k, v) in options.iter() {
        let k: String = k.extract()?;
        set_option(&mut opts, &k, &v)?;
    }
    let obs = PyObserver::new(progress);
    let rec = obs
        .run(py, || matfit::recover(&scene.inner, &inputs, &opts, &obs))
        .map_err(|e| obs.error(e))?;
    let out = PyDict::new(py);
    let results = serde_json::to_string(&rec.results()).expect("results serialise");
    out.set_item("results", results)?;
    let log: Vec<String> = std::mem::take(&mut *obs.log.lock().unwrap());
    out.set_item("log", PyList::new(py, log)?)?;
    let photo = rec.photo();
    let error = py.detach(|| rec.error_image());
    out.set_item("photo", rgb_array(py, &photo.image)?)?;
    out.set_item("synthetic", rgb_array(py, &rec.fit.synthetic)?)?;
    out.set_item("error", rgb_array(py, &error)?)?;
    out.set_item(
        "scene",
        Scene {
            inner: rec.fit.scene.clone(),
        },
    )?;
    out.set_item("output", rec.output.clone())?;
    Ok(out)
}

/// `matfit.composite`: an edit of the recovered scene rendered into its photo.
#[pyfunction]
#[pyo3(signature = (scene, photo, *, edit_files=Vec::new(), remove=Vec::new(), moves=Vec::new(),
    scale_light=Vec::new(), material=Vec::new(), add=Vec::new(), spp=None, seed=None,
    exposure=None, response="srgb", progress=None))]
fn composite<'py>(
    py: Python<'py>,
    scene: &Scene,
    photo: &Bound<'py, PyAny>,
    edit_files: Vec<PathBuf>,
    remove: Vec<String>,
    moves: Vec<String>,
    scale_light: Vec<String>,
    material: Vec<String>,
    add: Vec<String>,
    spp: Option<u32>,
    seed: Option<u64>,
    exposure: Option<f32>,
    response: &str,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let edits = edits(
        edit_files,
        matfit::EditFlags {
            remove,
            moves,
            scale_lights: scale_light,
            materials: material,
            add,
            ..Default::default()
        },
    )?;
    let photo = photo_input(photo)?;
    let options = matfit::CompositeOptions {
        spp,
        seed,
        response: matfit::parse_response(response).map_err(py_err)?,
        exposure,
    };
    let obs = PyObserver::new(progress);
    let c = obs
        .run(py, || {
            matfit::composite(&scene.inner, &photo, &edits, &options, &obs)
        })
        .map_err(|e| obs.error(e))?;
    rgb_array(py, &c.image)
}

/// `matfit.read_image`: a linear image file (EXR, HDR, PFM) as float32 (H, W, 3).
#[pyfunction]
fn read_image(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyAny>> {
    let img = py.detach(|| matfit::read_image(&path)).map_err(py_err)?;
    rgb_array(py, &img)
}

#[pymodule]
fn _matfit(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<Scene>()?;
    m.add_function(wrap_pyfunction!(recover, m)?)?;
    m.add_function(wrap_pyfunction!(composite, m)?)?;
    m.add_function(wrap_pyfunction!(read_image, m)?)?;
    m.add("MatfitError", py.get_type::<MatfitError>())?;
    m.add("SceneError", py.get_type::<SceneError>())?;
    m.add("PhotoError", py.get_type::<PhotoError>())?;
    m.add("RecoverError", py.get_type::<RecoverError>())?;
    m.add("ExportError", py.get_type::<ExportError>())?;
    m.add("OptionsError", py.get_type::<OptionsError>())?;
    Ok(())
}
