//! Part files merged into images: the render parts of a job array's plane ranges, the row
//! bands of a reference or its pilot (the command line's `merge`, and `render --plane-range`'s
//! check). A part's recorded settings are resolved through [`crate::settings`] like a caller's,
//! so a part is trusted no more than an argument.

use crate::error::{Error, Result};
use crate::film::Film;
use crate::options::RenderOptions;
use crate::partial::file::{PartKind, RenderRecord};
use crate::partial::parts::{Part, read_part, reference_fingerprint, reference_options_of, scene_of};
use crate::partial::{Partial, fingerprint, finish, merge_in_canonical_order};
use crate::reference::ReferenceOptions;
use crate::scene::Scene;
use crate::settings::{Overrides, resolve_render};
use std::path::PathBuf;

/// The options a render part records, resolved as a caller's would be (the kernel that ran is
/// not needed to merge: every kernel gives the same bits).
fn recorded_options(scene: &Scene, r: &RenderRecord) -> std::result::Result<RenderOptions, String> {
    let given = Overrides {
        estimator: Some(r.estimator.parse()?),
        orientations: Some(r.orientations),
        planes: Some(r.planes as u64),
        seed: Some(r.seed),
        sampler: Some(r.sampler.parse()?),
        lobes: Some(r.lobes),
        spp: Some(r.spp),
        pixel_center: r.pixel_center,
        accelerator: Some(r.accelerator.parse()?),
        ..Overrides::default()
    };
    resolve_render(scene, &given).map(|r| r.options).map_err(|e| format!("its settings: {e}"))
}

/// What parts merge into.
pub enum Merged {
    /// A whole render: its image, the scene, the settings and the merged sums, which hold the
    /// devices its parts were gathered on ([`Partial::devices`]: more than one, and the image
    /// agrees with each device's render within f32 rounding, docs/gpu.md, but is the bits of
    /// neither).
    Render { scene: Scene, options: RenderOptions, partial: Partial, image: Film },
    /// A whole reference: mean and standard error.
    Reference { scene: Scene, options: ReferenceOptions, mean: Film, stderr: Film, seconds: f64 },
    /// A whole pilot pass.
    Pilot { scene: Scene, options: ReferenceOptions, pilot: Film, seconds: f64 },
}

