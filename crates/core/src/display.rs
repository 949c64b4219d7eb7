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
//! time limit, so a slow, absent or vanished viewer never holds the job up. At the job's end the
//! last frame is given [`LINGER`] to go through; a viewer that has not taken it by then (one that
//! accepts the connection and never reads) is cut off, and the job ends without it. A viewer
//! that cannot be reached, is lost, or is cut off costs one warning in the view's life (through
//! the caller's `warn`); the view tries again with each later frame, silently, and creates the
//! image anew once connected.

use crate::film::Film;
use std::io::Write;
use std::net::{IpAddr, Shutdown, TcpStream, ToSocketAddrs};
use std::ops::Range;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// The largest side of a tile sent in one packet: a tile of two RGB layers is 384 KiB, well
/// inside tev's receive buffer.
pub const TILE: u32 = 128;

/// How long a connection may take to open, and one write to go through.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(2);
const WRITE_TIMEOUT: Duration = Duration::from_secs(5);

/// The longest a job's end waits for its last frame to reach the viewer.
pub const LINGER: Duration = Duration::from_secs(1);

/// tev's packet types used here.
const CREATE_IMAGE: u8 = 4;
const UPDATE_IMAGE_V2: u8 = 5;

/// Checks a display server's address, `HOST:PORT`, without resolving it: HOST a name (letters,
/// digits, `-` and `.`), an IPv4 address or an IPv6 one in brackets, not one that no viewer can
/// listen on (unspecified, broadcast, multicast); PORT 1 to 65535.
pub fn check_address(address: &str) -> std::result::Result<(), String> {
    let bad =
        |why: &str| format!("{why} in {address:?}: expected HOST:PORT (tev listens on 127.0.0.1:14158 by default)");
    let (host, port) = address.rsplit_once(':').ok_or_else(|| bad("no port"))?;
    match port.parse::<u16>() {
        Ok(0) => return Err(bad("port 0 (any free port) is not a viewer's")),
        Ok(_) => {}
        Err(_) => return Err(bad(&format!("the port {port:?} is not a number from 1 to 65535"))),
    }
    let ip = if let Some(inner) = host.strip_prefix('[').and_then(|h| h.strip_suffix(']')) {
        Some(inner.parse::<std::net::Ipv6Addr>().map_err(|_| bad(&format!("{host:?} is not an IPv6 address")))?.into())
    } else if host.contains(':') {
        return Err(bad(&format!("the host {host:?} holds a ':' (an IPv6 address goes in brackets)")));
    } else if !host.is_empty() && host.bytes().all(|b| b.is_ascii_digit() || b == b'.') {
        Some(IpAddr::V4(host.parse().map_err(|_| bad(&format!("{host:?} is not an IPv4 address")))?))
    } else {
        let label_ok = |l: &str| {
            !l.is_empty()
                && !l.starts_with('-')
                && !l.ends_with('-')
                && l.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-')
        };
        if host.len() > 253 || !host.trim_end_matches('.').split('.').all(label_ok) {
            return Err(bad(&format!("{host:?} is not a host name")));
        }
        None
    };
    let unusable = |ip: IpAddr| match ip {
        IpAddr::V4(v4) => v4.is_unspecified() || v4.is_broadcast() || v4.is_multicast(),
        IpAddr::V6(v6) => v6.is_unspecified() || v6.is_multicast(),
    };
    if let Some(ip) = ip.filter(|&ip| unusable(ip)) {
        return Err(bad(&format!("{ip} is no viewer's address (unspecified, broadcast or multicast)")));
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
    /// The sender's thread has returned.
    done: bool,
    /// The job's end cut the viewer off: the sender's failed write is not a lost viewer.
    cut_off: bool,
    /// Whether a warning was given (one in a view's life).
    warned: bool,
    /// Frames handed over, and frames the viewer took whole.
    shown: u64,
    sent: u64,
    /// A second handle on the sender's connection, so that the job's end can cut it off while
    /// the sender is blocked writing to a viewer that does not read.
    stream: Option<TcpStream>,
}

struct Shared {
    slot: Mutex<Slot>,
    /// Wakes the sender (a frame, or closing) and the closer (the sender is done).
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
    address: String,
    warn: Arc<dyn Fn(&str) + Send + Sync>,
}

impl LiveView {
    /// Starts the view's thread; nothing is sent before the first frame. `warn` gets one line
    /// the first time the viewer cannot be reached or is lost.
    pub fn start(spec: ViewSpec, warn: Arc<dyn Fn(&str) + Send + Sync>) -> LiveView {
        let shared = Arc::new(Shared { slot: Mutex::new(Slot::default()), wake: Condvar::new() });
        let (theirs, their_warn) = (Arc::clone(&shared), Arc::clone(&warn));
        let address = spec.address.clone();
        let thread = std::thread::Builder::new()
            .name("fogplanes-live-view".into())
            .spawn(move || {
                Sender { spec, warn: their_warn, stream: None }.run(&theirs);
                theirs.slot().done = true;
                theirs.wake.notify_all();
            })
            .ok();
        if thread.is_none() {
            warn("the live view cannot start a thread; the job goes on without it");
        }
        LiveView { shared, thread, address, warn }
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
        slot.shown += 1;
        self.shared.wake.notify_all();
    }

    /// Sends the frame waiting, if any, within [`LINGER`], and ends the view's thread. A viewer
    /// that has not taken it by then is cut off, with one warning that frames were dropped.
    pub fn finish(mut self) {
        self.close(false);
    }

    /// Ends the view within [`LINGER`] (and the connect time of a viewer being reached): the
    /// sender gets that long to finish; then its connection is shut down, which ends a write
    /// blocked on a viewer that does not read, and the thread is left to end by itself.
    fn close(&mut self, discard: bool) {
        // Closed already (finished, then dropped), or never started.
        let Some(thread) = self.thread.take() else { return };
        let deadline = Instant::now() + LINGER;
        let mut slot = self.shared.slot();
        slot.closing = true;
        if discard {
            slot.frame = None;
        }
        self.shared.wake.notify_all();
        while !slot.done {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break;
            }
            slot = self.shared.wake.wait_timeout(slot, left).unwrap_or_else(|e| e.into_inner()).0;
        }
        if !slot.done {
            slot.cut_off = true;
            slot.frame = None;
            if let Some(stream) = slot.stream.take() {
                let _ = stream.shutdown(Shutdown::Both);
            }
        }
        let (done, dropped, shown) = (slot.done, slot.shown - slot.sent.min(slot.shown), slot.shown);
        let warn = !discard && !done && !std::mem::replace(&mut slot.warned, true);
        drop(slot);
        if warn {
            (self.warn)(&format!(
                "the viewer at {} did not take the last frame within {} s; {dropped} of {shown} frames were dropped and \
                 the job ends without them",
                self.address,
                LINGER.as_secs_f64()
            ));
        }
        // Done: join at once. Else the thread ends when its write fails or its connect times
        // out; the job does not wait for it.
        if done {
            let _ = thread.join();
        }
    }
}

