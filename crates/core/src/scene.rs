//! Scene files (`media_scenes/*.toml`): the schema, its validation, and the validated [`Scene`].
//!
//! Every problem is reported as one [`SceneError`] that names the file, the field and what is
//! wrong; nothing in here panics on any input.

use crate::camera::Camera;
use crate::light::RectLight;
use crate::limits::{
    DEFAULT_PLANES, DEFAULT_RAY_SETS, DEFAULT_SEED, MAX_LIGHTS, MAX_SCENE_FILE_BYTES, check_lobes, check_planes,
    check_render_memory, check_resolution, check_spp,
};
use crate::medium::{G_MAX, Medium};
use crate::sampling::{Discrete, Sampler};
use crate::weights::{Estimator, Weighting};
use glam::DVec3;
use serde::Deserialize;
use std::fmt;
use std::path::Path;

pub use crate::error::SceneError;
use crate::error::acts_on_terminal;

/// An RGB triple that may be written as a single number (grey).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rgb(pub [f64; 3]);

impl<'de> Deserialize<'de> for Rgb {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = Rgb;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number or an array of three numbers")
            }
            fn visit_f64<E>(self, v: f64) -> Result<Rgb, E> {
                Ok(Rgb([v; 3]))
            }
            fn visit_i64<E>(self, v: i64) -> Result<Rgb, E> {
                Ok(Rgb([v as f64; 3]))
            }
            fn visit_u64<E>(self, v: u64) -> Result<Rgb, E> {
                Ok(Rgb([v as f64; 3]))
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Rgb, A::Error> {
                let mut out = [0.0; 3];
                for (i, slot) in out.iter_mut().enumerate() {
                    *slot = seq.next_element()?.ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
                }
                if seq.next_element::<f64>()?.is_some() {
                    return Err(serde::de::Error::invalid_length(4, &self));
                }
                Ok(Rgb(out))
            }
        }
        d.deserialize_any(Visitor)
    }
}

/// An array of exactly `N` elements: serde's arrays take the first `N` of a longer one and
/// ignore the rest, so that `position = [0, 0, 4, 9]` would render. (Asked for as a tuple, as
/// serde's arrays are: the TOML reader hands over every element either way.)
fn exactly<'de, D, T, const N: usize>(d: D) -> Result<[T; N], D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    struct Visitor<T, const N: usize>(std::marker::PhantomData<T>);
    impl<'de, T: Deserialize<'de>, const N: usize> serde::de::Visitor<'de> for Visitor<T, N> {
        type Value = [T; N];
        fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
            write!(f, "an array of exactly {N} numbers")
        }
        fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<[T; N], A::Error> {
            let mut out = Vec::with_capacity(N);
            for i in 0..N {
                out.push(seq.next_element()?.ok_or_else(|| serde::de::Error::invalid_length(i, &self))?);
            }
            let mut extra = 0;
            while seq.next_element::<serde::de::IgnoredAny>()?.is_some() {
                extra += 1;
            }
            if extra > 0 {
                return Err(serde::de::Error::invalid_length(N + extra, &self));
            }
            Ok(out.try_into().unwrap_or_else(|_| unreachable!("N elements were pushed")))
        }
    }
    d.deserialize_tuple(N, Visitor(std::marker::PhantomData))
}

