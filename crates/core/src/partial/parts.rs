//! Partial files of renders and references: written by the jobs of a job array, read and
//! merged into one image (the command line's `render --plane-range`, `reference --rows` and
//! `merge`). The format is [`super::file`]'s.

use super::file::{self, Array, PartKind, PartMeta, ReferenceRecord, RenderRecord, SceneRecord};
use super::{Partial, stable_hash};
use crate::error::{Error, Result};
use crate::film::Film;
use crate::options::{Devices, RenderOptions};
use crate::reference::ReferenceOptions;
use crate::scene::Scene;
use glam::{DVec3, Vec3};
use std::path::{Path, PathBuf};

/// The scene as a part records it: its text (a scene made otherwise cannot travel).
fn scene_record(scene: &Scene) -> Result<SceneRecord> {
    let source = scene.source().ok_or_else(|| {
        Error::Partial("the scene was not made from a scene file or text, so no part can carry it".into())
    })?;
    Ok(SceneRecord {
        name: scene.name.clone(),
        file: source.file.clone(),
        text: source.text.clone(),
        resolution: [scene.camera.width, scene.camera.height],
    })
}

/// The scene a part records, remade.
pub fn scene_of(r: &SceneRecord) -> Result<Scene> {
    Scene::parse(&r.text, &r.file, &r.name)?.with_resolution(r.resolution[0], r.resolution[1])
}

/// The settings of a render as its parts record them, with the devices whose gathering a
/// part holds.
pub fn render_record(o: &RenderOptions, devices: &Devices) -> RenderRecord {
    RenderRecord {
        planes: o.planes,
        estimator: o.weighting.estimator.name().into(),
        orientations: o.weighting.orientations,
        seed: o.seed,
        sampler: o.sampler.name().into(),
        lobes: o.lobes,
        spp: o.spp,
        pixel_center: o.pixel_center,
        accelerator: o.accelerator.name().into(),
        kernel: o.kernel.name().into(),
        devices: devices.names().to_vec(),
        device: None,
    }
}

/// Identifies a reference image (`pilot`: its pilot pass): the scene's content and every
/// setting that changes it.
pub fn reference_fingerprint(scene: &Scene, o: &ReferenceOptions, pilot: bool) -> String {
    let what = if pilot {
        "pilot"
    } else if o.uniform {
        "uniform"
    } else {
        "adaptive"
    };
    let description = format!(
        "fogplanes {} reference {what} | {:?} | {:?} | {:?} | spp {} | seed {} | centre {}",
        env!("CARGO_PKG_VERSION"),
        scene.camera,
        scene.medium,
        scene.lights,
        o.spp,
        o.seed,
        o.pixel_center
    );
    stable_hash(&[description.as_bytes()])
}

/// The metadata of a part of `kind` over `range` = (start, end, total) of the image
/// `fingerprint` names, with the scene it carries; no counts, no settings yet.
pub fn meta_of(kind: PartKind, fingerprint: String, scene: &Scene, range: (usize, usize, usize)) -> Result<PartMeta> {
    Ok(PartMeta {
        format: file::FORMAT.into(),
        version: file::VERSION,
        fogplanes: env!("CARGO_PKG_VERSION").into(),
        kind,
        fingerprint,
        scene: scene_record(scene)?,
        start: range.0,
        end: range.1,
        total: range.2,
        hits: 0,
        seconds: 0.0,
        render: None,
        reference: None,
    })
}

fn meta_array(meta: &PartMeta) -> Array {
    Array::text("meta", &serde_json::to_string(meta).expect("plain data serialises"))
}

fn pixel_shape(rows: usize, width: u32) -> Vec<usize> {
    vec![rows, width as usize, 3]
}

fn f32s(film: &Film) -> impl Iterator<Item = f32> + '_ {
    film.pixels.iter().flat_map(|p| p.to_array())
}

