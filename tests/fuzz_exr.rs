//! Fuzzing the EXR reader and `compare` (proptest): headers grown from hostile sizes, data
//! windows, channel lists, codecs, tiles and truncated chunks; real files of every codec the
//! writer has, mutated byte by byte; images with NaN and infinity in random places.
//!
//! Promised and checked on every case: no panic; a refusal is an error, not an abort; the
//! largest single allocation while loading a file of n bytes stays below 8 MiB + 2 n R, with R
//! the worst-case expansion of the file's codec (`fogplanes::film::check_exr_headers`): a
//! pixel costs the image 12 bytes and the file at least 6 (three half samples). CI runs a
//! thousand cases in about a second; `PROPTEST_CASES=100000 cargo test --release --test all --
//! fuzz_exr::` fuzzes for longer.

use crate::craft;
use crate::craft::{Channel, Header};
use fogplanes::film::Film;
use fogplanes::metrics::compare;
use glam::Vec3;
use proptest::prelude::*;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Counts the allocations of a thread that is loading a file (see [`load`]): the largest, and
/// any above 4 GiB refused (a bug then fails with an allocation failure instead of filling the
/// machine's memory). Per thread, since every test of the program shares the process; the exr
/// crate's decoding threads go uncounted (their buffers hold one chunk each), the pixel buffer
/// does not (`the_counter_sees_the_pixel_buffer`).
struct Counting;

thread_local! {
    /// The largest allocation of this thread while it loads; `None` when it does not.
    static LARGEST: Cell<Option<usize>> = const { Cell::new(None) };
}

const REFUSED_ABOVE: usize = 4 << 30;

