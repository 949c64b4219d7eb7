//! The scene classes: `Scene` (picklable, as its text) and its read-only views.

use crate::errors::*;
use crate::given::*;
use crate::*;
use fogplanes::partial::stable_hash;
use fogplanes::scene::Scene;
use fogplanes::settings::Setting;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

/// A validated scene: camera, fog box, rectangular lights and render defaults. Read-only.
///
/// Made by `fogplanes.load_scene(path)` or `Scene.from_toml(text)`.
#[pyclass(frozen, module = "fogplanes", name = "Scene")]
pub(crate) struct PyScene {
    pub(crate) inner: Scene,
}

/// The pinhole camera of a scene.
#[pyclass(frozen, get_all, module = "fogplanes", name = "Camera")]
pub(crate) struct PyCamera {
    /// Position of the pinhole.
    pub(crate) position: Vec3,
    /// Unit view direction.
    pub(crate) forward: Vec3,
    /// Unit right vector of the image plane.
    pub(crate) right: Vec3,
    /// Unit up vector of the image plane (orthogonal to forward).
    pub(crate) up: Vec3,
    /// Vertical field of view in degrees.
    pub(crate) vfov_deg: f64,
    /// (width, height) in pixels.
    pub(crate) resolution: (u32, u32),
}

/// The homogeneous fog: an axis-aligned box, vacuum outside.
#[pyclass(frozen, get_all, module = "fogplanes", name = "Medium")]
pub(crate) struct PyMedium {
    /// Lower corner of the box.
    pub(crate) min: Vec3,
    /// Upper corner of the box.
    pub(crate) max: Vec3,
    /// Scattering coefficient, RGB, per unit length.
    pub(crate) sigma_s: Vec3,
    /// Absorption coefficient, RGB, per unit length.
    pub(crate) sigma_a: Vec3,
    /// Extinction sigma_s + sigma_a.
    pub(crate) sigma_t: Vec3,
    /// Henyey-Greenstein asymmetry in [-0.99, 0.99]: 0 isotropic, positive scatters forward.
    pub(crate) g: f64,
}

/// A one-sided rectangular light: corner + p edge_u/|edge_u| + q edge_v/|edge_v|.
#[pyclass(frozen, get_all, module = "fogplanes", name = "Light")]
pub(crate) struct PyLight {
    /// The light's name (`light<i>` when the file gives none).
    pub(crate) name: String,
    pub(crate) corner: Vec3,
    /// First edge (|edge_u| times its unit direction, as stored after validation).
    pub(crate) edge_u: Vec3,
    /// Second edge, orthogonal to the first.
    pub(crate) edge_v: Vec3,
    /// Unit normal normalize(edge_u x edge_v): the side it emits to.
    pub(crate) normal: Vec3,
    /// Emitted radiance, RGB.
    pub(crate) radiance: Vec3,
    /// Area |edge_u| |edge_v|.
    pub(crate) area: f64,
}

/// The scene file's `[render]` defaults (after defaults were filled in).
#[pyclass(frozen, get_all, module = "fogplanes", name = "RenderDefaults")]
pub(crate) struct PyRenderDefaults {
    pub(crate) planes: u64,
    pub(crate) estimator: String,
    pub(crate) orientations: u32,
    pub(crate) seed: u64,
    pub(crate) spp: u32,
    pub(crate) sampler: String,
    pub(crate) lobes: f64,
}

pub(crate) fn fmt3(v: Vec3) -> String {
    format!("({}, {}, {})", v.0, v.1, v.2)
}

#[pymethods]
impl PyCamera {
    fn __repr__(&self) -> String {
        format!(
            "Camera(position={}, vfov_deg={}, resolution={:?})",
            fmt3(self.position),
            self.vfov_deg,
            self.resolution
        )
    }
}

#[pymethods]
impl PyMedium {
    fn __repr__(&self) -> String {
        format!(
            "Medium(min={}, max={}, sigma_s={}, sigma_a={}, g={})",
            fmt3(self.min),
            fmt3(self.max),
            fmt3(self.sigma_s),
            fmt3(self.sigma_a),
            self.g
        )
    }
}