/// Writes the partial of a render of `scene` with `opts`.
pub fn save_render_part(path: &Path, scene: &Scene, opts: &RenderOptions, p: &Partial) -> Result<()> {
    let mut meta = meta_of(PartKind::Render, p.fingerprint.clone(), scene, (p.start, p.end, p.planes_total))?;
    (meta.hits, meta.seconds, meta.render) = (p.hits, p.seconds, Some(render_record(opts, &p.devices)));
    let sums = Array::f64s("sums", pixel_shape(p.height as usize, p.width), p.sums.iter().flat_map(|s| s.to_array()));
    file::write_npz(path, &[meta_array(&meta), sums])
}

/// Writes rows `rows` of a reference (`mean` and `stderr` are the band).
pub fn save_reference_part(
    path: &Path,
    scene: &Scene,
    opts: &ReferenceOptions,
    rows: std::ops::Range<u32>,
    (mean, stderr): (&Film, &Film),
    seconds: f64,
) -> Result<()> {
    save_band(path, PartKind::Reference, scene, opts, rows, &[("mean", mean), ("stderr", stderr)], seconds)
}

/// Writes rows `rows` of an adaptive reference's pilot pass (the whole image when they are all
/// its rows: what `reference --pilot` reads).
pub fn save_pilot_part(
    path: &Path,
    scene: &Scene,
    opts: &ReferenceOptions,
    rows: std::ops::Range<u32>,
    pilot: &Film,
    seconds: f64,
) -> Result<()> {
    save_band(path, PartKind::Pilot, scene, opts, rows, &[("pilot", pilot)], seconds)
}

/// Writes the `films` of a band of rows of a reference or its pilot.
fn save_band(
    path: &Path,
    kind: PartKind,
    scene: &Scene,
    opts: &ReferenceOptions,
    rows: std::ops::Range<u32>,
    films: &[(&str, &Film)],
    seconds: f64,
) -> Result<()> {
    let range = (rows.start as usize, rows.end as usize, scene.camera.height as usize);
    let fingerprint = reference_fingerprint(scene, opts, kind == PartKind::Pilot);
    let mut meta = meta_of(kind, fingerprint, scene, range)?;
    (meta.seconds, meta.reference) = (seconds, Some(reference_record(opts)));
    let shape = pixel_shape(rows.len(), scene.camera.width);
    let mut arrays = vec![meta_array(&meta)];
    arrays.extend(films.iter().map(|(name, film)| Array::f32s(name, shape.clone(), f32s(film))));
    file::write_npz(path, &arrays)
}

fn reference_record(o: &ReferenceOptions) -> ReferenceRecord {
    ReferenceRecord { spp: o.spp, seed: o.seed, pixel_center: o.pixel_center, uniform: o.uniform }
}

pub fn reference_options_of(r: &ReferenceRecord) -> ReferenceOptions {
    ReferenceOptions { spp: r.spp, seed: r.seed, pixel_center: r.pixel_center, uniform: r.uniform }
}

/// A part read back: its metadata and arrays checked ([`read_part`]).
pub struct Part {
    pub path: PathBuf,
    pub meta: PartMeta,
    pub arrays: Vec<Array>,
}

impl Part {
    pub fn bad(&self, message: impl std::fmt::Display) -> Error {
        Error::bad_input(&self.path, message.to_string())
    }

    /// The band of rows of its array `name` (a reference's `mean`, `stderr`, a `pilot`).
    pub fn film(&self, name: &str) -> Result<Film> {
        let array =
            self.arrays.iter().find(|a| a.name == name).ok_or_else(|| self.bad(format!("no '{name}' array")))?;
        let (w, rows) = (self.meta.scene.resolution[0], self.meta.end - self.meta.start);
        let values = array.as_f32s(&pixel_shape(rows, w)).map_err(|m| self.bad(m))?;
        let mut film = Film::new(w, u32::try_from(rows).map_err(|_| self.bad("too many rows"))?);
        film.pixels = values.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        Ok(film)
    }