/// Reads and merges parts of one render (plane ranges) or one reference or pilot (row bands),
/// given in any order: refuses parts of different kinds, scenes or settings, overlapping
/// ranges and gaps, each with one line naming the files.
pub fn merge_parts(paths: &[PathBuf]) -> Result<Merged> {
    let parts = paths.iter().map(|p| read_part(p)).collect::<Result<Vec<_>>>()?;
    let first = parts.first().ok_or_else(|| Error::Partial("no parts to merge".into()))?;
    // Each part's recorded scene and settings, not only its fingerprint, are the first's: a
    // band whose recorded width had been changed was stacked as it was, shifting every later
    // row (or indexing past the image).
    // The device is not a setting of the image: parts of different devices merge. Nor is the
    // kernel (not in the fingerprint: every kernel gives the same bits), which `auto` makes the
    // widest of each node's CPU: parts of an AVX-512 node and an AVX2 node were refused as
    // "parts of different images".
    let settings = |r: &Option<RenderRecord>| {
        r.clone().map(|r| RenderRecord { devices: Vec::new(), device: None, kernel: String::new(), ..r })
    };
    for p in &parts[1..] {
        let (a, b) = (&first.meta, &p.meta);
        // An adaptive reference's checkpoint holds its pilot pass beside its bands: `CK/*.npz`
        // names both, and only the bands are the image.
        if let Some((pilot, band)) = match (a.kind, b.kind) {
            (PartKind::Pilot, PartKind::Reference) => Some((first, p)),
            (PartKind::Reference, PartKind::Pilot) => Some((p, first)),
            _ => None,
        } {
            return Err(Error::Partial(format!(
                "{} is a reference's pilot pass and {} a band of its image: merge the bands alone \
                 (of a checkpoint CK, CK/rows_*.npz)",
                pilot.path.display(),
                band.path.display()
            )));
        }
        if b.kind != a.kind
            || b.fingerprint != a.fingerprint
            || b.total != a.total
            || b.scene != a.scene
            || settings(&b.render) != settings(&a.render)
            || b.reference != a.reference
        {
            return Err(Error::Partial(format!(
                "{} and {} are parts of different images (another scene, other settings or another kind)",
                first.path.display(),
                p.path.display()
            )));
        }
    }
    let scene = scene_of(&first.meta.scene).map_err(|e| first.bad(format!("its scene: {e}")))?;
    match first.meta.kind {
        PartKind::Render => {
            let record = first.meta.render.as_ref().ok_or_else(|| first.bad("no render settings"))?;
            let options = recorded_options(&scene, record).map_err(|e| first.bad(e))?;
            if fingerprint(&scene, &options) != first.meta.fingerprint {
                return Err(
                    first.bad("its settings do not give its fingerprint (written by another fogplanes version?)")
                );
            }
            if first.meta.total != options.planes() {
                return Err(first.bad(format!(
                    "its planes {}:{} of {}: its settings render {} planes",
                    first.meta.start,
                    first.meta.end,
                    first.meta.total,
                    options.planes()
                )));
            }
            let partials = parts.iter().map(Part::partial).collect::<Result<Vec<_>>>()?;
            let partial = merge_in_canonical_order(partials).map_err(|e| named(&parts, e))?;
            let image = finish(&scene, &options, &partial)?;
            Ok(Merged::Render { scene, options, partial, image })
        }
        kind => {
            let record = first.meta.reference.as_ref().ok_or_else(|| first.bad("no reference settings"))?;
            let options = reference_options_of(record);
            let pilot = kind == PartKind::Pilot;
            if reference_fingerprint(&scene, &options, pilot) != first.meta.fingerprint {
                return Err(
                    first.bad("its settings do not give its fingerprint (written by another fogplanes version?)")
                );
            }
            if first.meta.total != scene.camera.height as usize {
                return Err(first.bad("its rows do not match its scene's resolution"));
            }
            let mut order: Vec<&Part> = parts.iter().collect();
            order.sort_by_key(|p| (p.meta.start, p.meta.end));
            let mut next = 0;
            for p in &order {
                if p.meta.start > next {
                    return Err(Error::Partial(format!("rows {next}:{} are missing", p.meta.start)));
                }
                if p.meta.start < next {
                    return Err(Error::Partial(format!(
                        "{} overlaps another part (rows {}:{})",
                        p.path.display(),
                        p.meta.start,
                        p.meta.end
                    )));
                }
                next = p.meta.end;
            }
            if next != first.meta.total {
                return Err(Error::Partial(format!("rows {next}:{} are missing", first.meta.total)));
            }
            let seconds = parts.iter().map(|p| p.meta.seconds).sum();
            let stack = |name: &str| -> Result<Film> {
                let mut film = Film::new(scene.camera.width, scene.camera.height);
                film.pixels.clear();
                for p in &order {
                    let band = p.film(name)?;
                    if band.width != scene.camera.width {
                        return Err(
                            p.bad(format!("its rows are {} wide, the image {}", band.width, scene.camera.width))
                        );
                    }
                    film.pixels.extend(band.pixels);
                }
                Ok(film)
            };
            if pilot {
                Ok(Merged::Pilot { pilot: stack("pilot")?, scene, options, seconds })
            } else {
                Ok(Merged::Reference { mean: stack("mean")?, stderr: stack("stderr")?, scene, options, seconds })
            }
        }
    }
}

/// A merge error of render parts, with the files that hold the planes it names.
fn named(parts: &[Part], e: Error) -> Error {
    match e {
        Error::Partial(m) => {
            let files: Vec<String> = parts
                .iter()
                .filter(|p| m.contains(&format!("planes {}:{}", p.meta.start, p.meta.end)))
                .map(|p| p.path.display().to_string())
                .collect();
            if files.is_empty() { Error::Partial(m) } else { Error::Partial(format!("{m} ({})", files.join(", "))) }
        }
        e => e,
    }
}
