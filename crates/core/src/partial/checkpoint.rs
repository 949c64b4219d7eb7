//! Checkpoints of long jobs (the command line's `--checkpoint CK`): a directory of part files
//! ([`super::parts`]), each written whole or not at all the moment its work is finished, so that
//! an interruption (Ctrl-C, SIGTERM, a kill, a lost node) leaves every file whole, and the same
//! job resumes from them with the bits of one uninterrupted run.
//!
//! | file | holds | written |
//! |---|---|---|
//! | `planes_A-B.npz` | a render's sums over planes `A:B`, a node of the canonical tree | as the node is held ([`super::frontier`]) |
//! | `spread_B.groups` | with an error image, its plane groups' spread after planes `0:B` (an `.npz` by another name, so that `CK/*.npz` names the parts alone) | before the nodes of the window of chunks ending at `B` (the spread agrees with its nodes at a window's end alone); the older one removed after them |
//! | `pilot.npz` | an adaptive reference's pilot pass, every row | once the pass is finished |
//! | `rows_J0-J1.npz` | a band of a reference's final pass | as the band is finished |
//! | `.lock` | nothing: locked while a process uses the directory | at opening |
//!
//! A render saves, after each chunk, the nodes it holds that are not saved yet (one file: the
//! node the chunk completed; with an error image, after each window of chunks gathered at once,
//! the spread first, then a file for each node the window completed), then removes the files of
//! the nodes it added into them; a kill between the two leaves those as well, which the next
//! opening removes, and a kill between a window's files leaves the window before's nodes and
//! spread, which the next opening resumes from. Every file is a part
//! of the job's image (`fogplanes merge CK/*.npz -o OUT.exr` reads a finished one, a reference's
//! `CK/rows_*.npz` without its pilot pass), read back through
//! [`read_part`] and trusted no more than any part: its kind, its fingerprint (the scene and
//! every setting that changes the image) and its shape are checked, and a directory holding
//! another job's parts or anything else is refused, naming it.

use super::file::PartKind;
use super::parts::{Part, read_part, reference_fingerprint, save_pilot_part, save_reference_part, save_render_part};
use super::{Partial, Resume, chunk_planes, fingerprint, frontier};
use crate::error::{Error, Result};
use crate::film::Film;
use crate::limits::CHUNK_PLANES;
use crate::options::RenderOptions;
use crate::reference::{ReferenceBand, ReferenceDone, ReferenceOptions};
use crate::scene::Scene;
use crate::spread::GroupSpread;
use glam::DVec3;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// An open checkpoint directory: locked against other processes while it lives, and the files
/// of the work it holds.
pub struct Checkpoint {
    dir: PathBuf,
    /// Holds the directory's lock (released when dropped, or by the system when the process
    /// ends however it ends).
    _lock: std::fs::File,
    /// The files that hold finished work now, with the range of planes or rows each holds.
    files: Vec<(Range<usize>, PathBuf)>,
    /// The files of a render's plane groups' spread, with the planes each follows.
    spreads: Vec<(usize, PathBuf)>,
}

/// The name of the directory's lock file (hidden: `CK/*.npz` never names it).
const LOCK: &str = ".lock";

impl Checkpoint {
    /// The checkpoint directory.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// Opens the checkpoint `dir` of a render of `scene` with `opts` (made if missing, its
    /// parent must exist) and reads what it holds: the nodes the render held after its last
    /// saved chunk ([`crate::render::render_from`] resumes from them; empty for a new
    /// checkpoint). Files of nodes already added into a saved one are removed.
    pub fn render(dir: &Path, scene: &Scene, opts: &RenderOptions) -> Result<(Checkpoint, Vec<Partial>)> {
        let (mut ck, found) = Checkpoint::open(dir, &["planes_"])?;
        let expected = fingerprint(scene, opts);
        let mut parts = Vec::with_capacity(found.len());
        for (path, part) in found {
            let m = &part.meta;
            if m.kind != PartKind::Render || m.fingerprint != expected || m.total != opts.planes() {
                return Err(another(dir, &path));
            }
            parts.push((m.start..m.end, path, part));
        }
        // The most chunks whose nodes are all there (all of them, unless a file was removed
        // by hand); the rest are nodes already added into those. With an error image, the
        // most whose spread is there too, where any spread is: a window of chunks saves its
        // nodes after its spread, one file after another, so that a kill between two of them
        // can leave the nodes of a chunk inside the window, which has no spread, beside the
        // window before's nodes and spread, which are kept. (Where there is no spread at all,
        // the render was begun without an error image, and the resume says so.)
        let n = opts.planes().div_ceil(CHUNK_PLANES);
        let mut ends: Vec<usize> = parts.iter().map(|(r, ..)| r.end.div_ceil(CHUNK_PLANES).min(n)).collect();
        ends.sort_unstable_by(|a, b| b.cmp(a));
        let complete: Vec<Vec<Range<usize>>> = ends
            .into_iter()
            .map(|done| frontier(0..n, done).iter().map(|c| chunk_planes(opts.planes(), c)).collect::<Vec<_>>())
            .filter(|nodes| nodes.iter().all(|r| parts.iter().any(|(p, ..)| p == r)))
            .collect();
        let spread_of =
            |nodes: &Vec<Range<usize>>| nodes.last().is_some_and(|r| ck.spreads.iter().any(|(e, _)| *e == r.end));
        let wanted = if opts.stderr() && !ck.spreads.is_empty() {
            // None: a kill within the first window's files; the render starts again.
            complete.iter().find(|nodes| spread_of(nodes))
        } else {
            complete.first()
        };
        let wanted = wanted.cloned().unwrap_or_default();
        let mut held = Vec::with_capacity(wanted.len());
        for node in &wanted {
            let i = parts.iter().position(|(r, ..)| r == node).expect("found above");
            let (range, path, part) = parts.swap_remove(i);
            held.push(part.partial()?);
            ck.files.push((range, path));
        }
        for (_, path, _) in parts {
            remove(&path)?;
        }
        Ok((ck, held))
    }

