//! Watching a long job from the command line: the live view in tev, received by a listener
//! that decodes tev's protocol itself (packet by packet, as tev's `Ipc.cpp` reads them), and
//! checkpoints: a render and a reference killed at random moments resume to the bits of an
//! uninterrupted run; another job's checkpoint is refused with one line.

use crate::common::options;
use crate::common::{fogplanes, refused};
use fogplanes::control::Control;
use fogplanes::film::Film;
use fogplanes::limits::CHUNK_PLANES;
use fogplanes::partial::{Resume, RunningImage};
use fogplanes::render::render_from;
use fogplanes::scene::Scene;
use fogplanes::settings::Overrides;
use rand::{Rng, SeedableRng};
use std::io::Read;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const SCENE: &str = "media_scenes/six_lights.toml";

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fogplanes-live-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn succeeded(o: &Output, what: &str) -> String {
    assert!(o.status.success(), "{what}: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

fn same_bits(a: &Film, b: &Film) -> bool {
    a.width == b.width
        && a.pixels.len() == b.pixels.len()
        && a.pixels.iter().zip(&b.pixels).all(|(p, q)| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits))
}

// -------------------------------------------------------------------------------------------
// tev's protocol, decoded independently of the sender

/// A packet as tev reads it.
#[derive(Debug)]
enum Packet {
    Create { name: String, width: i32, height: i32, channels: Vec<String> },
    Update { name: String, channels: Vec<String>, x: i32, y: i32, w: i32, h: i32, values: Vec<f32> },
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> &[u8] {
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        s
    }
    fn byte(&mut self) -> u8 {
        self.take(1)[0]
    }
    fn i32(&mut self) -> i32 {
        i32::from_le_bytes(self.take(4).try_into().unwrap())
    }
    fn string(&mut self) -> String {
        let end = self.bytes[self.at..].iter().position(|&b| b == 0).expect("a NUL-terminated string");
        let s = String::from_utf8(self.bytes[self.at..self.at + end].to_vec()).unwrap();
        self.at += end + 1;
        s
    }
    fn strings(&mut self, n: i32) -> Vec<String> {
        (0..n).map(|_| self.string()).collect()
    }
}

/// Every packet of a stream: a `u32` length (itself included), a type byte, the fields.
fn decode(stream: &[u8]) -> Vec<Packet> {
    let mut packets = Vec::new();
    let mut at = 0;
    while at < stream.len() {
        let len = u32::from_le_bytes(stream[at..at + 4].try_into().unwrap()) as usize;
        assert!(len >= 5 && at + len <= stream.len(), "a packet of {len} bytes at {at} of {}", stream.len());
        let mut r = Reader { bytes: &stream[at..at + len], at: 4 };
        let packet = match r.byte() {
            4 => {
                assert_eq!(r.byte(), 1, "the image grabs the focus when created");
                let name = r.string();
                let (width, height, n) = (r.i32(), r.i32(), r.i32());
                Packet::Create { name, width, height, channels: r.strings(n) }
            }
            5 => {
                r.byte();
                let name = r.string();
                let n = r.i32();
                let channels = r.strings(n);
                let (x, y, w, h) = (r.i32(), r.i32(), r.i32(), r.i32());
                let count = (n * w * h) as usize;
                let values =
                    r.take(4 * count).chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
                Packet::Update { name, channels, x, y, w, h, values }
            }
            t => panic!("packet type {t}: not one fogplanes sends"),
        };
        assert_eq!(r.at, len, "{packet:?}: the fields fill the packet");
        packets.push(packet);
        at += len;
    }
    packets
}

/// What a viewer holds: the image as the updates left it, and a copy each time every pixel
/// has been updated since the last copy (one frame).
struct Canvas {
    name: String,
    width: usize,
    height: usize,
    channels: Vec<String>,
    values: Vec<Vec<f32>>,
    fresh: Vec<bool>,
    frames: Vec<Vec<Vec<f32>>>,
    /// The rows of each update, in order.
    rows: Vec<(i32, i32)>,
}

impl Canvas {
    /// The viewer's image after `packets`: exactly one CreateImage, first; updates of that
    /// image only, in tiles of at most 128 x 128 inside it.
    fn of(packets: &[Packet]) -> Canvas {
        let Some(Packet::Create { name, width, height, channels }) = packets.first() else {
            panic!("the first packet creates the image: {:?}", packets.first());
        };
        let (width, height) = (*width as usize, *height as usize);
        let mut canvas = Canvas {
            name: name.clone(),
            width,
            height,
            channels: channels.clone(),
            values: vec![vec![f32::NAN; width * height]; channels.len()],
            fresh: vec![false; width * height],
            frames: Vec::new(),
            rows: Vec::new(),
        };
        for p in &packets[1..] {
            let Packet::Update { name, channels, x, y, w, h, values } = p else {
                panic!("the image is created once: {p:?}");
            };
            assert!(*name == canvas.name && *channels == canvas.channels, "{name} {channels:?}");
            let (x, y, w, h) = (*x as usize, *y as usize, *w as usize, *h as usize);
            assert!(w >= 1 && h >= 1 && w <= 128 && h <= 128, "a tile of {w}x{h}");
            assert!(x + w <= width && y + h <= height, "a tile at {x},{y} of {w}x{h}");
            canvas.rows.push((y as i32, (y + h) as i32));
            for (c, channel) in canvas.values.iter_mut().enumerate() {
                for j in 0..h {
                    for i in 0..w {
                        channel[(y + j) * width + x + i] = values[(c * h + j) * w + i];
                        canvas.fresh[(y + j) * width + x + i] = true;
                    }
                }
            }
            if canvas.fresh.iter().all(|&f| f) {
                canvas.frames.push(canvas.values.clone());
                canvas.fresh.fill(false);
            }
        }
        canvas
    }

    /// Channels `first..first + 3` of `values` as a film.
    fn film(&self, values: &[Vec<f32>], first: usize) -> Film {
        let mut film = Film::new(self.width as u32, self.height as u32);
        for (k, p) in film.pixels.iter_mut().enumerate() {
            *p = glam::Vec3::new(values[first][k], values[first + 1][k], values[first + 2][k]);
        }
        film
    }
}

/// A listener on a free port of this machine that takes one connection and returns all it
/// received once the sender closes it.
fn listen() -> (String, std::thread::JoinHandle<Vec<u8>>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap().to_string();
    let received = std::thread::spawn(move || {
        let (mut stream, _) = listener.accept().unwrap();
        let mut bytes = Vec::new();
        stream.read_to_end(&mut bytes).unwrap();
        bytes
    });
    (address, received)
}

/// A render shown in tev: created once at its size and black, then frames each the image of
/// the planes of its first chunks (more chunks each time, as the render goes), and at the end
/// the image the render wrote, bit for bit.
#[test]
fn a_render_shown_in_tev_is_created_once_and_updated_until_its_image() {
    let dir = scratch("tev-render");
    let out = dir.join("out.exr");
    let (address, received) = listen();
    let planes = 4 * CHUNK_PLANES;
    let planes_arg = planes.to_string();
    let run = ["render", SCENE, "--resolution", "150x40", "--planes", &planes_arg, "-q", "--display-server", &address];
    let o = fogplanes(&[&run[..], &["-o", path(&out)]].concat());
    succeeded(&o, "render");
    assert!(o.stderr.is_empty(), "{}", String::from_utf8_lossy(&o.stderr));
    let canvas = Canvas::of(&decode(&received.join().unwrap()));
    assert_eq!((canvas.width, canvas.height, &canvas.channels[..]), (150, 40, &["R", "G", "B"].map(String::from)[..]));
    assert!(canvas.name.contains("six_lights") && canvas.name.contains("smis-exact"), "{}", canvas.name);
    // The running images after each chunk (docs/mathematics.md 8.1), made here.
    let scene = Scene::load(Path::new(SCENE)).unwrap().with_resolution(150, 40).unwrap();
    let opts = options(&scene, Overrides { planes: Some(planes as u64), ..Overrides::default() });
    let running = RunningImage::new(&scene, &opts);
    let mut after_chunks = Vec::new();
    render_from(&scene, &opts, Control::none(), Resume::default(), &mut |held, _| {
        after_chunks.push(running.image(held).unwrap());
        Ok(())
    })
    .unwrap();
    let image = Film::load_exr(&out).unwrap();
    assert!(same_bits(after_chunks.last().unwrap(), &image));
    // Black first; then running images of more and more chunks, the first chunk's at least
    // (frames the viewer could not take in time are skipped); the render's image last.
    let frames: Vec<Film> = canvas.frames.iter().map(|f| canvas.film(f, 0)).collect();
    assert!(frames.len() >= 3, "{} frames", frames.len());
    assert!(frames[0].pixels.iter().all(|p| *p == glam::Vec3::ZERO), "created black");
    let chunks: Vec<usize> = frames[1..]
        .iter()
        .map(|f| after_chunks.iter().position(|r| same_bits(r, f)).expect("a frame is the image after some chunk"))
        .collect();
    assert!(chunks[0] == 0 && chunks.windows(2).all(|w| w[0] <= w[1]) && chunks.last() == Some(&3), "{chunks:?}");
    assert!(!same_bits(&after_chunks[0], &image), "the first chunk's is an image of fewer planes");
    assert!(same_bits(&canvas.film(&canvas.values, 0), &image), "the viewer ends with the render's image");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A reference shown in tev: its mean and, as the layer `stderr`, its standard error, updated
/// band by band down the image, ending with the images it wrote.
#[test]
fn a_reference_shown_in_tev_is_updated_band_by_band_until_its_images() {
    let dir = scratch("tev-reference");
    let (mean, stderr) = (dir.join("mean.exr"), dir.join("stderr.exr"));
    let (address, received) = listen();
    let images = ["-o", path(&mean), "--stderr-image", path(&stderr)];
    let run = ["reference", SCENE, "--resolution", "20x40", "--spp", "1024", "-q", "--display-server", &address];
    let o = fogplanes(&[&run[..], &images].concat());
    succeeded(&o, "reference");
    let canvas = Canvas::of(&decode(&received.join().unwrap()));
    let rgb = ["R", "G", "B"].map(String::from);
    let channels: Vec<String> = rgb.iter().cloned().chain(rgb.iter().map(|c| format!("stderr.{c}"))).collect();
    assert_eq!((canvas.width, canvas.height, &canvas.channels), (20, 40, &channels));
    // Created black at the start (one tile: all 40 rows), then each band of 16 rows as it
    // finishes, unless the band before is still being sent, then the whole image.
    assert_eq!(canvas.rows[0], (0, 40));
    assert!(canvas.rows[1..].iter().any(|&(a, b)| a % 16 == 0 && b - a <= 16), "{:?}", canvas.rows);
    assert!(same_bits(&canvas.film(&canvas.values, 0), &Film::load_exr(&mean).unwrap()));
    assert!(same_bits(&canvas.film(&canvas.values, 3), &Film::load_exr(&stderr).unwrap()));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A render with an error image shows it in tev as the layer `stderr`: created black, then
/// (once two plane groups are closed) the running estimate, non-negative and finite, and at the
/// end the error image written, bit for bit, beside the image.
#[test]
fn a_renders_error_image_is_shown_in_tev_as_a_layer() {
    let dir = scratch("tev-stderr");
    let (out, se) = (dir.join("out.exr"), dir.join("se.exr"));
    let (address, received) = listen();
    let planes = (6 * CHUNK_PLANES).to_string();
    let run = ["render", SCENE, "--resolution", "60x30", "--planes", &planes, "-q", "--display-server", &address];
    let o = fogplanes(&[&run[..], &["-o", path(&out), "--stderr-image", path(&se)]].concat());
    succeeded(&o, "render");
    let canvas = Canvas::of(&decode(&received.join().unwrap()));
    let rgb = ["R", "G", "B"].map(String::from);
    let channels: Vec<String> = rgb.iter().cloned().chain(rgb.iter().map(|c| format!("stderr.{c}"))).collect();
    assert_eq!((canvas.width, canvas.height, &canvas.channels), (60, 30, &channels));
    let frames: Vec<Film> = canvas.frames.iter().map(|f| canvas.film(f, 3)).collect();
    assert!(frames.len() >= 3, "{} frames", frames.len());
    assert!(frames[0].pixels.iter().all(|p| *p == glam::Vec3::ZERO), "created black");
    assert!(frames.iter().all(|f| f.all_finite_non_negative()));
    assert!(frames[1..frames.len() - 1].iter().any(|f| f.max() > 0.0), "no running error image was shown");
    assert!(same_bits(frames.last().unwrap(), &Film::load_exr(&se).unwrap()));
    assert!(same_bits(&canvas.film(&canvas.values, 0), &Film::load_exr(&out).unwrap()));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// No viewer at the address, or one that goes away: one warning line, and the render writes
/// its image as without a viewer.
#[test]
fn an_absent_or_vanishing_viewer_costs_one_warning() {
    let dir = scratch("tev-absent");
    let planes = (4 * CHUNK_PLANES).to_string();
    let render = |out: &Path, server: Option<&str>| {
        let mut args = vec!["render", SCENE, "--resolution", "96x54", "--planes", &planes, "-q", "-o", path(out)];
        args.extend(server.map(|s| ["--display-server", s]).into_iter().flatten());
        fogplanes(&args)
    };
    succeeded(&render(&dir.join("plain.exr"), None), "render");
    let plain = Film::load_exr(&dir.join("plain.exr")).unwrap();
    // A port nothing listens on.
    let closed = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().to_string();
    // A viewer that reads the first bytes, then closes the connection and stops listening.
    let vanishing = TcpListener::bind("127.0.0.1:0").unwrap();
    let gone = vanishing.local_addr().unwrap().to_string();
    let viewer = std::thread::spawn(move || {
        let (mut stream, _) = vanishing.accept().unwrap();
        let mut first = [0u8; 64];
        stream.read_exact(&mut first).unwrap();
    });
    for (address, warning) in [(closed, "no viewer at"), (gone, "is lost")] {
        let out = dir.join("out.exr");
        let o = render(&out, Some(&address));
        succeeded(&o, &address);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.starts_with("warning: ") && err.contains(warning) && err.contains(&address), "{err}");
        assert!(same_bits(&Film::load_exr(&out).unwrap(), &plain));
    }
    viewer.join().unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

// -------------------------------------------------------------------------------------------
// Checkpoints

/// The plane or row counts each run said it resumed from ("resuming from CK: K of N ...").
fn resumed_from(stdout: &str) -> Option<u64> {
    let line = stdout.lines().find(|l| l.starts_with("resuming from"))?;
    line.split(": ").nth(1)?.split(' ').next()?.parse().ok()
}

/// Runs `args` and SIGKILLs it a random moment after `ready` appears in `ck` (or lets it end);
/// returns what it printed.
fn kill_at_random(args: &[&str], ck: &Path, ready: &str, rng: &mut impl Rng, within: Duration) -> String {
    let mut child = Command::new(env!("CARGO_BIN_EXE_fogplanes"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    let has_ready =
        || std::fs::read_dir(ck).is_ok_and(|d| d.flatten().any(|e| e.file_name().to_string_lossy().starts_with(ready)));
    while !has_ready() && child.try_wait().unwrap().is_none() && start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(2));
    }
    // Within a fraction of an uninterrupted run's time, so that the kill lands mid-job on a
    // fast machine as on a slow one.
    let most = within.as_millis().clamp(2, 400) as u64;
    std::thread::sleep(Duration::from_millis(rng.random_range(0..most)));
    let _ = child.kill();
    let o = child.wait_with_output().unwrap();
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A render SIGKILLed at random moments (after its first saved chunk, seeded) and run again
/// each time resumes from its checkpoint; finished, it is the uninterrupted render bit for bit.
#[test]
fn a_render_killed_at_random_moments_resumes_to_the_uninterrupted_bits() {
    killed_render_resumes(false, 28);
}

/// The same with an error image: the checkpoint keeps the spread of the plane groups beside
/// the nodes, and the error image resumed is the uninterrupted one bit for bit. A checkpoint
/// made without an error image cannot resume one (one line, exit code 2).
#[test]
fn a_render_with_an_error_image_killed_at_random_moments_resumes_to_the_uninterrupted_bits() {
    killed_render_resumes(true, 29);
}

fn killed_render_resumes(stderr: bool, seed: u64) {
    let dir = scratch(if stderr { "kill-render-se" } else { "kill-render" });
    let ck = dir.join("ck");
    let planes = 16 * CHUNK_PLANES;
    let planes_arg = planes.to_string();
    let se = |out: &Path| out.with_extension("se.exr");
    let args = |out: &Path, ck: Option<&Path>| -> Vec<String> {
        let mut v: Vec<String> =
            ["render", SCENE, "--resolution", "64x36", "--planes", &planes_arg, "-q", "-o"].map(String::from).into();
        v.push(path(out).into());
        if stderr {
            v.extend(["--stderr-image".to_string(), path(&se(out)).into()]);
        }
        v.extend(ck.map(|c| ["--checkpoint".to_string(), path(c).into()]).into_iter().flatten());
        v
    };
    let same_files = |a: &Path, b: &Path| same_bits(&Film::load_exr(a).unwrap(), &Film::load_exr(b).unwrap());
    let whole = dir.join("whole.exr");
    let t = Instant::now();
    succeeded(&fogplanes(&strs(&args(&whole, None))), "the uninterrupted render");
    let within = t.elapsed() / 4;
    let out = dir.join("out.exr");
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut resumed = Vec::new();
    for _ in 0..3 {
        let stdout = kill_at_random(&strs(&args(&out, Some(&ck))), &ck, "planes_", &mut rng, within);
        resumed.extend(resumed_from(&stdout));
    }
    let stdout = succeeded(&fogplanes(&strs(&args(&out, Some(&ck)))), "the last run");
    resumed.extend(resumed_from(&stdout));
    assert!(resumed.iter().any(|&k| k > 0 && k < planes as u64), "never resumed mid-render: {resumed:?}");
    assert!(same_files(&out, &whole));
    if stderr {
        assert!(same_files(&se(&out), &se(&whole)), "the error image resumed differs");
    }
    // The image records the render's planes, those the checkpoint held included (it recorded
    // the last run's alone).
    let recorded = |p: &Path| {
        let (info, _) = fogplanes::film::read_image_info(p).unwrap();
        info.unwrap().get("planes").map(str::to_string)
    };
    assert_eq!(recorded(&out), Some(planes_arg.clone()));
    // A finished checkpoint holds one part of all the planes (and their spread), and a run
    // again just writes the image.
    let mut names: Vec<String> =
        std::fs::read_dir(&ck).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.retain(|n| !n.starts_with('.'));
    names.sort();
    let mut expected = vec![format!("planes_0-{planes}.npz")];
    if stderr {
        expected.push(format!("spread_{planes}.groups"));
    }
    assert_eq!(names, expected);
    let again = dir.join("again.exr");
    let stdout = succeeded(&fogplanes(&strs(&args(&again, Some(&ck)))), "a run of a finished checkpoint");
    assert_eq!(resumed_from(&stdout), Some(planes as u64));
    assert!(same_files(&again, &out));
    assert_eq!(recorded(&again), Some(planes_arg.clone()));
    if stderr {
        assert!(same_files(&se(&again), &se(&out)));
        // A spread file that is not one is refused like any part, naming it.
        let spread = ck.join(format!("spread_{planes}.groups"));
        std::fs::write(&spread, b"not an archive").unwrap();
        let e = refused(&strs(&args(&again, Some(&ck))));
        assert!(e.contains(&format!("spread_{planes}.groups")), "{e}");
    } else {
        let mut with_se = args(&again, Some(&ck));
        with_se.extend(["--stderr-image".to_string(), path(&dir.join("x.exr")).into()]);
        let e = refused(&strs(&with_se));
        assert!(e.contains("not the spread of their plane groups"), "{e}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// With an error image, every time the render tells what it holds (after which a checkpoint
/// saves the nodes and the spread of their plane groups, each file whole), the spread is that
/// of the nodes' planes, and a render resumed from any of those states gives the render and its
/// error image bit for bit. A small image gathers several chunks at once (a window: 64 x 36
/// pixels are 3 bands of rows, so at least 2 chunks for one worker), whose gathering adds all
/// their groups to the spread: told after each chunk, the spread was a window ahead of the
/// nodes, so that a kill between two chunks' files left a spread the resume refused ("its
/// counts (147456 planes in 9 groups) are not those of 131072 planes"; the killed render's
/// test above failed so about one run in five).
#[test]
fn the_spread_told_with_the_nodes_is_theirs_and_resumes_to_the_bits() {
    let scene = Scene::load(Path::new(SCENE)).unwrap().with_resolution(64, 36).unwrap();
    let planes = 8 * CHUNK_PLANES;
    let opts = options(&scene, Overrides { planes: Some(planes as u64), stderr: true, ..Overrides::default() });
    let pixels = 64 * 36;
    let mut told = Vec::new();
    let (whole, stats) = render_from(&scene, &opts, Control::none(), Resume::default(), &mut |held, spread| {
        let done = held.last().map_or(0, |p| p.end);
        let spread = spread.expect("an error image's spread");
        if let Err(why) = spread.check(pixels, opts.ray_sets(), done) {
            panic!("told after {done} planes, a spread that is not theirs: {why}");
        }
        told.push((held.to_vec(), spread.clone()));
        Ok(())
    })
    .unwrap();
    let ends: Vec<usize> = told.iter().map(|(held, _)| held.last().unwrap().end).collect();
    assert_eq!(ends.last(), Some(&planes), "{ends:?}");
    let error = stats.stderr.unwrap();
    // Resumed from the first state told and from one in the middle.
    for k in [0, told.len() / 2] {
        let (held, spread) = told[k].clone();
        let (resumed, resumed_stats) =
            render_from(&scene, &opts, Control::none(), Resume { held, spread: Some(spread) }, &mut |_, _| Ok(()))
                .unwrap();
        assert!(same_bits(&resumed, &whole), "resumed after {} planes: the image differs", ends[k]);
        assert!(same_bits(&resumed_stats.stderr.unwrap(), &error), "resumed after {} planes: the error image", ends[k]);
    }
}

/// A kill between the files of one save: with an error image a window of chunks saves its
/// spread, then a file for each node it completed, so that a kill between two node files leaves
/// the nodes of a chunk inside the window, which has no spread, beside the window before's
/// nodes and spread. The next opening resumes from those (it took the newer nodes, deleted the
/// others, and refused: "holds 131072 planes of this render but not the spread"), and the
/// render ends with the uninterrupted bits and error image. Made here in the library: a
/// checkpoint saved as the command line saves it, and copied at each save as a kill after the
/// save's first node file would leave it; the tiles cut as for 2 workers, so that a window is
/// 3 chunks (64 x 36 pixels are 3 bands of rows) and its save writes two node files (the image
/// is the same bits however its work is cut, so other tests are not moved).
#[test]
fn a_kill_between_a_windows_files_resumes_from_the_window_before() {
    use fogplanes::partial::checkpoint::Checkpoint;
    let dir = scratch("kill-window");
    let (ck_dir, killed) = (dir.join("ck"), dir.join("killed"));
    let scene = Scene::load(Path::new(SCENE)).unwrap().with_resolution(64, 36).unwrap();
    let opts =
        options(&scene, Overrides { planes: Some(9 * CHUNK_PLANES as u64), stderr: true, ..Overrides::default() });
    let files = |d: &Path| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| !n.starts_with('.'))
            .collect();
        v.sort();
        v
    };
    fogplanes::schedule::cut_for(Some(2));
    let (mut ck, held) = Checkpoint::render(&ck_dir, &scene, &opts).unwrap();
    assert!(held.is_empty());
    // The kills made: the nodes' end the state before each save held.
    let mut made = Vec::new();
    let rendered = render_from(&scene, &opts, Control::none(), Resume::default(), &mut |held, spread| {
        let done = held.last().map_or(0, |p| p.end);
        let before = files(&ck_dir);
        // The files before the save, which it may remove.
        let pre = dir.join("pre");
        let _ = std::fs::remove_dir_all(&pre);
        std::fs::create_dir_all(&pre).unwrap();
        for name in &before {
            std::fs::copy(ck_dir.join(name), pre.join(name)).unwrap();
        }
        ck.save_spread(&scene, &opts, done, spread.unwrap())?;
        ck.save_render(&scene, &opts, held)?;
        // The node files this save wrote, in the order it wrote them (held's).
        let new: Vec<String> =
            held.iter().map(|p| format!("planes_{}-{}.npz", p.start, p.end)).filter(|n| !before.contains(n)).collect();
        if new.len() >= 2 && !before.is_empty() && made.is_empty() {
            let _ = std::fs::remove_dir_all(&killed);
            std::fs::create_dir_all(&killed).unwrap();
            let spread = format!("spread_{done}.groups");
            for name in &before {
                std::fs::copy(pre.join(name), killed.join(name)).unwrap();
            }
            for name in [&spread, &new[0]] {
                std::fs::copy(ck_dir.join(name), killed.join(name)).unwrap();
            }
            made.push(before.iter().filter_map(|n| n.strip_prefix("spread_")).map(String::from).collect::<Vec<_>>());
        }
        ck.keep_spread(done)?;
        Ok(())
    });
    fogplanes::schedule::cut_for(None);
    let (whole, stats) = rendered.unwrap();
    assert!(!made.is_empty(), "no save wrote two node files: the windows were not of 3 chunks");
    drop(ck);
    // The kill's checkpoint opened: the state before the window, its spread's, resumed.
    let (ck, held) = Checkpoint::render(&killed, &scene, &opts).unwrap();
    let resume = ck.resume(&scene, &opts, held).unwrap();
    let done = resume.held.last().map_or(0, |p| p.end);
    assert!(done > 0 && made[0] == [format!("{done}.groups")], "resumed after {done} planes: {made:?}");
    let (resumed, resumed_stats) = render_from(&scene, &opts, Control::none(), resume, &mut |_, _| Ok(())).unwrap();
    assert!(same_bits(&resumed, &whole), "the image resumed differs");
    assert!(same_bits(&resumed_stats.stderr.unwrap(), &stats.stderr.unwrap()), "the error image resumed differs");
    drop(ck);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The same for an adaptive reference: killed after its pilot pass, resumed, its mean and
/// standard error are the uninterrupted run's.
#[test]
fn a_reference_killed_at_random_moments_resumes_to_the_uninterrupted_bits() {
    let dir = scratch("kill-reference");
    let ck = dir.join("ck");
    let args = |name: &str, ck: Option<&Path>| -> Vec<String> {
        let (mean, err) = (dir.join(format!("{name}.exr")), dir.join(format!("{name}_err.exr")));
        let mut v: Vec<String> =
            ["reference", SCENE, "--resolution", "48x48", "--spp", "512", "-q"].map(String::from).into();
        v.extend(["-o".into(), path(&mean).into(), "--stderr-image".into(), path(&err).into()]);
        v.extend(ck.map(|c| ["--checkpoint".to_string(), path(c).into()]).into_iter().flatten());
        v
    };
    let t = Instant::now();
    succeeded(&fogplanes(&strs(&args("whole", None))), "the uninterrupted reference");
    let within = t.elapsed() / 4;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(28);
    let mut said = Vec::new();
    for _ in 0..2 {
        said.push(kill_at_random(&strs(&args("out", Some(&ck))), &ck, "pilot", &mut rng, within));
    }
    said.push(succeeded(&fogplanes(&strs(&args("out", Some(&ck)))), "the last run"));
    let resumed: Vec<&str> = said.iter().flat_map(|s| s.lines()).filter(|l| l.starts_with("resuming from")).collect();
    assert!(
        resumed.iter().any(|l| l.contains(": the pilot pass and ") && !l.contains(" 48 of 48 rows")),
        "{resumed:?}"
    );
    let load = |name: &str| Film::load_exr(&dir.join(name)).unwrap();
    assert!(same_bits(&load("out.exr"), &load("whole.exr")) && same_bits(&load("out_err.exr"), &load("whole_err.exr")));
    // The finished checkpoint holds the pilot pass beside the bands: `merge CK/*.npz` says to
    // leave it out, and the bands alone merge to the image.
    let mut npz: Vec<PathBuf> = std::fs::read_dir(&ck)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "npz"))
        .collect();
    npz.sort();
    let merged = dir.join("merged.exr");
    let merge = |parts: &[PathBuf]| {
        let mut v = vec!["merge", "-o", path(&merged)];
        v.extend(parts.iter().map(|p| path(p)));
        v.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let e = refused(&strs(&merge(&npz)));
    assert!(e.contains("pilot.npz is a reference's pilot pass") && e.contains("CK/rows_*.npz"), "{e}");
    let bands: Vec<PathBuf> =
        npz.into_iter().filter(|p| p.file_name().unwrap().to_string_lossy().starts_with("rows_")).collect();
    assert!(bands.len() >= 2, "{bands:?}");
    succeeded(&fogplanes(&strs(&merge(&bands))), "the bands merged");
    assert!(same_bits(&load("merged.exr"), &load("whole.exr")));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A checkpoint of another scene, of other settings, or a place that is no checkpoint, is
/// refused with one line before any work; so is one in use; Ctrl-C says what it holds.
#[test]
fn another_jobs_checkpoint_is_refused_and_ctrl_c_says_what_it_holds() {
    let dir = scratch("refused");
    let ck = dir.join("ck");
    let (x, r) = (dir.join("x.exr"), dir.join("r.exr"));
    let render = |scene: &str, extra: &[&str]| -> Vec<String> {
        let mut v = vec!["render", scene, "--resolution", "32x18", "--planes", "40000", "-q", "-o", path(&x)];
        v.extend(["--checkpoint", path(&ck)]);
        v.extend(extra);
        v.into_iter().map(String::from).collect()
    };
    succeeded(&fogplanes(&strs(&render(SCENE, &[]))), "the first render");
    let other_scene = refused(&strs(&render("media_scenes/two_lights_one_blocker.toml", &[])));
    let other_seed = refused(&strs(&render(SCENE, &["--seed", "7"])));
    for e in [&other_scene, &other_seed] {
        assert!(e.contains("holds the work of another render or reference"), "{e}");
    }
    let reference = ["reference", SCENE, "--resolution", "32x18", "--spp", "16", "-q", "-o", path(&r)];
    assert!(refused(&[&reference[..], &["--checkpoint", path(&ck)]].concat()).contains("another render or reference"));
    std::fs::write(ck.join("notes.txt"), "mine").unwrap();
    assert!(
        refused(&strs(&render(SCENE, &[]))).contains("holds notes.txt, which is not a file of a fogplanes checkpoint")
    );
    std::fs::write(dir.join("file"), "").unwrap();
    let file = dir.join("file");
    let v = ["render", SCENE, "-q", "-o", path(&x), "--checkpoint", path(&file)];
    assert!(refused(&v).contains("is not a directory"));
    // In use: a long render holds it; Ctrl-C then tells what it holds.
    let (busy, y) = (dir.join("busy"), dir.join("y.exr"));
    let long = ["render", SCENE, "--resolution", "96x54", "--planes", "2000000", "-q", "-o", path(&y)];
    let child = Command::new(env!("CARGO_BIN_EXE_fogplanes"))
        .args(long)
        .args(["--checkpoint", path(&busy)])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while !std::fs::read_dir(&busy)
        .is_ok_and(|d| d.flatten().any(|e| e.file_name().to_string_lossy().starts_with("planes_")))
    {
        assert!(start.elapsed() < Duration::from_secs(60), "no chunk saved");
        std::thread::sleep(Duration::from_millis(5));
    }
    let e = refused(&[&long[..], &["--checkpoint", path(&busy)]].concat());
    assert!(e.contains("is in use by another fogplanes process"), "{e}");
    assert!(Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap().success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{err}");
    let note = err.lines().find(|l| l.starts_with("interrupted: ")).unwrap_or_else(|| panic!("{err}"));
    let k: u64 = note.split(" holds ").nth(1).and_then(|r| r.split(' ').next()).and_then(|k| k.parse().ok()).unwrap();
    assert!(k > 0 && k.is_multiple_of(CHUNK_PLANES as u64), "{note}");
    let expected = format!(
        "interrupted: the checkpoint {} holds {k} of 2000000 planes; run the same command to resume",
        busy.display()
    );
    assert_eq!(note, expected);
    // What it says is what the files hold: their last plane.
    let last = std::fs::read_dir(&busy)
        .unwrap()
        .filter_map(|e| {
            e.unwrap()
                .file_name()
                .to_string_lossy()
                .strip_prefix("planes_")?
                .strip_suffix(".npz")?
                .split('-')
                .nth(1)?
                .parse::<u64>()
                .ok()
        })
        .max();
    assert_eq!(last, Some(k));
    std::fs::remove_dir_all(&dir).unwrap();
}
