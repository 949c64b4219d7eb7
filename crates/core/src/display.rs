//! A live view in tev (Thomas Müller's image viewer, <https://github.com/Tom94/tev>): the image a
//! long job is making, sent as it improves over the TCP protocol tev listens on (by default at
//! 127.0.0.1:14158), as pbrt-v4's `--display-server` does.
//!
//! The protocol: a packet is its length in bytes (`u32`, these four bytes included), a type
//! byte and its fields, numbers little-endian, a bool one byte, a string its UTF-8 bytes and a
//! NUL. Two packets are used:
//!
//! | type | fields |
//! |---|---|
//! | 4, CreateImage | grab focus, name, width, height (`i32`), channel count (`i32`), the channel names |
//! | 5, UpdateImageV2 | grab focus, name, channel count (`i32`), the channel names, x, y, width, height of a tile (`i32`), then the tile's `f32` values, one channel after another, rows top down |
//!
//! tev replaces an image of the same name on CreateImage, so a job run again (or resumed)
//! shows in the same place. A layer's channels are `R`, `G`, `B`, prefixed by `layer.` for a
//! named one (tev shows `stderr.R`, ... as the layer `stderr`).
//!
//! The view sends from a thread of its own: the job hands over a frame and goes on, a frame
//! not sent yet is replaced by a newer one (only the latest matters), and each write has a
//! time limit, so a slow, absent or vanished viewer never holds the job up. A viewer that
//! cannot be reached, or is lost, costs one warning in the view's life (through the caller's
//! `warn`); the view tries again with each later frame, silently, and creates the image anew
//! once connected.

use crate::film::Film;
use std::io::Write;
use std::net::{TcpStream, ToSocketAddrs};
use std::ops::Range;
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// The largest side of a tile sent in one packet: a tile of two RGB layers is 384 KiB, well
/// inside tev's receive buffer.
pub const TILE: u32 = 128;

/// How long a connection may take to open, and one write to go through.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(2);
const WRITE_TIMEOUT: Duration = Duration::from_secs(5);

/// tev's packet types used here.
const CREATE_IMAGE: u8 = 4;
const UPDATE_IMAGE_V2: u8 = 5;

/// Checks a display server's address, `HOST:PORT` (a name or an IP address, an IPv6 one in
/// brackets), without resolving it.
pub fn check_address(address: &str) -> std::result::Result<(), String> {
    let bad = || format!("expected HOST:PORT (tev listens on 127.0.0.1:14158 by default), got {address:?}");
    let (host, port) = address.rsplit_once(':').ok_or_else(bad)?;
    if host.is_empty() || host.contains(char::is_whitespace) || port.parse::<u16>().is_err() {
        return Err(bad());
    }
    Ok(())
}

/// What a view shows: one image of `width x height` pixels named `name`, with one RGB layer per
/// entry of `layers` (`""` for the image itself, else the layer's name).
#[derive(Clone, Debug)]
pub struct ViewSpec {
    pub address: String,
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub layers: Vec<String>,
}

impl ViewSpec {
    fn channels(&self) -> Vec<String> {
        let rgb = ["R", "G", "B"];
        self.layers
            .iter()
            .flat_map(|l| rgb.iter().map(move |c| if l.is_empty() { c.to_string() } else { format!("{l}.{c}") }))
            .collect()
    }
}

/// A frame waiting to be sent: one film per layer and the rows that changed since the last.
struct Frame {
    layers: Vec<Film>,
    rows: Range<u32>,
}

#[derive(Default)]
struct Slot {
    frame: Option<Frame>,
    closing: bool,
}

struct Shared {
    slot: Mutex<Slot>,
    wake: Condvar,
}

