//! Watching a long job (`--display-server`, `--checkpoint`): the live view in tev and the
//! checkpoint of a render or a reference, fed by the library's observers
//! ([`fogplanes::render::render_from`], [`fogplanes::reference::render_reference_from`]), and
//! what Ctrl-C says of the checkpoint.

use crate::args::WatchArgs;
use fogplanes::display::{LiveView, ViewSpec};
use fogplanes::film::Film;
use fogplanes::options::RenderOptions;
use fogplanes::partial::checkpoint::Checkpoint;
use fogplanes::partial::{Partial, Resume, RunningImage};
use fogplanes::reference::{ReferenceDone, ReferenceImage, ReferenceOptions, ReferenceStep};
use fogplanes::scene::Scene;
use fogplanes::spread::GroupSpread;
use indicatif::ProgressBar;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// What an interruption leaves, as the Ctrl-C handler says it: set once a checkpoint is open,
/// and held while a checkpoint file is written (so the handler waits for it and tells what is
/// on disk).
static LEFT: Mutex<Option<String>> = Mutex::new(None);

/// The open checkpoint's directory, whose files an interruption's note leaves to [`LEFT`].
static CHECKPOINT: Mutex<Option<PathBuf>> = Mutex::new(None);

/// What a checkpoint holds, once any checkpoint file under way is written, and its directory:
/// read first by an interruption, before it stops every write (a checkpoint's write holds
/// [`LEFT`] until its file is in place).
pub(crate) fn checkpoint_left() -> (Option<String>, Option<PathBuf>) {
    let left = LEFT.lock().unwrap_or_else(|e| e.into_inner()).clone();
    (left, CHECKPOINT.lock().unwrap_or_else(|e| e.into_inner()).clone())
}

/// What an interrupted command leaves: the outputs it wrote whole before the interruption
/// (`written`, the checkpoint's files aside), and what its checkpoint holds; else nothing.
pub(crate) fn interrupted_note((left, checkpoint): (Option<String>, Option<PathBuf>), written: &[PathBuf]) -> String {
    let outputs: Vec<String> = written
        .iter()
        .filter(|p| !checkpoint.as_ref().is_some_and(|dir| p.parent().is_some_and(|d| same_dir(d, dir))))
        .map(|p| p.display().to_string())
        .collect();
    match (outputs.is_empty(), left) {
        (true, None) => "nothing was written".into(),
        (true, Some(left)) => left,
        (false, left) => {
            let left = left.map(|l| format!("; {l}")).unwrap_or_default();
            format!("{} written whole before it{left}", outputs.join(", "))
        }
    }
}

fn same_dir(a: &Path, b: &Path) -> bool {
    a == b || std::fs::canonicalize(a).ok().is_some_and(|a| std::fs::canonicalize(b).is_ok_and(|b| a == b))
}

/// Runs `save` (a checkpoint write) under the lock of [`LEFT`], then records what the
/// checkpoint holds.
fn saving(save: impl FnOnce() -> fogplanes::Result<String>) -> fogplanes::Result<()> {
    let mut left = LEFT.lock().unwrap_or_else(|e| e.into_inner());
    *left = Some(save()?);
    Ok(())
}

fn resume_note(ck: &Checkpoint, holds: &str) -> String {
    format!("the checkpoint {} holds {holds}; run the same command to resume", ck.path().display())
}

/// A warning from the live view's thread, printed above the progress bar.
fn warner(bar: &ProgressBar) -> Arc<dyn Fn(&str) + Send + Sync> {
    let bar = bar.clone();
    Arc::new(move |m: &str| bar.suspend(|| eprintln!("warning: {m}")))
}

/// A render's checkpoint and live view.
pub(crate) struct RenderWatch<'a> {
    scene: &'a Scene,
    opts: &'a RenderOptions,
    checkpoint: Option<Checkpoint>,
    live: Option<(LiveView, RunningImage)>,
    /// What the checkpoint held at the start, until the render takes it.
    resumed: Resume,
}