    /// Saves the nodes of `held` (what the render holds now) that no file holds yet, then
    /// removes the files of the nodes it no longer holds.
    pub fn save_render(&mut self, scene: &Scene, opts: &RenderOptions, held: &[Partial]) -> Result<()> {
        for p in held {
            if !self.files.iter().any(|(r, _)| *r == (p.start..p.end)) {
                let path = self.dir.join(format!("planes_{}-{}.npz", p.start, p.end));
                save_render_part(&path, scene, opts, p)?;
                self.files.push((p.start..p.end, path));
            }
        }
        let mut kept = Vec::with_capacity(held.len());
        for (range, path) in std::mem::take(&mut self.files) {
            if held.iter().any(|p| (p.start..p.end) == range) {
                kept.push((range, path));
            } else {
                remove(&path)?;
            }
        }
        self.files = kept;
        Ok(())
    }

    /// What the render resumes from: the nodes `held` ([`Checkpoint::render`]) and, when it
    /// makes an error image, the spread of their plane groups, which must be here (a render
    /// started without an error image has none: refused, with what to do).
    pub fn resume(&self, scene: &Scene, opts: &RenderOptions, held: Vec<Partial>) -> Result<Resume> {
        let done = held.last().map_or(0, |p| p.end);
        if !opts.stderr() || done == 0 {
            return Ok(Resume { held, spread: None });
        }
        let spread = self.spread(scene, opts, done)?.ok_or_else(|| {
            Error::bad_input(
                &self.dir,
                format!(
                    "holds {done} planes of this render but not the spread of their plane groups, which an error image needs (the render was started without one): resume without it, or remove the checkpoint"
                ),
            )
        })?;
        Ok(Resume { held, spread: Some(spread) })
    }

    /// The plane groups' spread of the render's error image after its first `planes` planes
    /// (what [`Checkpoint::render`] gave back), if the checkpoint holds it: read back and
    /// checked as any file ([`GroupSpread::check`]); `None` if it holds none for those planes
    /// (the render was started without an error image, or a kill came between the files).
    pub fn spread(&self, scene: &Scene, opts: &RenderOptions, planes: usize) -> Result<Option<GroupSpread>> {
        let Some((_, path)) = self.spreads.iter().find(|(end, _)| *end == planes) else { return Ok(None) };
        let bad = |m: String| Error::bad_input(path, m);
        let mut npz = super::file::Npz::open(path)?;
        let pixels = scene.camera.width as usize * scene.camera.height as usize;
        let meta = npz.read("meta", 1 << 16).and_then(|a| a.as_text()).map_err(bad)?;
        let meta: SpreadMeta = serde_json::from_str(&meta).map_err(|e| bad(format!("meta: {e}")))?;
        if meta.fingerprint != fingerprint(scene, opts) || meta.planes != planes || meta.pixels != pixels {
            return Err(another(&self.dir, path));
        }
        let bytes = super::file::entry_bytes("<f8", &[4, pixels, 3]);
        let mut vectors = |name: &str, shape: &[usize]| -> Result<Vec<DVec3>> {
            let values = npz.read(name, bytes).and_then(|a| a.as_f64s(shape)).map_err(bad)?;
            Ok(values.chunks_exact(3).map(DVec3::from_slice).collect())
        };
        let quarters = vectors("quarters", &[4, pixels, 3])?;
        let open = vectors("open", &[2, pixels, 3])?;
        let spread = GroupSpread {
            squares: vectors("squares", &[pixels, 3])?,
            within: vectors("within", &[pixels, 3])?,
            quarters: std::array::from_fn(|q| quarters[q * pixels..(q + 1) * pixels].to_vec()),
            open: std::array::from_fn(|h| open[h * pixels..(h + 1) * pixels].to_vec()),
            open_key: meta.open_key,
            open_planes: meta.open_planes,
            planes: meta.quarter_planes,
            groups: meta.groups,
            halved: meta.halved,
        };
        spread.check(pixels, opts.ray_sets(), planes).map_err(|m| bad(format!("not a spread of this render: {m}")))?;
        Ok(Some(spread))
    }