impl Drop for LiveView {
    /// A view dropped without [`LiveView::finish`] (a job that failed) sends nothing more.
    fn drop(&mut self) {
        self.close(true);
    }
}

/// The view's thread and its connection. It warns once in a view's life (the slot's `warned`):
/// a viewer that accepts connections but never reads would otherwise cost a line per frame.
struct Sender {
    spec: ViewSpec,
    warn: Arc<dyn Fn(&str) + Send + Sync>,
    stream: Option<TcpStream>,
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
            self.send(frame, shared);
        }
    }

    /// Sends a frame, connecting (and creating the image) first if need be; on failure, warns
    /// once and drops the connection (the next frame tries again).
    fn send(&mut self, frame: Frame, shared: &Shared) {
        let rows = if self.stream.is_some() { frame.rows.clone() } else { 0..self.spec.height };
        if self.stream.is_none() {
            match self.connect() {
                Ok(stream) => {
                    let mut slot = shared.slot();
                    if slot.cut_off {
                        return;
                    }
                    slot.stream = stream.try_clone().ok();
                    self.stream = Some(stream);
                }
                Err(e) => {
                    let message = format!("no viewer at {} ({e}); the job goes on without it", self.spec.address);
                    Self::warn_once(shared, &self.warn, &message);
                    return;
                }
            }
        }
        let stream = self.stream.as_mut().expect("connected above");
        match write_frame(stream, &self.spec, &frame.layers, rows) {
            Ok(()) => shared.slot().sent += 1,
            Err(e) => {
                self.stream = None;
                shared.slot().stream = None;
                let message = format!("the viewer at {} is lost ({e}); the job goes on without it", self.spec.address);
                Self::warn_once(shared, &self.warn, &message);
            }
        }
    }

    /// Warns unless the view has warned already, or the job's end cut the viewer off (which
    /// warns for itself).
    fn warn_once(shared: &Shared, warn: &Arc<dyn Fn(&str) + Send + Sync>, message: &str) {
        let mut slot = shared.slot();
        if !slot.warned && !slot.cut_off {
            slot.warned = true;
            drop(slot);
            warn(message);
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
        for good in ["127.0.0.1:14158", "localhost:1", "[::1]:14158", "tev.example.org:65535", "my-host.:80"] {
            assert!(check_address(good).is_ok(), "{good}");
        }
        // Port 0, a host with a ':' outside brackets, addresses no viewer listens on, malformed
        // IP addresses and names: each was accepted once and failed only at connect time.
        let bad = [
            "",
            "14158",
            ":14158",
            "localhost:",
            "localhost:65536",
            "host:port",
            "a b:1",
            "127.0.0.1:0",
            "127.0.0.1:14158:1",
            "localhost:14158:x",
            "::1:14158",
            "[::1:14158",
            "[nonsense]:1",
            "0.0.0.0:14158",
            "[::]:14158",
            "255.255.255.255:1",
            "224.0.0.1:1",
            "999.1.1.1:1",
            "1.2.3:1",
            "-host:1",
            "a..b:1",
            "host_name:1",
            "h\u{e9}te:1",
        ];
        for bad in bad {
            let e = check_address(bad).unwrap_err();
            assert!(e.contains("HOST:PORT") && e.contains(&format!("{bad:?}")), "{bad}: {e}");
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

    /// A viewer that accepts the connection and never reads: the view's end waits [`LINGER`]
    /// for the last frame, cuts the viewer off and says in one warning that frames were dropped
    /// (it once held the job's end for 15 s, its writes' time limits one after another).
    #[test]
    fn a_viewer_that_never_reads_holds_the_end_for_linger_at_most() {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let address = listener.local_addr().unwrap().to_string();
        // Accepts, holds the connection open without reading, until the test ends.
        let holder = std::thread::spawn(move || listener.accept().map(|(stream, _)| stream));
        let warnings = Arc::new(Mutex::new(Vec::<String>::new()));
        let log = Arc::clone(&warnings);
        // A frame of 12 MB: far more than the sockets' buffers hold.
        let (width, height) = (1024, 1024);
        let spec =
            ViewSpec { address: address.clone(), name: "test".into(), width, height, layers: vec![String::new()] };
        let view = LiveView::start(spec, Arc::new(move |m: &str| log.lock().unwrap().push(m.to_string())));
        for _ in 0..3 {
            view.show(vec![Film::new(width, height)], 0..height);
        }
        let start = Instant::now();
        view.finish();
        let waited = start.elapsed();
        // The bound the module promises, with room for a loaded machine (the old end took 15 s).
        assert!(waited < LINGER + Duration::from_millis(1500), "the end waited {waited:?}");
        let warnings = warnings.lock().unwrap();
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(warnings[0].contains(&address) && warnings[0].contains("frames were dropped"), "{warnings:?}");
        drop(holder.join().unwrap());
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