/// The file schema. Unknown keys are errors.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    pub camera: CameraDesc,
    pub medium: MediumDesc,
    #[serde(rename = "light")]
    pub lights: Vec<LightDesc>,
    #[serde(default)]
    pub render: RenderDesc,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct CameraDesc {
    #[serde(deserialize_with = "exactly")]
    pub position: [f64; 3],
    #[serde(deserialize_with = "exactly")]
    pub look_at: [f64; 3],
    #[serde(deserialize_with = "exactly")]
    pub up: [f64; 3],
    pub vfov_deg: f64,
    #[serde(deserialize_with = "exactly")]
    pub resolution: [u32; 2],
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct MediumDesc {
    #[serde(deserialize_with = "exactly")]
    pub min: [f64; 3],
    #[serde(deserialize_with = "exactly")]
    pub max: [f64; 3],
    pub sigma_s: Rgb,
    pub sigma_a: Rgb,
    /// The Henyey-Greenstein asymmetry; absent is 0 (isotropic).
    #[serde(default)]
    pub g: f64,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct LightDesc {
    pub name: Option<String>,
    #[serde(deserialize_with = "exactly")]
    pub corner: [f64; 3],
    #[serde(deserialize_with = "exactly")]
    pub edge_u: [f64; 3],
    #[serde(deserialize_with = "exactly")]
    pub edge_v: [f64; 3],
    pub radiance: Rgb,
}

/// Optional defaults for rendering; the command line overrides them.
#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
pub struct RenderDesc {
    pub planes: Option<u64>,
    pub estimator: Option<String>,
    pub orientations: Option<u32>,
    pub seed: Option<u64>,
    pub spp: Option<u32>,
    /// `sobol` (the default) or `independent`.
    pub sampler: Option<String>,
    /// The share of each light's planes swept along the phase function's lobe, in [0, 1]
    /// ([`crate::limits::DEFAULT_LOBES`] by default).
    pub lobes: Option<f64>,
}

/// Render settings after defaults, validated.
#[derive(Clone, Debug)]
pub struct RenderDefaults {
    pub planes: u64,
    pub weighting: Weighting,
    pub seed: u64,
    pub spp: u32,
    pub sampler: Sampler,
    pub lobes: f64,
}

/// A validated scene.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The file stem, used for default output names.
    pub name: String,
    pub camera: Camera,
    pub medium: Medium,
    pub lights: Vec<RectLight>,
    pub render: RenderDefaults,
    /// The text it was parsed from and the file that named it, so that a scene can travel to
    /// another process as text (Python's pickle); `None` for a scene made from a description.
    source: Option<std::sync::Arc<SceneSource>>,
}

/// The TOML text of a scene and the file name its errors cite.
#[derive(Debug, PartialEq, Eq)]
pub struct SceneSource {
    pub text: String,
    pub file: String,
}

impl Scene {
    /// Reads and validates a scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let file = path.display().to_string();
        let whole = |message: String| SceneError { file: file.clone(), position: None, field: String::new(), message };
        let meta = std::fs::metadata(path).map_err(|e| whole(format!("cannot read the scene file: {e}")))?;
        if meta.is_dir() {
            return Err(whole("is a directory, not a scene file".into()));
        }
        if meta.len() > MAX_SCENE_FILE_BYTES {
            return Err(whole(format!(
                "the file is {} bytes; scene files are limited to {} bytes",
                meta.len(),
                MAX_SCENE_FILE_BYTES
            )));
        }
        use std::io::Read as _;
        // The size above is the file's word for it: /dev/zero, a pipe or a file growing as it
        // is read say otherwise. Read one byte past the limit at most and refuse if it came.
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .and_then(|f| f.take(MAX_SCENE_FILE_BYTES + 1).read_to_end(&mut bytes))
            .map_err(|e| whole(format!("cannot read the scene file: {e}")))?;
        if bytes.len() as u64 > MAX_SCENE_FILE_BYTES {
            return Err(whole(format!(
                "the file holds more than {MAX_SCENE_FILE_BYTES} bytes; scene files are limited to {MAX_SCENE_FILE_BYTES} bytes"
            )));
        }
        let text = String::from_utf8(bytes).map_err(|e| whole(format!("not UTF-8 text ({e})")))?;
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scene".into());
        Scene::parse(&text, &file, &name)
    }

    /// Parses and validates scene text; `file` names it in errors. Text beyond the size of a
    /// scene file is refused as the file would be (a scene travels as its text, in part files
    /// and pickles).
    pub fn parse(text: &str, file: &str, name: &str) -> Result<Scene, SceneError> {
        if text.len() as u64 > MAX_SCENE_FILE_BYTES {
            return Err(SceneError {
                file: file.to_string(),
                position: None,
                field: String::new(),
                message: format!(
                    "the text is {} bytes; scene files are limited to {MAX_SCENE_FILE_BYTES} bytes",
                    text.len()
                ),
            });
        }
        let desc = parse_file(text, file)?;
        let mut scene = Scene::from_desc(&desc, file, name)?;
        scene.source = Some(std::sync::Arc::new(SceneSource { text: text.to_string(), file: file.to_string() }));
        Ok(scene)
    }

    /// Names the scene's content: camera (at its resolution), medium and lights, not its name
    /// or file; the same in every process and run. What an image records of its scene.
    pub fn fingerprint(&self) -> String {
        let description = format!("{:?} | {:?} | {:?}", self.camera, self.medium, self.lights);
        crate::sampling::stable_hash(&[description.as_bytes()])
    }

    /// The text the scene was parsed from ([`Scene::parse`], [`Scene::load`]), if it was.
    pub fn source(&self) -> Option<&SceneSource> {
        self.source.as_deref()
    }

    /// Validates a parsed description.
    pub fn from_desc(desc: &SceneFile, file: &str, name: &str) -> Result<Scene, SceneError> {
        let err =
            |field: String, message: String| SceneError { file: file.to_string(), position: None, field, message };
        let vec3 = |field: &str, v: [f64; 3]| -> Result<DVec3, SceneError> {
            if v.iter().all(|x| x.is_finite()) {
                Ok(DVec3::from_array(v))
            } else {
                Err(err(field.into(), format!("must be finite, got {v:?}")))
            }
        };
        let non_negative = |field: &str, v: Rgb| -> Result<DVec3, SceneError> {
            if v.0.iter().all(|x| x.is_finite() && *x >= 0.0) {
                Ok(DVec3::from_array(v.0))
            } else {
                Err(err(field.into(), format!("must be finite and non-negative, got {:?}", v.0)))
            }
        };

        // Medium.
        let m = &desc.medium;
        let (min, max) = (vec3("medium.min", m.min)?, vec3("medium.max", m.max)?);
        if !(min.cmplt(max).all()) {
            return Err(err(
                "medium".into(),
                format!("the box is empty: min {:?} must be below max {:?} on every axis", m.min, m.max),
            ));
        }
        let medium = Medium {
            min,
            max,
            sigma_s: non_negative("medium.sigma_s", m.sigma_s)?,
            sigma_a: non_negative("medium.sigma_a", m.sigma_a)?,
            g: if m.g.is_finite() && m.g.abs() <= G_MAX {
                m.g
            } else {
                return Err(err(
                    "medium.g".into(),
                    format!("must be a finite number in [-{G_MAX}, {G_MAX}], got {}", crate::error::Number(m.g)),
                ));
            },
        };
        let scale = medium.diagonal();
        if !(scale >= crate::limits::MIN_BOX_DIAGONAL) {
            return Err(err(
                "medium".into(),
                format!(
                    "the box's diagonal is {scale:e}; at least {:e} is supported (positions are held in f32): scale the scene up",
                    crate::limits::MIN_BOX_DIAGONAL
                ),
            ));
        }
        if !(scale <= crate::limits::MAX_BOX_DIAGONAL) {
            return Err(err(
                "medium".into(),
                format!(
                    "the box's diagonal is {scale:e}; at most {:e} is supported (positions are held in f32)",
                    crate::limits::MAX_BOX_DIAGONAL
                ),
            ));
        }

        // Camera.
        let c = &desc.camera;
        let position = vec3("camera.position", c.position)?;
        let look_at = vec3("camera.look_at", c.look_at)?;
        let up = vec3("camera.up", c.up)?;
        // The camera's distance to the box (0 inside it), in box diagonals.
        // (Its length taken over its largest component: a camera at 1e308 is 1.7e307 diagonals
        // away, not an infinity.)
        let gap = (min - position).max(position - max).max(DVec3::ZERO);
        let largest = gap.max_element();
        let away = if largest > 0.0 { largest * (gap / largest).length() / scale } else { 0.0 };
        if !(away <= crate::limits::MAX_CAMERA_DISTANCE_DIAGONALS) {
            return Err(err(
                "camera.position".into(),
                format!(
                    "the camera is {away:.6e} box diagonals from the fog box; at most {:e} are supported (planes are held in f32 relative to the camera, which keeps the box's detail to about 6e-8 times that distance over its size): move the camera closer and widen vfov_deg",
                    crate::limits::MAX_CAMERA_DISTANCE_DIAGONALS
                ),
            ));
        }
        // Only the directions matter, whatever the vectors' lengths (camera::tamed): a camera
        // at 1e308 was told that look_at "must differ from camera.position" (its view's length
        // overflowed), and an up of [0, 1e308, 0] that it "must not be zero". The camera is near
        // the box (checked above), so that only a look_at near f64's limit overflows the view.
        let view = look_at - position;
        if !view.is_finite() {
            return Err(err(
                "camera.look_at".into(),
                "is too far from camera.position: their difference is no finite number".into(),
            ));
        }
        let Some(view) = crate::camera::tamed(view) else {
            return Err(err("camera.look_at".into(), "must differ from camera.position".into()));
        };
        let tamed_up = crate::camera::tamed(up);
        if tamed_up.is_none_or(|up| view.normalize().cross(up.normalize()).length() < 1e-9) {
            return Err(err(
                "camera.up".into(),
                format!("must not be zero or parallel to the view direction, got {:?}", c.up),
            ));
        }
        if !(c.vfov_deg >= crate::limits::MIN_VFOV_DEG && c.vfov_deg <= crate::limits::MAX_VFOV_DEG) {
            return Err(err(
                "camera.vfov_deg".into(),
                format!(
                    "must lie between {} and {} degrees, got {}",
                    crate::limits::MIN_VFOV_DEG,
                    crate::limits::MAX_VFOV_DEG,
                    crate::error::Number(c.vfov_deg)
                ),
            ));
        }
        check_resolution(c.resolution[0], c.resolution[1]).map_err(|m| err("camera.resolution".into(), m))?;
        let camera = Camera::new(position, look_at, up, c.vfov_deg, c.resolution[0], c.resolution[1]);

        // Lights.
        if desc.lights.is_empty() {
            return Err(err("light".into(), "the scene needs at least one [[light]]".into()));
        }
        if desc.lights.len() > MAX_LIGHTS {
            return Err(err(
                "light".into(),
                format!("at most {MAX_LIGHTS} lights are supported, got {}", desc.lights.len()),
            ));
        }
        let mut lights = Vec::with_capacity(desc.lights.len());
        for (i, l) in desc.lights.iter().enumerate() {
            // A name is echoed in errors (`light[2] (ceiling).corner`): a control character in it
            // (an escape sequence, a newline) acted on the terminal, or broke the error's one
            // line, and a bidirectional override (U+202E) turned the rest of the line around, so
            // both are refused here, at the door, shown escaped.
            if let Some(name) = l.name.as_deref().filter(|n| n.chars().any(acts_on_terminal)) {
                return Err(err(
                    format!("light[{i}].name"),
                    format!(
                        "must not hold control characters (escape sequences, newlines, tabs, text direction), got {name:?}"
                    ),
                ));
            }
            let field = |f: &str| match &l.name {
                Some(n) => format!("light[{i}] ({n}).{f}"),
                None => format!("light[{i}].{f}"),
            };
            let corner = vec3(&field("corner"), l.corner)?;
            let eu = vec3(&field("edge_u"), l.edge_u)?;
            let ev = vec3(&field("edge_v"), l.edge_v)?;
            let radiance = non_negative(&field("radiance"), l.radiance)?;
            for (name, e) in [("edge_u", eu), ("edge_v", ev)] {
                // The length over the largest component (|[1e-300, 0, 0]| was 0e0), and no
                // longer than the box, inside which the light lies: an edge of 1e308 made the
                // light's frame NaN, and the error named a corner [NaN, NaN, NaN].
                let largest = e.abs().max_element();
                let length = if largest > 0.0 { largest * (e / largest).length() } else { 0.0 };
                if !(length > 1e-9 * scale) {
                    return Err(err(
                        field(name),
                        format!(
                            "is too short: |{name}| = {length:e}, where an edge must be longer than 1e-9 of the box's diagonal ({scale:e})"
                        ),
                    ));
                }
                if !(length <= scale * (1.0 + 2e-9)) {
                    return Err(err(
                        field(name),
                        format!(
                            "is longer than the box's diagonal: |{name}| = {length:e} against {scale:e}; the light must lie inside the medium box"
                        ),
                    ));
                }
            }
            let cos = eu.normalize().dot(ev.normalize());
            if cos.abs() > 1e-6 {
                return Err(err(
                    field("edge_v"),
                    format!("must be orthogonal to edge_u (the cosine between them is {cos:.3e})"),
                ));
            }
            let light = RectLight::new(l.name.as_deref().unwrap_or(&format!("light{i}")), corner, eu, ev, radiance);
            if let Some(k) = light.corners().iter().position(|&p| !medium.contains(p, 1e-9 * scale)) {
                return Err(err(
                    field("corner"),
                    format!(
                        "the light must lie inside the medium box or on its boundary; its corner {:?} does not",
                        light.corners()[k].to_array()
                    ),
                ));
            }
            lights.push(light);
        }
        let power = lights.iter().map(|l| l.power()).sum::<f64>();
        if !(power > 0.0) {
            return Err(err("light".into(), "every light has zero power (area x luminance); nothing to render".into()));
        }
        if !(power <= crate::limits::MAX_TOTAL_POWER) {
            return Err(err(
                "light".into(),
                format!(
                    "the lights' total power (area x luminance) is {power:e}, above the {:e} an f32 image can sum",
                    crate::limits::MAX_TOTAL_POWER
                ),
            ));
        }

        // What each plane of a light carries, in f32 with the lights' power's headroom: beyond it
        // a plane's power is no finite f32, and its hits' sums no number. That is
        // photon_plane.rs `power`, sigma_s rho pi Le A / P_l (docs/mathematics.md section 2.3,
        // rho the isotropic 1/(4 pi), so rho pi = 1/4: with g != 0 the phase value divides D), P_l = A
        // luminance(Le) / power: (Le / luminance(Le)) power sigma_s / 4, the area cancelled, so
        // that a dim light beside a bright one divides no tiny power.
        for (i, (l, desc)) in lights.iter().zip(&desc.lights).enumerate() {
            let luminance = crate::light::luminance(l.radiance);
            if luminance > 0.0 {
                let carried = medium.sigma_s * (l.radiance / luminance) * (0.25 * power);
                if !(carried.max_element() <= crate::limits::MAX_TOTAL_POWER) {
                    let light = match &desc.name {
                        Some(n) => format!("light[{i}] ({n})"),
                        None => format!("light[{i}]"),
                    };
                    return Err(err(
                        "medium.sigma_s".into(),
                        format!(
                            "the planes of {light} carry sigma_s x radiance x area / 4 over its share of the power, {:e}, above the {:e} an f32 image can sum",
                            carried.max_element(),
                            crate::limits::MAX_TOTAL_POWER
                        ),
                    ));
                }
            }
        }

        // Render defaults.
        let r = &desc.render;
        let planes = r.planes.unwrap_or(DEFAULT_PLANES);
        check_planes(planes).map_err(|m| err("render.planes".into(), m))?;
        let estimator = match &r.estimator {
            Some(name) => name.parse::<Estimator>().map_err(|m| err("render.estimator".into(), m))?,
            None => Estimator::DEFAULT,
        };
        let weighting = Weighting::new(estimator, r.orientations).map_err(|m| err("render.orientations".into(), m))?;
        let spp = r.spp.unwrap_or(DEFAULT_RAY_SETS);
        check_spp(spp).map_err(|m| err("render.spp".into(), m))?;
        let sampler = match &r.sampler {
            Some(name) => name.parse::<Sampler>().map_err(|m| err("render.sampler".into(), m))?,
            None => Sampler::default(),
        };
        let lobes = r.lobes.unwrap_or(crate::limits::DEFAULT_LOBES);
        check_lobes(lobes).map_err(|m| err("render.lobes".into(), m))?;
        let render = RenderDefaults { planes, weighting, seed: r.seed.unwrap_or(DEFAULT_SEED), spp, sampler, lobes };
        check_render_memory(camera.width, camera.height, planes).map_err(|m| err("camera.resolution".into(), m))?;

        Ok(Scene { name: name.to_string(), camera, medium, lights, render, source: None })
    }

    /// The first light panel crossed by the ray `o + t we` with `t` in `(0, t_max)`: its distance
    /// and index.
    pub fn first_light(&self, o: DVec3, we: DVec3, t_max: f64) -> Option<(f64, usize)> {
        self.first_light_among(o, we, t_max, 0..self.lights.len())
    }

    /// [`Scene::first_light`] among the panels `lights` (ascending indices): the same answer
    /// whenever the others cannot be crossed (as outside a pixel's footprint,
    /// [`crate::pixel::PanelFootprints`]).
    pub fn first_light_among(
        &self,
        o: DVec3,
        we: DVec3,
        t_max: f64,
        lights: impl IntoIterator<Item = usize>,
    ) -> Option<(f64, usize)> {
        let mut best = None;
        let mut t_max = t_max;
        for k in lights {
            if let Some(t) = self.lights[k].intersect(o, we, 0.0, t_max) {
                t_max = t;
                best = Some((t, k));
            }
        }
        best
    }

    /// What a camera ray `o + t we` (unit `we`) meets: its segment inside the medium before the
    /// first light panel (None if empty), and the attenuated emission of that panel when its
    /// front faces the ray (docs/mathematics.md section 1, the direct term).
    pub fn camera_segment(&self, o: DVec3, we: DVec3) -> (Option<(f64, f64)>, DVec3) {
        let (t_surface, emission) = self.first_surface(o, we, 0..self.lights.len());
        (self.segment_before(o, we, t_surface), emission)
    }

    /// The part of the ray `o + t we` inside the medium and before `t_surface` (None if empty).
    pub fn segment_before(&self, o: DVec3, we: DVec3, t_surface: f64) -> Option<(f64, f64)> {
        match self.medium.clip_ray(o, we) {
            Some((t0, t1)) if t0 < t_surface.min(t1) => Some((t0, t_surface.min(t1))),
            _ => None,
        }
    }

    /// The distance to the first of the panels `lights` that the ray `o + t we` crosses
    /// (infinite if none), and the emission it sends back: `Tr(o, xL) Le` when its front faces
    /// the ray, else 0 (docs/mathematics.md section 1, the direct term).
    pub fn first_surface(&self, o: DVec3, we: DVec3, lights: impl IntoIterator<Item = usize>) -> (f64, DVec3) {
        match self.first_light_among(o, we, f64::INFINITY, lights) {
            Some((t, k)) if we.dot(self.lights[k].n) < 0.0 => {
                let tr = self.medium.transmittance(self.medium.length_inside(o, o + t * we));
                (t, self.lights[k].radiance * tr)
            }
            Some((t, _)) => (t, DVec3::ZERO),
            None => (f64::INFINITY, DVec3::ZERO),
        }
    }

    /// Whether a light panel other than `except` blocks the segment from light point `y` to `x`.
    pub fn blocked(&self, y: DVec3, x: DVec3, except: usize) -> bool {
        self.blocked_by(y, x, (0..self.lights.len()).filter(|&k| k != except))
    }

    /// Whether one of the light panels `lights` blocks the segment from `y` to `x` (its ends
    /// left out, to a billionth of its length): [`Scene::blocked`] among a subset.
    pub fn blocked_by(&self, y: DVec3, x: DVec3, mut lights: impl Iterator<Item = usize>) -> bool {
        let d = x - y;
        let len = d.length();
        if len == 0.0 {
            return false;
        }
        let dir = d / len;
        lights.any(|k| self.lights[k].intersect(y, dir, 1e-9 * len, len * (1.0 - 1e-9)).is_some())
    }

    /// Light choice by power, P_l proportional to A_l luminance(Le_l) (docs/mathematics.md
    /// section 2, step 1): shared by the photon planes and the reference.
    pub fn light_distribution(&self) -> Discrete {
        Discrete::new(&self.lights.iter().map(RectLight::power).collect::<Vec<_>>())
    }

    /// The same scene seen at another resolution (each side in range; the memory a render
    /// needs at that size is checked with its own plane count, see [`crate::settings`]).
    pub fn with_resolution(&self, width: u32, height: u32) -> Result<Scene, crate::Error> {
        check_resolution(width, height).map_err(|m| crate::Error::option(crate::error::Setting::Resolution, m))?;
        let c = &self.camera;
        let mut s = self.clone();
        s.camera = Camera { width, height, ..c.clone() };
        Ok(s)
    }
}