impl<'a> RenderWatch<'a> {
    /// Opens the checkpoint (refusing another render's) and starts the live view, showing
    /// what the checkpoint holds at once.
    pub(crate) fn start(
        a: &WatchArgs,
        scene: &'a Scene,
        opts: &'a RenderOptions,
        bar: &ProgressBar,
    ) -> fogplanes::Result<Self> {
        let (mut checkpoint, mut resumed) = (None, Resume::default());
        if let Some(dir) = &a.checkpoint {
            let (ck, held) = Checkpoint::render(dir, scene, opts)?;
            *CHECKPOINT.lock().unwrap_or_else(|e| e.into_inner()) = Some(ck.path().to_path_buf());
            let done = held.last().map_or(0, |p| p.end);
            let resume = ck.resume(scene, opts, held)?;
            *LEFT.lock().unwrap_or_else(|e| e.into_inner()) =
                Some(resume_note(&ck, &format!("{done} of {} planes", opts.planes())));
            (checkpoint, resumed) = (Some(ck), resume);
        }
        let live = a.display_server.as_ref().map(|address| {
            let spec = ViewSpec {
                address: address.clone(),
                name: format!("{} {} {} planes", scene.name, opts.weighting().label(), opts.planes()),
                width: scene.camera.width,
                height: scene.camera.height,
                // With an error image, its running estimate as the layer `stderr`.
                layers: if opts.stderr() { vec![String::new(), "stderr".into()] } else { vec![String::new()] },
            };
            (LiveView::start(spec, warner(bar)), RunningImage::new(scene, opts))
        });
        // The image is created at once: black, or what the checkpoint holds.
        if let Some((view, image)) = &live {
            let (w, h) = (scene.camera.width, scene.camera.height);
            let mut layers = vec![image.image(&resumed.held).unwrap_or_else(|| Film::new(w, h))];
            if opts.stderr() {
                layers.push(Film::new(w, h));
            }
            view.show(layers, 0..h);
        }
        Ok(RenderWatch { scene, opts, checkpoint, live, resumed })
    }

    /// The planes the checkpoint held at the start (0 without one).
    pub(crate) fn resumed_planes(&self) -> usize {
        self.resumed.held.last().map_or(0, |p| p.end)
    }

    /// The devices whose gathering the checkpoint held at the start.
    pub(crate) fn resumed_devices(&self) -> fogplanes::options::Devices {
        let mut devices = fogplanes::options::Devices::default();
        for p in &self.resumed.held {
            devices.add(&p.devices);
        }
        devices
    }

    /// What the checkpoint held at the start, for the render to resume from.
    pub(crate) fn take_resumed(&mut self) -> Resume {
        std::mem::take(&mut self.resumed)
    }

    /// After each chunk: the checkpoint saves what the render holds, the view shows the image
    /// of its planes so far, and its error image from the plane groups closed so far (unless
    /// the last frame is still being sent).
    pub(crate) fn chunk_done(&mut self, held: &[Partial], spread: Option<&GroupSpread>) -> fogplanes::Result<()> {
        if let Some(ck) = &mut self.checkpoint {
            let (scene, opts) = (self.scene, self.opts);
            saving(|| {
                let done = held.last().map_or(0, |p| p.end);
                // The spread first: a kill before the nodes leaves the spread of the last
                // saved nodes beside it (kept until these are saved).
                if let Some(spread) = spread {
                    ck.save_spread(scene, opts, done, spread)?;
                }
                ck.save_render(scene, opts, held)?;
                if spread.is_some() {
                    ck.keep_spread(done)?;
                }
                Ok(resume_note(ck, &format!("{done} of {} planes", opts.planes())))
            })?;
        }
        self.show(held, spread);
        Ok(())
    }

    fn show(&self, held: &[Partial], spread: Option<&GroupSpread>) {
        if let Some((view, image)) = &self.live
            && view.ready()
            && let Some(film) = image.image(held)
        {
            let (w, h) = (film.width, film.height);
            let mut layers = vec![film];
            if self.opts.stderr() {
                let planes = held.last().map_or(0, |p| p.end);
                layers.push(spread.and_then(|s| image.stderr(s, planes)).unwrap_or_else(|| Film::new(w, h)));
            }
            view.show(layers, 0..h);
        }
    }

    /// Shows the finished image (and error image) and waits until it is sent.
    pub(crate) fn finish(self, film: &Film, stderr: Option<&Film>) {
        if let Some((view, _)) = self.live {
            view.show(std::iter::once(film).chain(stderr).cloned().collect(), 0..film.height);
            view.finish();
        }
    }
}

/// A reference's checkpoint and live view (its mean, with the standard error as the layer
/// `stderr`).
pub(crate) struct ReferenceWatch<'a> {
    scene: &'a Scene,
    opts: &'a ReferenceOptions,
    checkpoint: Option<Checkpoint>,
    live: Option<LiveView>,
    /// The image so far: the finished bands' rows, black elsewhere.
    mean: Film,
    stderr: Film,
    /// Whether the pilot pass is finished, and the rows of the final pass.
    pilot: bool,
    rows: u32,
    /// When the last step ended (a band's seconds, recorded in its part).
    last: Instant,
    done: ReferenceDone,
}