    /// Saves the spread of the render's plane groups after its first `planes` planes: before
    /// the nodes of the chunk that ends there ([`Checkpoint::save_render`]), so that a kill
    /// between the two leaves the spread of the nodes saved before.
    pub fn save_spread(
        &mut self,
        scene: &Scene,
        opts: &RenderOptions,
        planes: usize,
        spread: &GroupSpread,
    ) -> Result<()> {
        use super::file::{Array, write_npz};
        let pixels = spread.squares.len();
        let meta = SpreadMeta {
            fingerprint: fingerprint(scene, opts),
            planes,
            pixels,
            groups: spread.groups,
            quarter_planes: spread.planes,
            open_key: spread.open_key,
            open_planes: spread.open_planes,
            halved: spread.halved,
        };
        let flat = |v: &[DVec3]| v.iter().flat_map(|d| d.to_array()).collect::<Vec<f64>>();
        let arrays = [
            Array::text("meta", &serde_json::to_string(&meta).expect("plain data")),
            Array::f64s("squares", vec![pixels, 3], flat(&spread.squares).into_iter()),
            Array::f64s(
                "quarters",
                vec![4, pixels, 3],
                spread.quarters.iter().flat_map(|q| flat(q)).collect::<Vec<_>>().into_iter(),
            ),
            Array::f64s("within", vec![pixels, 3], flat(&spread.within).into_iter()),
            Array::f64s(
                "open",
                vec![2, pixels, 3],
                spread.open.iter().flat_map(|h| flat(h)).collect::<Vec<_>>().into_iter(),
            ),
        ];
        let path = self.dir.join(format!("spread_{planes}.groups"));
        write_npz(&path, &arrays)?;
        self.spreads.push((planes, path));
        Ok(())
    }

    /// Removes the spreads of other planes than `planes` (once the nodes that go with it are
    /// saved).
    pub fn keep_spread(&mut self, planes: usize) -> Result<()> {
        for (_, path) in self.spreads.iter().filter(|(end, _)| *end != planes) {
            remove(path)?;
        }
        self.spreads.retain(|(end, _)| *end == planes);
        Ok(())
    }

    /// Opens the checkpoint `dir` of a reference of `scene` with `opts` (as [`Checkpoint::render`])
    /// and reads what it holds: its pilot pass (adaptive) and finished bands, for
    /// [`crate::reference::render_reference_from`].
    pub fn reference(dir: &Path, scene: &Scene, opts: &ReferenceOptions) -> Result<(Checkpoint, ReferenceDone)> {
        let (mut ck, found) = Checkpoint::open(dir, &["pilot.npz", "rows_"])?;
        let h = scene.camera.height as usize;
        let mut done = ReferenceDone::default();
        let mut bands: Vec<(PathBuf, Part)> = Vec::new();
        for (path, part) in found {
            let m = &part.meta;
            let pilot = path.file_name().is_some_and(|n| n == "pilot.npz");
            let (kind, fingerprint) = match pilot {
                true => (PartKind::Pilot, reference_fingerprint(scene, opts, true)),
                false => (PartKind::Reference, reference_fingerprint(scene, opts, false)),
            };
            if m.kind != kind || m.fingerprint != fingerprint || m.total != h || (pilot && opts.uniform) {
                return Err(another(dir, &path));
            }
            if pilot {
                if (m.start, m.end) != (0, h) {
                    return Err(part.bad("a checkpoint's pilot pass holds every row"));
                }
                done.pilot = Some(part.film("pilot")?);
                ck.files.push((0..h, path));
            } else {
                bands.push((path, part));
            }
        }
        // Bands never overlap as written; any that do (copied in by hand) hold the same pixels.
        bands.sort_by_key(|(_, p)| (p.meta.start, p.meta.end));
        let mut next = 0;
        for (path, part) in bands {
            let rows = part.meta.start..part.meta.end;
            if rows.start < next {
                remove(&path)?;
                continue;
            }
            next = rows.end;
            let band = |name| part.film(name);
            let rows32 = rows.start as u32..rows.end as u32;
            done.bands.push(ReferenceBand { rows: rows32, mean: band("mean")?, stderr: band("stderr")? });
            ck.files.push((rows, path));
        }
        Ok((ck, done))
    }

