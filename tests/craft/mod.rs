//! OpenEXR files written byte by byte, so that a header can claim anything: the hostile files
//! of tests/hostile/ and the headers the fuzzing harness grows (tests/fuzz_exr.rs). The layout
//! is the OpenEXR file format's: magic number, version and flags, attributes (name, type, size,
//! value), a zero byte, the offset table (one u64 per chunk), then the chunks.
#![allow(dead_code)] // each test file uses its own part

/// Sample types as the file spells them.
pub const UINT: i32 = 0;
pub const HALF: i32 = 1;
pub const FLOAT: i32 = 2;

/// Compression codes as the file spells them.
pub const NONE: u8 = 0;
pub const RLE: u8 = 1;
pub const ZIPS: u8 = 2;
pub const ZIP: u8 = 3;
pub const PIZ: u8 = 4;
pub const PXR24: u8 = 5;
pub const B44: u8 = 6;
pub const B44A: u8 = 7;
pub const DWAA: u8 = 8;
pub const DWAB: u8 = 9;

#[derive(Clone, Debug)]
pub struct Channel {
    pub name: String,
    pub sample_type: i32,
    pub sampling: (i32, i32),
}

impl Channel {
    pub fn new(name: &str, sample_type: i32) -> Channel {
        Channel { name: name.into(), sample_type, sampling: (1, 1) }
    }
}

/// A single-part header: what the attributes say, whatever the chunks hold.
#[derive(Clone, Debug)]
pub struct Header {
    /// In the file's order (alphabetical in a valid file).
    pub channels: Vec<Channel>,
    pub compression: u8,
    /// x min, y min, x max, y max (inclusive).
    pub data_window: [i32; 4],
    pub display_window: [i32; 4],
    pub line_order: u8,
    /// Tile width, height and mode (level mode + 16 x rounding mode): a tiled file.
    pub tiles: Option<(u32, u32, u8)>,
}

impl Header {
    /// Float RGB, uncompressed scan lines, `width` x `height` pixels.
    pub fn rgb(width: i32, height: i32) -> Header {
        let window = [0, 0, width - 1, height - 1];
        Header {
            channels: ["B", "G", "R"].iter().map(|n| Channel::new(n, FLOAT)).collect(),
            compression: NONE,
            data_window: window,
            display_window: window,
            line_order: 0,
            tiles: None,
        }
    }

    /// The magic number, version, attributes and the closing zero byte.
    pub fn bytes(&self) -> Vec<u8> {
        let mut out = vec![0x76, 0x2f, 0x31, 0x01];
        let flags: u32 = if self.tiles.is_some() { 0x200 } else { 0 };
        out.extend((2 | flags).to_le_bytes());
        let mut chlist = Vec::new();
        for c in &self.channels {
            chlist.extend(c.name.as_bytes());
            chlist.push(0);
            chlist.extend(c.sample_type.to_le_bytes());
            chlist.extend([0, 0, 0, 0]); // pLinear and three reserved bytes
            chlist.extend(c.sampling.0.to_le_bytes());
            chlist.extend(c.sampling.1.to_le_bytes());
        }
        chlist.push(0);
        attribute(&mut out, "channels", "chlist", &chlist);
        attribute(&mut out, "compression", "compression", &[self.compression]);
        attribute(&mut out, "dataWindow", "box2i", &ints(&self.data_window));
        attribute(&mut out, "displayWindow", "box2i", &ints(&self.display_window));
        attribute(&mut out, "lineOrder", "lineOrder", &[self.line_order]);
        attribute(&mut out, "pixelAspectRatio", "float", &1.0f32.to_le_bytes());
        attribute(&mut out, "screenWindowCenter", "v2f", &[0; 8]);
        attribute(&mut out, "screenWindowWidth", "float", &1.0f32.to_le_bytes());
        if let Some((w, h, mode)) = self.tiles {
            let mut t = Vec::new();
            t.extend(w.to_le_bytes());
            t.extend(h.to_le_bytes());
            t.push(mode);
            attribute(&mut out, "tiles", "tiledesc", &t);
        }
        out.push(0);
        out
    }
}

fn ints(v: &[i32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn attribute(out: &mut Vec<u8>, name: &str, kind: &str, value: &[u8]) {
    out.extend(name.as_bytes());
    out.push(0);
    out.extend(kind.as_bytes());
    out.push(0);
    out.extend((value.len() as i32).to_le_bytes());
    out.extend(value);
}

/// A header followed by `entries` zero offset-table entries and nothing else: a file that
/// claims its size and holds no pixel.
pub fn header_only(header: &Header, entries: usize) -> Vec<u8> {
    let mut out = header.bytes();
    out.resize(out.len() + 8 * entries, 0);
    out
}

/// A complete, valid file: float RGB, uncompressed scan lines, pixels row-major from the top.
pub fn rgb_file(width: usize, height: usize, pixels: &[[f32; 3]]) -> Vec<u8> {
    assert_eq!(pixels.len(), width * height);
    let mut out = Header::rgb(width as i32, height as i32).bytes();
    let line_bytes = 3 * 4 * width;
    let table_end = out.len() + 8 * height;
    for y in 0..height {
        out.extend(((table_end + y * (8 + line_bytes)) as u64).to_le_bytes());
    }
    for y in 0..height {
        out.extend((y as i32).to_le_bytes());
        out.extend((line_bytes as i32).to_le_bytes());
        for c in [2, 1, 0] {
            // B, G, R: the channels' alphabetical order.
            for x in 0..width {
                out.extend(pixels[y * width + x][c].to_le_bytes());
            }
        }
    }
    out
}

/// A complete float RGB file under RLE that is small for its size: every line one run of
/// bytes after another (128 bytes coded in 2), 64 times smaller than its pixels. What the
/// bytes decode to (RLE undoes a predictor) does not matter to the tests that use it.
pub fn rle_file(width: usize, height: usize) -> Vec<u8> {
    let line_bytes = 3 * 4 * width;
    assert_eq!(line_bytes % 128, 0);
    let runs = [0x7f, 0x00].repeat(line_bytes / 128);
    let mut out = Header { compression: RLE, ..Header::rgb(width as i32, height as i32) }.bytes();
    let table_end = out.len() + 8 * height;
    for y in 0..height {
        out.extend(((table_end + y * (8 + runs.len())) as u64).to_le_bytes());
    }
    for y in 0..height {
        out.extend((y as i32).to_le_bytes());
        out.extend((runs.len() as i32).to_le_bytes());
        out.extend(&runs);
    }
    out
}