#[pymethods]
impl PyLight {
    fn __repr__(&self) -> String {
        format!(
            "Light(name={}, corner={}, edge_u={}, edge_v={}, radiance={})",
            py_str(&self.name),
            fmt3(self.corner),
            fmt3(self.edge_u),
            fmt3(self.edge_v),
            fmt3(self.radiance)
        )
    }
}

#[pymethods]
impl PyRenderDefaults {
    fn __repr__(&self) -> String {
        format!(
            "RenderDefaults(planes={}, estimator={}, orientations={}, seed={}, spp={}, sampler={}, lobes={})",
            self.planes,
            py_str(&self.estimator),
            self.orientations,
            self.seed,
            self.spp,
            py_str(&self.sampler),
            self.lobes
        )
    }
}

#[pymethods]
impl PyScene {
    /// Parses and validates scene text (TOML, the schema of media_scenes/*.toml).
    ///
    /// `name` is the scene's name; `file` names the text in error messages. Raises ValueError
    /// with the file, line, field and problem for anything invalid, TypeError naming the
    /// argument for one that is not a str (bytes too: decode the text first).
    #[staticmethod]
    #[pyo3(signature = (text, name = None, file = None))]
    #[pyo3(text_signature = "(text, name='scene', file='<string>')")]
    fn from_toml(
        text: &Bound<'_, PyAny>,
        name: Option<&Bound<'_, PyAny>>,
        file: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        if !text.is_instance_of::<pyo3::types::PyString>() {
            let type_name = text.get_type().name().map(|n| n.to_string()).unwrap_or_default();
            return Err(PyTypeError::new_err(format!("text: expected the scene's TOML text (a str), got {type_name}")));
        }
        let text = crate::given::text("text", text)?;
        let string = |v: Option<&Bound<'_, PyAny>>, arg: &str, default: &str| match v {
            None => Ok(default.to_string()),
            Some(v) => crate::given::text(arg, v),
        };
        let (name, file) = (string(name, "name", "scene")?, string(file, "file", "<string>")?);
        Scene::parse(&text, &file, &name)
            .map(|inner| PyScene { inner })
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// The scene made from its text, name, file and resolution: what a pickled scene is
    /// rebuilt with (`__reduce__`).
    /// The parts are trusted no more than a file (a pickle may be forged): each of its type, a
    /// `ValueError` naming it otherwise, the resolution's range the scene's own.
    #[staticmethod]
    fn _from_parts(
        text: &Bound<'_, PyAny>,
        name: &Bound<'_, PyAny>,
        file: &Bound<'_, PyAny>,
        resolution: &Bound<'_, PyAny>,
    ) -> PyResult<Self> {
        let part = |v: &Bound<'_, PyAny>, what: &str| {
            crate::given::text(what, v)
                .map_err(|e| PyValueError::new_err(format!("not the state of a fogplanes.Scene: {}", e.value(v.py()))))
        };
        let (text, name, file) = (part(text, "text")?, part(name, "name")?, part(file, "file")?);
        let side = |v: PyResult<Bound<'_, PyAny>>| -> Option<u32> {
            v.ok().and_then(|v| integer("resolution", &v).ok().flatten()).and_then(|n| u32::try_from(n).ok())
        };
        let sides = resolution
            .len()
            .ok()
            .filter(|&n| n == 2)
            .and_then(|_| Some((side(resolution.get_item(0))?, side(resolution.get_item(1))?)));
        let Some((width, height)) = sides else {
            return Err(PyValueError::new_err(format!(
                "not the state of a fogplanes.Scene: resolution={}: expected two whole numbers (width, height)",
                short_repr(resolution)
            )));
        };
        let scene = Scene::parse(&text, &file, &name).map_err(|e| PyValueError::new_err(e.to_string()))?;
        scene.with_resolution(width, height).map(|inner| PyScene { inner }).map_err(py_error)
    }

    /// Pickles as its text, name, file and resolution (not a pointer): a scene travels to
    /// another process (a Dask worker) and is rebuilt there, identical.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, SceneParts)> {
        let s = &slf.get().inner;
        let source = s.source().ok_or_else(|| PyValueError::new_err("this scene has no text to pickle"))?;
        let make = slf.get_type().getattr("_from_parts")?;
        Ok((make, (source.text.clone(), s.name.clone(), source.file.clone(), (s.camera.width, s.camera.height))))
    }

    /// A stable token (32 hex digits, the same in every process and run): a hash of the
    /// scene's text, name, file and resolution, for Dask's task keys.
    fn __dask_tokenize__(&self) -> String {
        let s = &self.inner;
        let (text, file) = s.source().map_or(("", ""), |src| (src.text.as_str(), src.file.as_str()));
        let resolution = format!("{}x{}", s.camera.width, s.camera.height);
        stable_hash(&[text.as_bytes(), s.name.as_bytes(), file.as_bytes(), resolution.as_bytes()])
    }

    /// The TOML text the scene was made from.
    #[getter]
    fn source(&self) -> String {
        self.inner.source().map(|s| s.text.clone()).unwrap_or_default()
    }

    /// The file name the scene's errors cite (`<string>` for from_toml's default).
    #[getter]
    fn file(&self) -> String {
        self.inner.source().map(|s| s.file.clone()).unwrap_or_default()
    }

    /// The same scene at another resolution.
    fn with_resolution(&self, width: &Bound<'_, PyAny>, height: &Bound<'_, PyAny>) -> PyResult<Self> {
        // The types named by argument, the range as the resolution (`resolution=(0, 4): ...`).
        integer("width", width)?;
        integer("height", height)?;
        let mut given = Given::default();
        let w = given.uint32(Setting::Resolution, Some(width))?.unwrap_or_default();
        let h = given.uint32(Setting::Resolution, Some(height))?.unwrap_or_default();
        given.reprs.push((Setting::Resolution, format!("({w}, {h})")));
        self.inner.with_resolution(w, h).map(|inner| PyScene { inner }).map_err(|e| given.error(e))
    }

    /// The file stem (or the name given to from_toml).
    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }

    /// (width, height) in pixels.
    #[getter]
    fn resolution(&self) -> (u32, u32) {
        (self.inner.camera.width, self.inner.camera.height)
    }

    #[getter]
    fn camera(&self) -> PyCamera {
        let c = &self.inner.camera;
        PyCamera {
            position: triple(c.position),
            forward: triple(c.forward),
            right: triple(c.right),
            up: triple(c.up),
            vfov_deg: (2.0 * c.tan_half_fov.atan()).to_degrees(),
            resolution: (c.width, c.height),
        }
    }

    #[getter]
    fn medium(&self) -> PyMedium {
        let m = &self.inner.medium;
        PyMedium {
            min: triple(m.min),
            max: triple(m.max),
            sigma_s: triple(m.sigma_s),
            sigma_a: triple(m.sigma_a),
            sigma_t: triple(m.sigma_t()),
            g: m.g,
        }
    }

    /// The lights, in file order.
    #[getter]
    fn lights(&self) -> Vec<PyLight> {
        self.inner
            .lights
            .iter()
            .map(|l| PyLight {
                name: l.name.clone(),
                corner: triple(l.corner),
                edge_u: triple(l.u * l.width),
                edge_v: triple(l.v * l.height),
                normal: triple(l.n),
                radiance: triple(l.radiance),
                area: l.area(),
            })
            .collect()
    }

    /// The `[render]` defaults: planes, estimator, orientations, seed, spp, sampler, lobes.
    #[getter]
    fn render(&self) -> PyRenderDefaults {
        let r = &self.inner.render;
        PyRenderDefaults {
            planes: r.planes,
            estimator: r.weighting.estimator.name().to_string(),
            orientations: r.weighting.orientations,
            seed: r.seed,
            spp: r.spp,
            sampler: r.sampler.name().to_string(),
            lobes: r.lobes,
        }
    }

    fn __repr__(&self) -> String {
        let s = &self.inner;
        format!(
            "Scene(name={}, resolution={}x{}, lights={})",
            py_str(&s.name),
            s.camera.width,
            s.camera.height,
            s.lights.len()
        )
    }
}