    /// The render partial it holds, checked ([`Partial::check`]).
    pub fn partial(&self) -> Result<Partial> {
        let m = &self.meta;
        let [w, h] = m.scene.resolution;
        let array = self.arrays.iter().find(|a| a.name == "sums").ok_or_else(|| self.bad("no 'sums' array"))?;
        let sums = array.as_f64s(&pixel_shape(h as usize, w)).map_err(|e| self.bad(e))?;
        let partial = Partial {
            width: w,
            height: h,
            sums: sums.chunks_exact(3).map(|c| DVec3::new(c[0], c[1], c[2])).collect(),
            start: m.start,
            end: m.end,
            planes_total: m.total,
            fingerprint: m.fingerprint.clone(),
            hits: m.hits,
            seconds: m.seconds,
            devices: m
                .render
                .as_ref()
                .ok_or_else(|| self.bad("no render settings"))?
                .devices()
                .map_err(|e| self.bad(e))?,
        };
        partial.check().map_err(|e| self.bad(e))?;
        Ok(partial)
    }
}

/// Reads a part written by this module, trusting nothing it claims before checking it: a
/// regular file; its metadata first ([`file::meta`], at most [`file::MAX_META_BYTES`]); then
/// the arrays its kind holds, each refused before it is read if its entry is larger than the
/// shape the metadata records needs, and of that dtype and shape; and their numbers: a band's
/// values finite and non-negative (means and standard errors of non-negative samples), a
/// render's sums as [`Partial::check`] has them. Every refusal is one line naming the file
/// (and the pixel).
pub fn read_part(path: &Path) -> Result<Part> {
    let bad = |m: String| Error::bad_input(path, m);
    let mut npz = file::Npz::open(path)?;
    let meta = file::meta(&npz.read("meta", file::MAX_META_BYTES).map_err(bad)?).map_err(bad)?;
    let mut arrays = Vec::new();
    for (name, descr, shape) in file::expected_arrays(&meta) {
        let array = npz.read(name, file::entry_bytes(descr, &shape)).map_err(bad)?;
        array.check(descr, &shape).map_err(bad)?;
        arrays.push(array);
    }
    let part = Part { path: path.to_path_buf(), meta, arrays };
    match part.meta.kind {
        PartKind::Render => {
            part.partial()?;
        }
        PartKind::Reference | PartKind::Pilot => {
            let holds = if part.meta.kind == PartKind::Pilot { "standard errors" } else { "means and standard errors" };
            for (name, _, _) in file::expected_arrays(&part.meta) {
                if let Some(p) = part.film(name)?.first_outside(f32::MAX as f64) {
                    return Err(part.bad(format!(
                        "{name}: {p} (of the band of rows {}:{}): a band holds {holds}, finite and non-negative",
                        part.meta.start, part.meta.end
                    )));
                }
            }
        }
    }
    Ok(part)
}

/// The whole pilot of an adaptive reference read from `path` (a merged pilot file), checked
/// against the reference it is for: its kind, settings, scene and resolution.
pub fn read_pilot(path: &Path, scene: &Scene, opts: &ReferenceOptions) -> Result<Film> {
    let part = read_part(path)?;
    let cam = &scene.camera;
    if part.meta.kind != PartKind::Pilot
        || part.meta.fingerprint != reference_fingerprint(scene, opts, true)
        || part.meta.scene.resolution != [cam.width, cam.height]
    {
        return Err(part.bad("not the pilot pass of this reference (another scene or other settings)"));
    }
    if part.meta.start != 0 || part.meta.end != part.meta.total {
        return Err(part.bad(format!(
            "holds pilot rows {}:{} only: merge the pilot's row parts first (fogplanes merge)",
            part.meta.start, part.meta.end
        )));
    }
    part.film("pilot")
}