/// Records an allocation of `size` bytes; whether it may be made.
fn allowed(size: usize) -> bool {
    LARGEST
        .try_with(|largest| match largest.get() {
            Some(m) => {
                largest.set(Some(m.max(size)));
                size <= REFUSED_ABOVE
            }
            None => true,
        })
        .unwrap_or(true)
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if allowed(layout.size()) { unsafe { System.alloc(layout) } } else { std::ptr::null_mut() }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if allowed(layout.size()) { unsafe { System.alloc_zeroed(layout) } } else { std::ptr::null_mut() }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if allowed(new_size) { unsafe { System.realloc(ptr, layout, new_size) } } else { std::ptr::null_mut() }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Worst-case expansion by compression code, as `fogplanes::film` bounds it (1 for codes the
/// reader refuses).
fn expansion(code: u8) -> u64 {
    [1, 64, 1032, 1032, 454, 1376, 11, 11, 66_048, 66_048].get(code as usize).copied().unwrap_or(1)
}

/// The compression code of a header that parses, else 0.
fn compression_code(bytes: &[u8]) -> u8 {
    let key = b"compression\0compression\0\x01\0\0\0";
    bytes.windows(key.len() + 1).find(|w| &w[..key.len()] == key).map_or(0, |w| w[key.len()])
}

/// What `f` returns and the largest allocation this thread made meanwhile (also used by
/// tests/fuzz_parts.rs).
pub(crate) fn largest_allocation<T>(f: impl FnOnce() -> T) -> (T, usize) {
    LARGEST.with(|l| l.set(Some(0)));
    let out = f();
    (out, LARGEST.with(|l| l.take()).unwrap_or(0))
}

/// Loads `bytes` from a file; returns the result and the largest allocation this thread made
/// meanwhile.
fn load(bytes: &[u8]) -> (fogplanes::Result<Film>, usize) {
    static FILES: AtomicUsize = AtomicUsize::new(0);
    let n = FILES.fetch_add(1, Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!("fogplanes-fuzz-exr-{}-{n}.exr", std::process::id()));
    std::fs::write(&path, bytes).unwrap();
    let (film, largest) = largest_allocation(|| Film::load_exr(&path));
    let _ = std::fs::remove_file(&path);
    (film, largest)
}

/// The measure itself: loading a 256x256 file is seen to allocate its 768 KiB pixel buffer.
#[test]
fn the_counter_sees_the_pixel_buffer() {
    let (film, largest) = load(&craft::rgb_file(256, 256, &vec![[0.5; 3]; 256 * 256]));
    assert_eq!(film.unwrap().pixels.len(), 256 * 256);
    assert!(largest >= 256 * 256 * 12, "{largest}");
}

/// A layer that is not RGB at full resolution is refused before its pixels are reserved: an
/// 8192 x 8192 header of one channel, or of RGB with R subsampled, in a 266,542-byte PXR24 file
/// claims few enough samples to pass the check of sizes. The fuzzing found the first: its
/// image's 12 bytes a pixel, probed before decoding (805 MB), exceeded the module's bound for
/// the file's size, and the reader then refused the layer for its missing channels.
#[test]
fn a_layer_without_full_rgb_is_refused_before_its_pixels_are_reserved() {
    let window = [0, 0, 8191, 8191];
    let mut subsampled: Vec<Channel> = ["B", "G", "R"].iter().map(|n| Channel::new(n, craft::HALF)).collect();
    subsampled[2].sampling = (2, 2);
    for (channels, says) in [
        (vec![Channel::new("R", craft::UINT)], "no layer has channels named R, G and B"),
        (subsampled, "subsampling not supported"),
    ] {
        let header = Header {
            channels,
            compression: craft::PXR24,
            data_window: window,
            display_window: window,
            line_order: 0,
            tiles: None,
        };
        let mut bytes = craft::header_only(&header, 512);
        bytes.resize(266_542, 0);
        check(&bytes).unwrap();
        let (film, largest) = load(&bytes);
        let e = film.map(|f| f.width).expect_err("refused");
        assert!(e.to_string().contains(says), "{e}");
        assert!(largest < 1 << 20, "{largest} bytes allocated at once");
    }
}

/// The promises of the module doc on one file.
fn check(bytes: &[u8]) -> Result<(), TestCaseError> {
    let (film, largest) = load(bytes);
    let bound = (8 << 20) + 2 * bytes.len() as u64 * expansion(compression_code(bytes));
    prop_assert!(largest as u64 <= bound, "{} bytes allocated at once for a {}-byte file", largest, bytes.len());
    match film {
        Ok(film) => {
            prop_assert_eq!(film.pixels.len(), film.width as usize * film.height as usize);
            // compare either refuses a non-finite value or gives finite metrics (zero against
            // itself).
            match compare(&film, &film) {
                Ok(m) => prop_assert_eq!(m, Default::default()),
                Err(e) => prop_assert!(film.first_non_finite().is_some() && e.is_input(), "{e}"),
            }
        }
        Err(e) => {
            prop_assert!(e.is_input(), "{e}");
            prop_assert_eq!(e.to_string().lines().count(), 1, "{}", e);
        }
    }
    Ok(())
}

/// Sizes at and beyond every limit, and (mostly) ordinary ones.
fn side() -> impl Strategy<Value = i32> {
    prop_oneof![
        16 => 1..40i32,
        1 => Just(0),
        1 => Just(-1),
        1 => Just(8192),
        1 => Just(32768),
        1 => Just(32769),
        1 => Just(65536),
        1 => Just(1 << 30),
        1 => Just(i32::MAX),
    ]
}

fn origin() -> impl Strategy<Value = i32> {
    prop_oneof![
        12 => Just(0),
        4 => -5..5i32,
        1 => Just(i32::MIN),
        1 => Just(i32::MAX),
        1 => Just(i32::MAX - 4),
        // Either side of the largest coordinate a window may have (2^30 - 1, exclusive).
        1 => Just((1 << 30) - 50),
        1 => Just(-(1 << 30) + 2),
    ]
}

fn channel() -> impl Strategy<Value = Channel> {
    let name = prop_oneof![Just("R"), Just("G"), Just("B"), Just("A"), Just("Y"), Just(""), Just("layer.R")];
    let sample_type = prop_oneof![4 => 0..3i32, 1 => Just(3), 1 => Just(-1)];
    let sampling =
        prop_oneof![4 => Just(1), 1 => Just(2), 1 => Just(0), 1 => Just(-1), 1 => Just(3), 1 => Just(i32::MAX)];
    (name, sample_type, sampling.clone(), sampling).prop_map(|(name, sample_type, sx, sy)| Channel {
        name: name.into(),
        sample_type,
        sampling: (sx, sy),
    })
}

fn channels() -> impl Strategy<Value = Vec<Channel>> {
    prop_oneof![
        // Valid RGB(A) of any types, as most files are.
        3 => prop::collection::vec(0..3i32, 4).prop_map(|t| ["A", "B", "G", "R"].iter().zip(t).map(|(n, t)| Channel::new(n, t)).collect()),
        3 => (0..3i32).prop_map(|t| ["B", "G", "R"].iter().map(|n| Channel::new(n, t)).collect()),
        2 => prop::collection::vec(channel(), 0..6),
    ]
}

fn tile_side() -> impl Strategy<Value = u32> {
    prop_oneof![Just(1u32), Just(8), Just(64), Just(0), Just(1 << 31), Just(u32::MAX)]
}

fn header() -> impl Strategy<Value = Header> {
    let tiles = prop_oneof![
        3 => Just(None),
        1 => (tile_side(), tile_side(), 0..0x23u8).prop_map(Some),
    ];
    (channels(), 0..13u8, origin(), origin(), side(), side(), prop::bool::weighted(0.8), 0..4u8, tiles).prop_map(
        |(channels, compression, x0, y0, w, h, same_display, line_order, tiles)| {
            let window = [x0, y0, x0.saturating_add(w - 1), y0.saturating_add(h - 1)];
            Header {
                channels,
                compression,
                data_window: window,
                display_window: if same_display { window } else { [0, 0, w, h] },
                line_order,
                tiles,
            }
        },
    )
}

/// What follows a header: an offset table of some length, then chunks that are absent, zeroed,
/// random, shaped right (line number and size) over zeroed data, or exact: every chunk of the
/// header's scan lines with its uncompressed size (which the reader takes as raw under any
/// codec) over random bytes, perhaps cut short.
#[derive(Clone, Debug)]
enum Body {
    Table(usize),
    Zeros(usize),
    Random(Vec<u8>),
    Chunks { lines: usize, line_bytes: usize },
    Exact { fill: Vec<u8>, cut: usize },
}

fn body() -> impl Strategy<Value = Body> {
    prop_oneof![
        1 => (0..64usize).prop_map(Body::Table),
        1 => (0..4096usize).prop_map(Body::Zeros),
        1 => prop::collection::vec(any::<u8>(), 0..512).prop_map(Body::Random),
        1 => (1..40usize, 0..512usize).prop_map(|(lines, line_bytes)| Body::Chunks { lines, line_bytes }),
        4 => (prop::collection::vec(any::<u8>(), 1..64), prop_oneof![3 => Just(0usize), 1 => 0..600usize])
            .prop_map(|(fill, cut)| Body::Exact { fill, cut }),
    ]
}

/// Scan lines per chunk by compression code, as the format fixes them.
fn lines_per_chunk(code: u8) -> usize {
    match code {
        3 | 5 => 16,
        4 | 6 | 7 | 8 => 32,
        9 => 256,
        _ => 1,
    }
}

/// At most this much body is written: a header claiming more makes a truncated file.
const MAX_BODY: usize = 256 << 10;

fn assemble(header: &Header, body: &Body) -> Vec<u8> {
    let mut out = header.bytes();
    match body {
        Body::Table(n) => out.resize(out.len() + 8 * n, 0),
        Body::Zeros(n) => out.resize(out.len() + n, 0),
        Body::Random(bytes) => out.extend(bytes),
        Body::Chunks { lines, line_bytes } => {
            let table_end = out.len() + 8 * lines;
            for y in 0..*lines {
                out.extend(((table_end + y * (8 + line_bytes)) as u64).to_le_bytes());
            }
            for y in 0..*lines {
                out.extend((header.data_window[1].wrapping_add(y as i32)).to_le_bytes());
                out.extend((*line_bytes as i32).to_le_bytes());
                out.resize(out.len() + line_bytes, 0);
            }
        }
        Body::Exact { fill, cut } => {
            let [x0, y0, x1, y1] = header.data_window.map(i64::from);
            let (width, height) = ((x1 - x0 + 1).max(0) as usize, (y1 - y0 + 1).max(0) as usize);
            let pixel_bytes: usize = header.channels.iter().map(|c| if c.sample_type == 1 { 2 } else { 4 }).sum();
            let per_chunk = lines_per_chunk(header.compression);
            let chunks = height.div_ceil(per_chunk).min(MAX_BODY / 8);
            let chunk_bytes =
                |i: usize| 8 + width.saturating_mul(pixel_bytes).saturating_mul(per_chunk.min(height - i * per_chunk));
            let start = out.len();
            let mut offset = start + 8 * chunks;
            for i in 0..chunks {
                out.extend((offset as u64).to_le_bytes());
                offset = offset.saturating_add(chunk_bytes(i));
            }
            let mut noise = fill.iter().copied().cycle();
            for i in 0..chunks {
                if out.len() - start > MAX_BODY {
                    break;
                }
                let data = chunk_bytes(i) - 8;
                out.extend((y0 as i32).wrapping_add((i * per_chunk) as i32).to_le_bytes());
                out.extend((data as i32).to_le_bytes());
                out.extend(noise.by_ref().take(data.min(MAX_BODY)));
            }
            out.truncate(out.len().saturating_sub(*cut));
        }
    }
    out
}

/// Real files written by the exr crate: 19x13 RGBA (half, float, float, half) with a ramp and
/// noise, in every codec it writes, as scan lines and as 8x8 tiles; and a crafted float file.
fn real_files() -> Vec<Vec<u8>> {
    use exr::prelude::*;
    let (w, h) = (19usize, 13usize);
    let mut files = vec![craft::rgb_file(
        w,
        h,
        &(0..w * h).map(|i| [i as f32, (i % 7) as f32 * 0.25, 1.0 / (1 + i) as f32]).collect::<Vec<_>>(),
    )];
    let codecs = [
        Compression::Uncompressed,
        Compression::RLE,
        Compression::ZIP1,
        Compression::ZIP16,
        Compression::PIZ,
        Compression::PXR24,
        Compression::B44,
        Compression::B44A,
    ];
    for compression in codecs {
        for blocks in [Blocks::ScanLines, Blocks::Tiles(Vec2(8, 8))] {
            let pixels = SpecificChannels::rgba(|Vec2(x, y): Vec2<usize>| {
                let noise = ((x * 7919 + y * 104_729) % 97) as f32 / 97.0;
                (f16::from_f32(x as f32 / 19.0), y as f32 + noise, noise, f16::from_f32(1.0))
            });
            let encoding = Encoding { compression, blocks, line_order: LineOrder::Increasing };
            let layer = Layer::new(Vec2(w, h), LayerAttributes::named("fuzz"), encoding, pixels);
            let mut bytes = std::io::Cursor::new(Vec::new());
            Image::from_layer(layer).write().to_buffered(&mut bytes).unwrap();
            files.push(bytes.into_inner());
        }
    }
    files
}

/// Values that break sizes and offsets when they replace four bytes.
const NASTY_INTS: &[i32] = &[0, -1, 1, i32::MAX, i32::MIN, 1 << 16, 1 << 20, 1 << 30, 32767, 32768, 65535];

fn mutate(bytes: &mut Vec<u8>, edits: &[(usize, u8, usize)]) {
    for &(pos, kind, arg) in edits {
        if bytes.is_empty() {
            return;
        }
        let pos = pos % bytes.len();
        match kind % 5 {
            0 => bytes[pos] = arg as u8,
            1 => bytes[pos] ^= 1 << (arg % 8),
            2 => {
                let end = (pos + 4).min(bytes.len());
                let v = NASTY_INTS[arg % NASTY_INTS.len()].to_le_bytes();
                bytes[pos..end].copy_from_slice(&v[..end - pos]);
            }
            3 => bytes.truncate(pos),
            _ => {
                let end = (pos + arg % 64).min(bytes.len());
                bytes.drain(pos..end);
            }
        }
    }
}

/// `PROPTEST_CASES` if set (a longer run), else `default` (CI).
fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(1000), ..ProptestConfig::default() })]

    #[test]
    fn crafted_headers_are_refused_or_read_within_bounds(header in header(), body in body()) {
        check(&assemble(&header, &body))?;
    }

    #[test]
    fn mutated_real_files_are_refused_or_read_within_bounds(
        file in 0..17usize,
        edits in prop::collection::vec((any::<usize>(), any::<u8>(), any::<usize>()), 1..5),
    ) {
        thread_local!(static FILES: Vec<Vec<u8>> = real_files());
        let mut bytes = FILES.with(|f| f[file % f.len()].clone());
        mutate(&mut bytes, &edits);
        check(&bytes)?;
    }

    /// Random images with NaN and infinity put anywhere: compare refuses exactly when one of
    /// the two holds a non-finite value, names the first, and is finite otherwise.
    #[test]
    fn compare_never_hides_a_non_finite_value(
        (w, h) in (1..6u32, 1..6u32),
        values in prop::collection::vec(prop_oneof![8 => -2.0..1e3f32, 1 => Just(0.0f32)], 2 * 3 * 36),
        poison in prop::collection::vec((any::<bool>(), 0..36usize, 0..3usize, prop_oneof![Just(f32::NAN), Just(f32::INFINITY), Just(f32::NEG_INFINITY)]), 0..3),
    ) {
        let n = (w * h) as usize;
        let film = |offset: usize| Film {
            width: w,
            height: h,
            pixels: (0..n).map(|i| Vec3::from_slice(&values[offset + 3 * i..offset + 3 * i + 3])).collect(),
        };
        let (mut image, mut reference) = (film(0), film(3 * 36));
        for &(in_image, i, c, v) in &poison {
            let target = if in_image { &mut image } else { &mut reference };
            target.pixels[i % n][c] = v;
        }
        match compare(&image, &reference) {
            Ok(m) => {
                prop_assert!(image.first_non_finite().is_none() && reference.first_non_finite().is_none());
                prop_assert!(m.smape.is_finite() && m.mse.is_finite() && m.rel_mse.is_finite() && m.max_abs_error.is_finite());
            }
            Err(e) => {
                let (which, bad) = match image.first_non_finite() {
                    Some(p) => ("image", p),
                    None => ("reference", reference.first_non_finite().expect("refused without a bad value")),
                };
                prop_assert_eq!(
                    e.to_string(),
                    format!("the {which} holds a value that is not a finite number: {bad}")
                );
                let v = [image.get(bad.x, bad.y), reference.get(bad.x, bad.y)][(which == "reference") as usize][bad.channel];
                prop_assert!(!v.is_finite() && v.to_bits() == bad.value.to_bits());
            }
        }
    }
}