impl Shared {
    fn slot(&self) -> std::sync::MutexGuard<'_, Slot> {
        self.slot.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A live view in tev, sending from its own thread (module docs).
pub struct LiveView {
    shared: Arc<Shared>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl LiveView {
    /// Starts the view's thread; nothing is sent before the first frame. `warn` gets one line
    /// the first time the viewer cannot be reached or is lost.
    pub fn start(spec: ViewSpec, warn: Arc<dyn Fn(&str) + Send + Sync>) -> LiveView {
        let shared = Arc::new(Shared { slot: Mutex::new(Slot::default()), wake: Condvar::new() });
        let (theirs, their_warn) = (Arc::clone(&shared), Arc::clone(&warn));
        let thread = std::thread::Builder::new()
            .name("fogplanes-live-view".into())
            .spawn(move || Sender { spec, warn: their_warn, stream: None, warned: false }.run(&theirs))
            .ok();
        if thread.is_none() {
            warn("the live view cannot start a thread; the job goes on without it");
        }
        LiveView { shared, thread }
    }

    /// Whether no frame is waiting: a job asks before making a frame, so as to make none that
    /// would only be replaced.
    pub fn ready(&self) -> bool {
        self.shared.slot().frame.is_none()
    }

    /// Hands over a frame: one film per layer of the spec, of which rows `rows` changed since
    /// the frame before. Replaces a frame still waiting (their changed rows joined).
    pub fn show(&self, layers: Vec<Film>, rows: Range<u32>) {
        let mut slot = self.shared.slot();
        let rows = match &slot.frame {
            Some(f) => f.rows.start.min(rows.start)..f.rows.end.max(rows.end),
            None => rows,
        };
        slot.frame = Some(Frame { layers, rows });
        self.shared.wake.notify_one();
    }

    /// Sends the frame waiting, if any, and ends the view's thread.
    pub fn finish(mut self) {
        self.close(false);
    }

    fn close(&mut self, discard: bool) {
        {
            let mut slot = self.shared.slot();
            slot.closing = true;
            if discard {
                slot.frame = None;
            }
            self.shared.wake.notify_one();
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for LiveView {
    /// A view dropped without [`LiveView::finish`] (a job that failed) sends nothing more.
    fn drop(&mut self) {
        self.close(true);
    }
}

/// The view's thread: its connection, and whether it has warned (once in a view's life: a
/// viewer that accepts connections but never reads would otherwise cost a line per frame).
struct Sender {
    spec: ViewSpec,
    warn: Arc<dyn Fn(&str) + Send + Sync>,
    stream: Option<TcpStream>,
    warned: bool,
}

impl Sender {
    fn run(mut self, shared: &Shared) {
        loop {
            let frame = {
                let mut slot = shared.slot();
                while slot.frame.is_none() && !slot.closing {
                    slot = shared.wake.wait(slot).unwrap_or_else(|e| e.into_inner());
                }
                match slot.frame.take() {
                    Some(f) => f,
                    None => return,
                }
            };
            self.send(frame);
        }
    }

    /// Sends a frame, connecting (and creating the image) first if need be; on failure, warns
    /// once and drops the connection (the next frame tries again).
    fn send(&mut self, frame: Frame) {
        let rows = if self.stream.is_some() { frame.rows.clone() } else { 0..self.spec.height };
        if self.stream.is_none() {
            match self.connect() {
                Ok(stream) => self.stream = Some(stream),
                Err(e) => {
                    self.warn_once(&format!("no viewer at {} ({e}); the job goes on without it", self.spec.address));
                    return;
                }
            }
        }
        let stream = self.stream.as_mut().expect("connected above");
        if let Err(e) = write_frame(stream, &self.spec, &frame.layers, rows) {
            self.stream = None;
            self.warn_once(&format!("the viewer at {} is lost ({e}); the job goes on without it", self.spec.address));
        }
    }

    fn warn_once(&mut self, message: &str) {
        if !self.warned {
            (self.warn)(message);
            self.warned = true;
        }
    }

    /// Connects to the viewer and creates the image there.
    fn connect(&self) -> std::io::Result<TcpStream> {
        let mut last = std::io::Error::new(std::io::ErrorKind::NotFound, "the host name has no address");
        for addr in self.spec.address.to_socket_addrs()? {
            match TcpStream::connect_timeout(&addr, CONNECT_TIMEOUT) {
                Ok(mut stream) => {
                    stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
                    stream.set_nodelay(true)?;
                    let s = &self.spec;
                    stream.write_all(&create_image(&s.name, s.width, s.height, &s.channels()))?;
                    return Ok(stream);
                }
                Err(e) => last = e,
            }
        }
        Err(last)
    }
}

/// Sends rows `rows` of `layers` as tiles of at most [`TILE`] x [`TILE`] pixels.
fn write_frame(stream: &mut TcpStream, spec: &ViewSpec, layers: &[Film], rows: Range<u32>) -> std::io::Result<()> {
    let channels = spec.channels();
    for y in rows.clone().step_by(TILE as usize) {
        let h = TILE.min(rows.end - y);
        for x in (0..spec.width).step_by(TILE as usize) {
            let w = TILE.min(spec.width - x);
            stream.write_all(&update_image(&spec.name, &channels, (x, y, w, h), layers))?;
        }
    }
    stream.flush()
}

/// The packet's bytes with its length in front.
fn packet(kind: u8, body: impl FnOnce(&mut Vec<u8>)) -> Vec<u8> {
    let mut bytes = vec![0, 0, 0, 0, kind];
    body(&mut bytes);
    let len = bytes.len() as u32;
    bytes[..4].copy_from_slice(&len.to_le_bytes());
    bytes
}

fn put_str(bytes: &mut Vec<u8>, s: &str) {
    // A NUL ends the string: one inside would cut it short.
    bytes.extend(s.bytes().filter(|&b| b != 0));
    bytes.push(0);
}

fn put_i32(bytes: &mut Vec<u8>, v: u32) {
    bytes.extend((v as i32).to_le_bytes());
}

/// A CreateImage packet.
fn create_image(name: &str, width: u32, height: u32, channels: &[String]) -> Vec<u8> {
    packet(CREATE_IMAGE, |b| {
        b.push(1); // grab focus: show it
        put_str(b, name);
        put_i32(b, width);
        put_i32(b, height);
        put_i32(b, channels.len() as u32);
        for c in channels {
            put_str(b, c);
        }
    })
}

/// An UpdateImageV2 packet of the tile `(x, y, w, h)` of `layers` (three channels each).
fn update_image(name: &str, channels: &[String], (x, y, w, h): (u32, u32, u32, u32), layers: &[Film]) -> Vec<u8> {
    packet(UPDATE_IMAGE_V2, |b| {
        b.push(0); // grab focus: leave the viewer's choice alone
        put_str(b, name);
        put_i32(b, channels.len() as u32);
        for c in channels {
            put_str(b, c);
        }
        for v in [x, y, w, h] {
            put_i32(b, v);
        }
        b.reserve(channels.len() * (w * h) as usize * 4);
        for film in layers {
            for c in 0..3 {
                for j in y..y + h {
                    let row = (j * film.width) as usize;
                    for p in &film.pixels[row + x as usize..row + (x + w) as usize] {
                        b.extend(p[c].to_le_bytes());
                    }
                }
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn addresses_are_host_and_port() {
        for good in ["127.0.0.1:14158", "localhost:1", "[::1]:14158", "tev.example.org:65535"] {
            assert!(check_address(good).is_ok(), "{good}");
        }
        for bad in ["", "14158", ":14158", "localhost:", "localhost:65536", "host:port", "a b:1"] {
            let e = check_address(bad).unwrap_err();
            assert!(e.contains("HOST:PORT"), "{bad}: {e}");
        }
    }

    /// The bytes of tev's packets, field by field as tev reads them.
    #[test]
    fn packets_are_laid_out_as_tev_reads_them() {
        let create = create_image("fog", 300, 2, &["R".into(), "stderr.G".into()]);
        let mut expected = Vec::new();
        expected.extend((create.len() as u32).to_le_bytes());
        expected.extend([4, 1]);
        expected.extend(b"fog\0");
        for v in [300i32, 2, 2] {
            expected.extend(v.to_le_bytes());
        }
        expected.extend(b"R\0stderr.G\0");
        assert_eq!(create, expected);

        let mut film = Film::new(3, 2);
        for (i, p) in film.pixels.iter_mut().enumerate() {
            *p = Vec3::new(i as f32, 10.0 + i as f32, 20.0 + i as f32);
        }
        let channels: Vec<String> = ["R", "G", "B"].map(String::from).into();
        let update = update_image("fog", &channels, (1, 0, 2, 2), std::slice::from_ref(&film));
        let header = 4 + 1 + 1 + 4 + 4 + 6 + 16;
        assert_eq!(update.len(), header + 3 * 4 * 4);
        assert_eq!(u32::from_le_bytes(update[..4].try_into().unwrap()) as usize, update.len());
        assert_eq!(update[4..6], [5, 0]);
        let values: Vec<f32> =
            update[header..].chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
        // Pixels 1, 2, 4, 5 (x 1..3 of both rows): R of each, then G, then B.
        assert_eq!(values, [1.0, 2.0, 4.0, 5.0, 11.0, 12.0, 14.0, 15.0, 21.0, 22.0, 24.0, 25.0]);
    }

    /// Nobody listening: one warning, and the frames are dropped without holding anyone up.
    #[test]
    fn an_absent_viewer_costs_one_warning() {
        // A port nothing listens on: bound, then closed.
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let warnings = Arc::new(Mutex::new(Vec::<String>::new()));
        let log = Arc::clone(&warnings);
        let spec = ViewSpec {
            address: format!("127.0.0.1:{port}"),
            name: "test".into(),
            width: 4,
            height: 3,
            layers: vec![String::new()],
        };
        let view = LiveView::start(spec, Arc::new(move |m: &str| log.lock().unwrap().push(m.to_string())));
        for _ in 0..3 {
            view.show(vec![Film::new(4, 3)], 0..3);
            while !view.ready() {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
        view.finish();
        let warnings = warnings.lock().unwrap();
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(warnings[0].contains("no viewer at 127.0.0.1:"), "{warnings:?}");
    }
}