impl<'a> ReferenceWatch<'a> {
    pub(crate) fn start(
        a: &WatchArgs,
        scene: &'a Scene,
        opts: &'a ReferenceOptions,
        bar: &ProgressBar,
    ) -> fogplanes::Result<Self> {
        let (w, h) = (scene.camera.width, scene.camera.height);
        let mut watch = ReferenceWatch {
            scene,
            opts,
            checkpoint: None,
            live: None,
            mean: Film::new(w, h),
            stderr: Film::new(w, h),
            pilot: false,
            rows: 0,
            last: Instant::now(),
            done: ReferenceDone::default(),
        };
        if let Some(dir) = &a.checkpoint {
            let (ck, done) = Checkpoint::reference(dir, scene, opts)?;
            *CHECKPOINT.lock().unwrap_or_else(|e| e.into_inner()) = Some(ck.path().to_path_buf());
            watch.pilot = done.pilot.is_some();
            for b in &done.bands {
                watch.place(b.rows.start, &b.mean, &b.stderr);
            }
            watch.checkpoint = Some(ck);
            watch.done = done;
            *LEFT.lock().unwrap_or_else(|e| e.into_inner()) = Some(watch.note());
        }
        if let Some(address) = &a.display_server {
            let spec = ViewSpec {
                address: address.clone(),
                name: format!("{} reference {} spp", scene.name, opts.spp),
                width: w,
                height: h,
                layers: vec![String::new(), "stderr".into()],
            };
            let view = LiveView::start(spec, warner(bar));
            // The image is created at once: black, or the bands the checkpoint holds.
            view.show(vec![watch.mean.clone(), watch.stderr.clone()], 0..h);
            watch.live = Some(view);
        }
        Ok(watch)
    }

    /// Progress units already done: the pilot's rows, then the final pass's.
    pub(crate) fn units_done(&self) -> u64 {
        let pilot = if self.pilot { self.scene.camera.height } else { 0 };
        (pilot + self.rows) as u64
    }

    /// What the checkpoint held at the start, for the reference to resume from.
    pub(crate) fn take_done(&mut self) -> ReferenceDone {
        std::mem::take(&mut self.done)
    }

    fn place(&mut self, row: u32, mean: &Film, stderr: &Film) {
        let at = (row * self.mean.width) as usize;
        self.mean.pixels[at..at + mean.pixels.len()].copy_from_slice(&mean.pixels);
        self.stderr.pixels[at..at + stderr.pixels.len()].copy_from_slice(&stderr.pixels);
        self.rows += mean.height;
    }

    /// What is done: "the pilot pass and 32 of 180 rows".
    pub(crate) fn done(&self) -> String {
        let pilot = if self.pilot { "the pilot pass and " } else { "" };
        format!("{pilot}{} of {} rows", self.rows, self.scene.camera.height)
    }

    fn note(&self) -> String {
        resume_note(self.checkpoint.as_ref().expect("a checkpoint is open"), &self.done())
    }

    /// After the pilot pass and each band: the checkpoint saves it, the view shows the rows.
    pub(crate) fn step(&mut self, step: ReferenceStep) -> fogplanes::Result<()> {
        let seconds = std::mem::replace(&mut self.last, Instant::now()).elapsed().as_secs_f64();
        let (scene, opts) = (self.scene, self.opts);
        match step {
            ReferenceStep::Pilot(pilot) => {
                self.pilot = true;
                self.save(|ck| ck.save_pilot(scene, opts, pilot))?;
            }
            ReferenceStep::Band(band) => {
                self.place(band.rows.start, &band.mean, &band.stderr);
                self.save(|ck| ck.save_band(scene, opts, band, seconds))?;
                if let Some(view) = &self.live {
                    view.show(vec![self.mean.clone(), self.stderr.clone()], band.rows.clone());
                }
            }
        }
        Ok(())
    }

    /// Writes to the checkpoint, if there is one, through `write`.
    fn save(&mut self, write: impl FnOnce(&mut Checkpoint) -> fogplanes::Result<()>) -> fogplanes::Result<()> {
        if self.checkpoint.is_none() {
            return Ok(());
        }
        let note = self.note();
        let ck = self.checkpoint.as_mut().expect("checked above");
        saving(|| write(ck).map(|()| note))
    }

    /// Shows the finished reference and waits until it is sent.
    pub(crate) fn finish(self, reference: &ReferenceImage) {
        if let Some(view) = self.live {
            view.show(vec![reference.mean.clone(), reference.stderr.clone()], 0..reference.mean.height);
            view.finish();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An interruption names the outputs written whole before it, leaves the checkpoint's own
    /// files to its note, and says nothing was written only where nothing was.
    #[test]
    fn an_interruption_says_what_was_written() {
        let ck = PathBuf::from("/tmp/ck");
        let note = "the checkpoint /tmp/ck holds 3 of 9 planes".to_string();
        assert_eq!(interrupted_note((None, None), &[]), "nothing was written");
        assert_eq!(interrupted_note((Some(note.clone()), Some(ck.clone())), &[ck.join("c0.npz")]), note);
        let written = [PathBuf::from("a.exr"), PathBuf::from("se.exr"), ck.join("c0.npz")];
        assert_eq!(interrupted_note((None, None), &written[..2]), "a.exr, se.exr written whole before it");
        assert_eq!(
            interrupted_note((Some(note.clone()), Some(ck)), &written),
            format!("a.exr, se.exr written whole before it; {note}")
        );
    }
}