    /// Saves the finished pilot pass of an adaptive reference.
    pub fn save_pilot(&mut self, scene: &Scene, opts: &ReferenceOptions, pilot: &Film) -> Result<()> {
        let path = self.dir.join("pilot.npz");
        save_pilot_part(&path, scene, opts, 0..scene.camera.height, pilot, 0.0)?;
        self.files.push((0..scene.camera.height as usize, path));
        Ok(())
    }

    /// Saves a finished band of a reference's final pass.
    pub fn save_band(
        &mut self,
        scene: &Scene,
        opts: &ReferenceOptions,
        band: &ReferenceBand,
        seconds: f64,
    ) -> Result<()> {
        let path = self.dir.join(format!("rows_{}-{}.npz", band.rows.start, band.rows.end));
        save_reference_part(&path, scene, opts, band.rows.clone(), (&band.mean, &band.stderr), seconds)?;
        self.files.push((band.rows.start as usize..band.rows.end as usize, path));
        Ok(())
    }

    /// Opens (making it if missing) and locks `dir`, removes the temporary files of writes a
    /// kill interrupted, and reads every part whose name starts with one of `ours`; refuses
    /// anything else in it.
    fn open(dir: &Path, ours: &[&str]) -> Result<(Checkpoint, Vec<(PathBuf, Part)>)> {
        let bad = |m: String| Error::bad_input(dir, m);
        match std::fs::metadata(dir) {
            Ok(m) if !m.is_dir() => {
                return Err(bad("is not a directory: a checkpoint is a directory of part files".into()));
            }
            Ok(_) => {}
            Err(_) => {
                std::fs::create_dir(dir).map_err(|e| bad(format!("cannot make the checkpoint directory: {e}")))?
            }
        }
        let lock = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(dir.join(LOCK))
            .map_err(|e| bad(format!("cannot write in the checkpoint directory: {e}")))?;
        match lock.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                return Err(bad("is in use by another fogplanes process".into()));
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(bad(format!("cannot lock the checkpoint: {e}"))),
        }
        let entries = std::fs::read_dir(dir).map_err(|e| bad(format!("cannot read: {e}")))?;
        let mut names = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| bad(format!("cannot read: {e}")))?;
            names.push(entry.file_name().to_string_lossy().into_owned());
        }
        names.sort();
        let (mut found, mut spreads) = (Vec::new(), Vec::new());
        for name in names {
            let path = dir.join(&name);
            let part_name =
                |n: &str| n.ends_with(".npz") && ["planes_", "pilot.npz", "rows_"].iter().any(|o| n.starts_with(o));
            if name == LOCK {
                continue;
            }
            // A write a kill cut short (film::temporary_path's names); the lock says no
            // process is writing it now.
            let interrupted = name.strip_prefix('.').and_then(|n| n.strip_suffix(".tmp"));
            let cut_short = interrupted.is_some_and(|n| {
                n.split_once(".npz.").is_some_and(|(stem, _)| part_name(&format!("{stem}.npz")))
                    || n.split_once(".groups.").is_some_and(|(stem, _)| spread_end(&format!("{stem}.groups")).is_some())
            });
            if cut_short {
                remove(&path)?;
                continue;
            }
            if let Some(end) = spread_end(&name) {
                if !ours.contains(&"planes_") {
                    return Err(another(dir, &path));
                }
                spreads.push((end, path));
                continue;
            }
            if !part_name(&name) {
                return Err(bad(format!(
                    "holds {name}, which is not a file of a fogplanes checkpoint: give a new or empty directory"
                )));
            }
            if !ours.iter().any(|o| name.starts_with(o)) {
                return Err(another(dir, &path));
            }
            let part = read_part(&path)?;
            found.push((path, part));
        }
        Ok((Checkpoint { dir: dir.to_path_buf(), _lock: lock, files: Vec::new(), spreads }, found))
    }
}

/// What a spread file records besides its buffers.
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct SpreadMeta {
    fingerprint: String,
    planes: usize,
    pixels: usize,
    groups: usize,
    quarter_planes: [usize; 4],
    open_key: Option<(u32, usize)>,
    /// Each half's planes in the open group.
    open_planes: [usize; 2],
    /// Closed groups with two halves.
    halved: usize,
}

/// The planes a spread file's name says it follows (`spread_B.groups`), if it is one.
fn spread_end(name: &str) -> Option<usize> {
    name.strip_prefix("spread_")?.strip_suffix(".groups")?.parse().ok()
}

/// The error of a checkpoint that holds another job's work.
fn another(dir: &Path, file: &Path) -> Error {
    let name = file.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    Error::bad_input(
        dir,
        format!(
            "holds the work of another render or reference ({name}: another scene or other settings); \
             remove it to start afresh, or give another directory"
        ),
    )
}

fn remove(path: &Path) -> Result<()> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(Error::write(path, format!("cannot remove: {e}"))),
        _ => Ok(()),
    }
}