/// Parses the TOML text into the schema, locating the error in the text.
pub fn parse_file(text: &str, file: &str) -> Result<SceneFile, SceneError> {
    let position_of = |span: Option<std::ops::Range<usize>>| {
        span.map(|s| {
            let before = &text[..s.start.min(text.len())];
            let line = before.matches('\n').count() + 1;
            let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            (line, col)
        })
    };
    let de = toml::Deserializer::parse(text).map_err(|e| {
        let mut message = format!("TOML syntax: {}", e.message().trim());
        // The reader says "duplicate key" and points at it without naming it: name it (the
        // key's text, as the file writes it), so that the line says which of a line's keys.
        if message.ends_with("duplicate key")
            && let Some(key) = e.span().and_then(|s| text.get(s)).map(str::trim).filter(|k| !k.is_empty())
        {
            message = format!("{message} `{key}` (each key is given once in its table)");
        }
        SceneError { file: file.to_string(), position: position_of(e.span()), field: String::new(), message }
    })?;
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        SceneError {
            file: file.to_string(),
            position: position_of(inner.span()),
            field: if path == "." { String::new() } else { path },
            message: inner.message().trim().to_string(),
        }
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A small valid scene for the unit tests of every module.
    pub const MINIMAL: &str = r#"
[camera]
position = [0.0, 1.0, 5.0]
look_at = [0.0, 1.0, 0.0]
up = [0.0, 1.0, 0.0]
vfov_deg = 40.0
resolution = [32, 16]

[medium]
min = [-2.0, 0.0, -2.0]
max = [2.0, 2.0, 2.0]
sigma_s = [0.1, 0.2, 0.3]
sigma_a = 0.05

[[light]]
name = "top"
corner = [-0.5, 1.9, -0.5]
edge_u = [1.0, 0.0, 0.0]
edge_v = [0.0, 0.0, 1.0]
radiance = 4
"#;

    fn parse(text: &str) -> Result<Scene, SceneError> {
        Scene::parse(text, "test.toml", "test")
    }

    /// [`MINIMAL`] with every length times `s` and its coefficients over `s`: the same image.
    fn scaled(s: f64) -> String {
        let v = |x: f64, y: f64, z: f64| format!("[{:e}, {:e}, {:e}]", x * s, y * s, z * s);
        format!(
            "[camera]\nposition = {}\nlook_at = {}\nup = [0.0, 1.0, 0.0]\nvfov_deg = 40.0\nresolution = [32, 16]\n\
             [medium]\nmin = {}\nmax = {}\nsigma_s = [{:e}, {:e}, {:e}]\nsigma_a = {:e}\n\
             [[light]]\ncorner = {}\nedge_u = {}\nedge_v = {}\nradiance = 4\n",
            v(0.0, 1.0, 5.0),
            v(0.0, 1.0, 0.0),
            v(-2.0, 0.0, -2.0),
            v(2.0, 2.0, 2.0),
            0.1 / s,
            0.2 / s,
            0.3 / s,
            0.05 / s,
            v(-0.5, 1.9, -0.5),
            v(1.0, 0.0, 0.0),
            v(0.0, 0.0, 1.0),
        )
    }

    #[test]
    fn minimal_scene_parses_with_grey_and_rgb_coefficients() {
        let s = parse(MINIMAL).unwrap();
        assert_eq!(s.medium.sigma_s, DVec3::new(0.1, 0.2, 0.3));
        assert_eq!(s.medium.sigma_a, DVec3::splat(0.05));
        assert_eq!(s.lights[0].radiance, DVec3::splat(4.0));
        assert_eq!(s.render.planes, 40_960);
        assert_eq!(s.render.weighting.estimator, Estimator::SmisExact);
        assert_eq!(s.render.sampler, Sampler::Sobol);
        let independent = parse(&format!("{MINIMAL}\n[render]\nsampler = \"independent\"\n")).unwrap();
        assert_eq!(independent.render.sampler, Sampler::Independent);
        assert_eq!(s.render.lobes, crate::limits::DEFAULT_LOBES);
        assert_eq!(parse(&format!("{MINIMAL}\n[render]\nlobes = 0\n")).unwrap().render.lobes, 0.0);
        assert_eq!(parse(&format!("{MINIMAL}\n[render]\nlobes = 0.25\n")).unwrap().render.lobes, 0.25);
    }

    fn expect_error(text: &str, field: &str, words: &str) {
        let e = parse(text).expect_err("should fail");
        assert!(e.field.contains(field), "field {:?} should contain {field:?}: {e}", e.field);
        assert!(e.message.contains(words), "message should contain {words:?}: {e}");
    }

    #[test]
    fn each_problem_names_its_field() {
        expect_error(&MINIMAL.replace("vfov_deg = 40.0", "vfov_deg = 40.0\nzoom = 2"), "camera", "unknown field");
        expect_error(&MINIMAL.replace("vfov_deg = 40.0", "vfov_deg = \"wide\""), "camera.vfov_deg", "invalid type");
        expect_error(&MINIMAL.replace("vfov_deg = 40.0\n", ""), "camera", "missing field");
        // Between MIN_VFOV_DEG and MAX_VFOV_DEG, both taken; NaN, 0 and below refused.
        let vfov = |v: &str| MINIMAL.replace("vfov_deg = 40.0", &format!("vfov_deg = {v}"));
        for refused in ["nan", "1e-4", "5e-324", "0.0", "-0.0", "179.5"] {
            expect_error(&vfov(refused), "camera.vfov_deg", "between 0.001 and 179 degrees");
        }
        assert!(parse(&vfov("0.001")).is_ok() && parse(&vfov("179.0")).is_ok());
        // The camera at most 1000 box diagonals (6,000 units here) from the box, a box at most 1e30 across.
        expect_error(&MINIMAL.replace("[0.0, 1.0, 5.0]", "[0.0, 1.0, 6003.0]"), "camera.position", "box diagonals");
        assert!(parse(&MINIMAL.replace("[0.0, 1.0, 5.0]", "[0.0, 1.0, 5900.0]")).is_ok());
        expect_error(&MINIMAL.replace("max = [2.0, 2.0, 2.0]", "max = [2.0, 2.0, 1e31]"), "medium", "diagonal");
        // And at least 1e-20 across: the benchmark scaled to 1e-40 rendered without its fog, and
        // a box of 1e-300 has a diagonal of 0 in f64.
        for s in [1e-21, 1e-40, 1e-300] {
            expect_error(&scaled(s), "medium", "at least 1e-20");
        }
        assert!(parse(&scaled(1e-20)).is_ok());
        expect_error(&MINIMAL.replace("[0.0, 1.0, 5.0]", "[0.0, inf, 5.0]"), "camera.position", "finite");
        expect_error(
            &MINIMAL.replace("look_at = [0.0, 1.0, 0.0]", "look_at = [0.0, 1.0, 5.0]"),
            "camera.look_at",
            "differ",
        );
        expect_error(&MINIMAL.replace("up = [0.0, 1.0, 0.0]", "up = [0.0, 0.0, 3.0]"), "camera.up", "parallel");
        // Only directions matter, whatever their length: an up or a view of 1e308 or 1e-300 is
        // one (each was refused as zero, or as a look_at equal to the position), and gives the
        // camera of the unit vector; a camera 1e308 away is named as such.
        let unit = parse(MINIMAL).unwrap().camera;
        for (from, to) in [
            ("up = [0.0, 1.0, 0.0]", "up = [0.0, 1e308, 0.0]"),
            ("up = [0.0, 1.0, 0.0]", "up = [0.0, 1e-300, 0.0]"),
            ("up = [0.0, 1.0, 0.0]", "up = [0.0, 5e-324, 0.0]"),
            ("up = [0.0, 1.0, 0.0]", "up = [1e-320, 1e-300, 0.0]"),
            ("look_at = [0.0, 1.0, 0.0]", "look_at = [0.0, 1.0, -1e308]"),
            ("look_at = [0.0, 1.0, 0.0]", "look_at = [0.0, 1.0, 4.9999999999999991]"),
        ] {
            let camera = parse(&MINIMAL.replace(from, to)).unwrap_or_else(|e| panic!("{to}: {e}")).camera;
            for (a, b) in [(camera.forward, unit.forward), (camera.right, unit.right), (camera.up, unit.up)] {
                assert!((a - b).length() < 1e-15, "{to}: {a} against {b}");
            }
        }
        expect_error(&MINIMAL.replace("[0.0, 1.0, 5.0]", "[0.0, 1.0, 1e308]"), "camera.position", "box diagonals");
        expect_error(&MINIMAL.replace("up = [0.0, 1.0, 0.0]", "up = [0.0, 0.0, 0.0]"), "camera.up", "zero");
        // An edge is named by its length, neither 0 nor NaN, and none is longer than the box.
        let edge = |e: &str| MINIMAL.replace("edge_u = [1.0, 0.0, 0.0]", &format!("edge_u = {e}"));
        expect_error(&edge("[1e-300, 0.0, 0.0]"), "light[0] (top).edge_u", "too short: |edge_u| = 1e-300");
        for long in ["[1e308, 0.0, 0.0]", "[7.0, 0.0, 0.0]", "[1e200, 0.0, 1e200]"] {
            expect_error(&edge(long), "light[0] (top).edge_u", "longer than the box's diagonal");
        }
        expect_error(&MINIMAL.replace("[32, 16]", "[0, 16]"), "camera.resolution", "between 1");
        expect_error(&MINIMAL.replace("sigma_a = 0.05", "sigma_a = -0.05"), "medium.sigma_a", "non-negative");
        expect_error(&MINIMAL.replace("max = [2.0, 2.0, 2.0]", "max = [2.0, 0.0, 2.0]"), "medium", "empty");
        for g in ["1.0", "-0.995", "nan", "inf"] {
            expect_error(
                &MINIMAL.replace("sigma_a = 0.05", &format!("sigma_a = 0.05\ng = {g}")),
                "medium.g",
                "[-0.99, 0.99]",
            );
        }
        let forward = parse(&MINIMAL.replace("sigma_a = 0.05", "sigma_a = 0.05\ng = 0.99")).unwrap();
        assert_eq!((forward.medium.g, parse(MINIMAL).unwrap().medium.g), (0.99, 0.0));
        // g joins the fingerprint only when it is not 0: an isotropic scene's is as before g.
        assert_ne!(forward.fingerprint(), parse(MINIMAL).unwrap().fingerprint());
        let zero = parse(&MINIMAL.replace("sigma_a = 0.05", "sigma_a = 0.05\ng = 0.0")).unwrap();
        assert_eq!(zero.fingerprint(), parse(MINIMAL).unwrap().fingerprint());
        expect_error(
            &MINIMAL.replace("edge_u = [1.0, 0.0, 0.0]", "edge_u = [0.0, 0.0, 0.0]"),
            "light[0] (top).edge_u",
            "too short",
        );
        // Arrays of exactly their length: one more element (of any type) is refused, as one less.
        for (from, to, field) in [
            ("position = [0.0, 1.0, 5.0]", "position = [0.0, 1.0, 5.0, 9.0]", "camera.position"),
            ("up = [0.0, 1.0, 0.0]", "up = [0.0, 1.0, 0.0, \"junk\", [1]]", "camera.up"),
            ("resolution = [32, 16]", "resolution = [32, 16, 1]", "camera.resolution"),
            ("resolution = [32, 16]", "resolution = [32]", "camera.resolution"),
            ("max = [2.0, 2.0, 2.0]", "max = [2.0, 2.0, 2.0, nan]", "medium.max"),
            ("edge_u = [1.0, 0.0, 0.0]", "edge_u = [1.0, 0.0, 0.0, 1e300]", "light[0].edge_u"),
        ] {
            expect_error(&MINIMAL.replace(from, to), field, "invalid length");
        }
        // A scattering coefficient whose planes' power no f32 holds (3e38 made every sum NaN).
        expect_error(
            &MINIMAL.replace("sigma_s = [0.1, 0.2, 0.3]", "sigma_s = 3e38"),
            "medium.sigma_s",
            "above the 1e30",
        );
        assert!(parse(&MINIMAL.replace("sigma_s = [0.1, 0.2, 0.3]", "sigma_s = 1e29")).is_ok());
        // A dim light beside a bright one carries little: no overflow from its tiny power.
        let dim = "\n[[light]]\ncorner = [-0.5, 0.5, -0.5]\nedge_u = [1.0, 0.0, 0.0]\nedge_v = [0.0, 0.0, 1.0]\nradiance = 1e-290\n";
        assert!(parse(&format!("{}{dim}", MINIMAL.replace("radiance = 4", "radiance = 1e20"))).is_ok());
        expect_error(
            &MINIMAL.replace("edge_u = [1.0, 0.0, 0.0]", "edge_u = [1.0, 0.0, 0.3]"),
            "light[0] (top).edge_v",
            "orthogonal",
        );
        expect_error(
            &MINIMAL.replace("corner = [-0.5, 1.9, -0.5]", "corner = [-0.5, 2.5, -0.5]"),
            "light[0] (top).corner",
            "inside the medium",
        );
        expect_error(&format!("{MINIMAL}\n[render]\nplanes = 0\n"), "render.planes", "between 1");
        // A K of the file is named by its key alone, not by the command line's flag.
        for (render, words) in [
            ("estimator = \"cmis-exact\"\norientations = 4", "applies to smis-cosine and smis-exact only"),
            ("orientations = 0", "between 1 and 64, got 0"),
        ] {
            let e = parse(&format!("{MINIMAL}\n[render]\n{render}\n")).unwrap_err();
            assert_eq!(e.field, "render.orientations", "{e}");
            assert!(e.message.contains(words) && !e.to_string().contains("--orientations"), "{e}");
        }
        expect_error(&format!("{MINIMAL}\n[render]\nestimator = \"best\"\n"), "render.estimator", "unknown estimator");
        expect_error(&format!("{MINIMAL}\n[render]\nsampler = \"halton\"\n"), "render.sampler", "unknown sampler");
        expect_error(&format!("{MINIMAL}\n[render]\nlobes = 1.5\n"), "render.lobes", "between 0 and 1, got 1.5");
        expect_error(&format!("{MINIMAL}\n[render]\nlobes = nan\n"), "render.lobes", "between 0 and 1");
        expect_error(&MINIMAL.replace("radiance = 4", "radiance = [1, 2]"), "light[0].radiance", "three numbers");
        expect_error(&MINIMAL.replace("radiance = 4", "radiance = 1e300"), "light", "total power");
    }

    /// A light's name holding a control character is refused, the name shown escaped: an
    /// escape sequence in it reached the terminal raw in every error naming the light.
    #[test]
    fn a_light_name_holding_control_characters_is_refused() {
        for name in [
            "\\u001b[31mred",
            "two\\nlines",
            "tab\\there",
            "bell\\u0007",
            "del\\u007f",
            "c1\\u009b2J",
            "left\\u202Eright",
            "isolate\\u2067",
        ] {
            let text = MINIMAL.replace("name = \"top\"", &format!("name = \"{name}\""));
            let e = parse(&text).unwrap_err();
            assert_eq!(e.field, "light[0].name", "{name}: {e}");
            assert!(e.message.contains("must not hold control characters"), "{name}: {e}");
            let line = e.to_string();
            assert!(!line.chars().any(acts_on_terminal), "{name}: {line:?}");
        }
        // Any other string is a name: empty, spaced, punctuated, beyond ASCII.
        for name in ["", "ceiling lamp", "a.b-c_d (2)", "lumière", "灯"] {
            let text = MINIMAL.replace("name = \"top\"", &format!("name = \"{name}\""));
            assert_eq!(parse(&text).unwrap_or_else(|e| panic!("{name}: {e}")).lights[0].name, name);
        }
    }

    /// Whatever of the file an error quotes stays on its line, escapes and all: an unknown key
    /// holding an escape sequence was echoed raw by the TOML reader's message.
    #[test]
    fn a_scene_error_is_one_line_whatever_it_quotes() {
        let text = MINIMAL.replace("vfov_deg = 40.0", "vfov_deg = 40.0\n\"\\u001b[2J\\nx\" = 1");
        let e = parse(&text).unwrap_err();
        assert!(e.message.contains("unknown field"), "{e}");
        let line = e.to_string();
        assert!(!line.chars().any(char::is_control) && line.contains("\\u{1b}[2J\\nx"), "{line:?}");
        // A right-to-left override in a key quoted back would turn the rest of the line around.
        let text = MINIMAL.replace("vfov_deg = 40.0", "vfov_deg = 40.0\n\"a\\u202Eb\" = 1");
        let line = parse(&text).unwrap_err().to_string();
        assert!(!line.contains('\u{202E}') && line.contains("a\\u{202e}b"), "{line:?}");
    }

    /// A key given twice is named with its line: the reader's "duplicate key" named none, and
    /// a line such as `position = [0, 1, 5]; up = ...` cannot hold it, but a table's header can.
    #[test]
    fn a_duplicate_key_is_named_with_its_line() {
        for (text, at, key) in [
            (MINIMAL.replace("vfov_deg = 40.0", "vfov_deg = 40.0\nvfov_deg = 41.0"), (7, 1), "`vfov_deg`"),
            (format!("{MINIMAL}\n[render]\nseed = 1\n\"seed\" = 2\n"), (24, 1), "`\"seed\"`"),
            (format!("{MINIMAL}\n[camera]\nzoom = 1\n"), (22, 2), "`camera`"),
            (format!("light = 1{MINIMAL}"), (15, 3), "`light`"),
        ] {
            let e = parse(&text).unwrap_err();
            let lines: Vec<&str> = text.lines().collect();
            assert_eq!(e.position, Some(at), "{e}: line {:?}", lines.get(at.0 - 1));
            assert!(e.message.contains(&format!("duplicate key {key}")), "{e}");
        }
    }

    #[test]
    fn syntax_errors_carry_a_position() {
        let e = parse(&MINIMAL.replace("vfov_deg = 40.0", "vfov_deg = = 40.0")).unwrap_err();
        assert_eq!(e.position.map(|p| p.0), Some(6), "{e}");
        assert!(e.to_string().starts_with("test.toml:6:"), "{e}");
    }
}
