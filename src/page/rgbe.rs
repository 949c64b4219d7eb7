//! The page's image encoding.
//!
//! Each image keeps its full dynamic range as Radiance RGBE (one shared exponent per pixel,
//! 8-bit mantissas): `value = (mantissa + 0.5) * 2^(E - 136)`, `E = 0` meaning black. The four
//! bytes of every pixel are laid out as four planes of one 8-bit greyscale PNG of 2W x 2H:
//!
//! ```text
//! +-------+-------+
//! |   R   |   G   |     each plane W x H, row-major, top row first
//! +-------+-------+
//! |   B   |   E   |
//! +-------+-------+
//! ```
//!
//! A greyscale PNG is opaque, so no browser premultiplies anything, and an untagged PNG decoded
//! with `colorSpaceConversion: 'none'` reaches `getImageData` byte for byte; the JavaScript
//! (`viewer.js`, `decodeImage`) then undoes RGBE into a `Float32Array`. Planes compress better
//! than interleaved bytes. Precision: each channel comes back within `max(r, g, b) / 256` of its
//! value (so the brightest channel within 0.4 %); values below 2^-128 become 0; negative and NaN
//! values become 0 and +inf the largest RGBE value (about 1.7e38).

/// The Radiance RGBE bytes of one linear RGB pixel (see the module's doc for the precision).
pub fn rgbe_encode(rgb: [f32; 3]) -> [u8; 4] {
    // Largest value RGBE holds: mantissa 255 (+0.5 on decoding) at E = 255.
    const MAX: f64 = 255.0 * (1u128 << 119) as f64; // mantissa 255 at E = 255: 255 * 2^(255 - 136)
    let c = rgb.map(|v| {
        let v = v as f64;
        if v > 0.0 { v.min(MAX) } else { 0.0 } // NaN and negatives: 0; +inf: MAX
    });
    let v = c[0].max(c[1]).max(c[2]);
    if v <= 0.0 {
        return [0; 4];
    }
    // v = f * 2^e with f in [0.5, 1): read e from the f64's exponent bits (v is normal in f64).
    let e = ((v.to_bits() >> 52) & 0x7ff) as i32 - 1022;
    if e + 128 < 1 {
        return [0; 4];
    }
    let scale = 2f64.powi(8 - e);
    let m = c.map(|x| (x * scale).floor().min(255.0) as u8);
    [m[0], m[1], m[2], (e + 128) as u8]
}

/// Linear RGB from RGBE bytes, computed as the page's JavaScript does (in f64, stored as f32).
/// The tests' model of the page's decoding.
#[cfg(test)]
pub fn rgbe_decode(rgbe: [u8; 4]) -> [f32; 3] {
    if rgbe[3] == 0 {
        return [0.0; 3];
    }
    let f = 2f64.powi(rgbe[3] as i32 - 136);
    [0, 1, 2].map(|c| ((rgbe[c] as f64 + 0.5) * f) as f32)
}

/// The 2W x 2H greyscale PNG of an image's RGBE planes (R G / B E). `pixels` holds
/// `width * height` linear RGB values, row-major, top row first.
pub fn encode_png(width: u32, height: u32, pixels: &[[f32; 3]]) -> Result<Vec<u8>, image::ImageError> {
    use image::ImageEncoder;
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    let (w, h) = (width as usize, height as usize);
    let mut planes = vec![0u8; 4 * w * h];
    for y in 0..h {
        for x in 0..w {
            let b = rgbe_encode(pixels[y * w + x]);
            let top = y * 2 * w + x;
            let bottom = top + 2 * w * h;
            planes[top] = b[0];
            planes[top + w] = b[1];
            planes[bottom] = b[2];
            planes[bottom + w] = b[3];
        }
    }
    let mut png = Vec::new();
    PngEncoder::new_with_quality(&mut png, CompressionType::Best, FilterType::Adaptive).write_image(
        &planes,
        2 * width,
        2 * height,
        image::ExtendedColorType::L8,
    )?;
    Ok(png)
}

/// The linear RGB pixels of a PNG made by [`encode_png`], as the page's JavaScript reads
/// them. The tests' model of the page's decoding.
#[cfg(test)]
pub fn decode_png(png: &[u8]) -> Result<(u32, u32, Vec<[f32; 3]>), String> {
    let img = image::load_from_memory_with_format(png, image::ImageFormat::Png).map_err(|e| e.to_string())?;
    let grey = img.to_luma8();
    let (w2, h2) = grey.dimensions();
    if w2 % 2 != 0 || h2 % 2 != 0 {
        return Err(format!("{w2}x{h2} is not 2W x 2H"));
    }
    let (w, h) = (w2 / 2, h2 / 2);
    let g = |x: u32, y: u32| grey.get_pixel(x, y).0[0];
    let mut pixels = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            pixels.push(rgbe_decode([g(x, y), g(x + w, y), g(x, y + h), g(x + w, y + h)]));
        }
    }
    Ok((w, h, pixels))
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// A deterministic pseudo-random number in [0, 1).
    pub fn hash01(i: u64) -> f32 {
        let mut z = i.wrapping_add(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Whether `decoded` is within RGBE's precision of `original` (the module's doc).
    pub fn within_rgbe(original: [f32; 3], decoded: [f32; 3]) -> bool {
        let c = original.map(|v| if v > 0.0 { v } else { 0.0 });
        let max = c[0].max(c[1]).max(c[2]);
        (0..3).all(|k| (decoded[k] - c[k]).abs() <= max / 256.0 * 1.000_01 + 3e-39)
    }

    #[test]
    fn rgbe_round_trips_within_a_256th_of_the_brightest_channel() {
        let mut values = vec![
            [0.0, 0.0, 0.0],
            [1.0, 1.0, 1.0],
            [0.5, 0.25, 0.125],
            [1e-3, 2e-5, 0.0],
            [1e-30, 1e-31, 3e-30],
            [65504.0, 1.0, 0.1],
            [1e30, 1e29, 5e30],
            [0.999_999, 0.999_999, 0.0],
            [255.0 / 256.0, 1.0 / 256.0, 0.0],
        ];
        for i in 0..20_000u64 {
            let e = (hash01(4 * i) * 40.0 - 20.0).exp2();
            values.push([hash01(4 * i + 1) * e, hash01(4 * i + 2) * e, hash01(4 * i + 3) * e]);
        }
        for v in values {
            let d = rgbe_decode(rgbe_encode(v));
            assert!(within_rgbe(v, d), "{v:?} -> {d:?}");
        }
        // Out of range: negatives and NaN are black, +inf is the largest value, tiny is black.
        assert_eq!(rgbe_decode(rgbe_encode([-1.0, f32::NAN, 0.5])), rgbe_decode(rgbe_encode([0.0, 0.0, 0.5])));
        assert!(rgbe_decode(rgbe_encode([f32::INFINITY, 0.0, 0.0]))[0] > 1e38);
        assert_eq!(rgbe_encode([1e-39, 0.0, 0.0]), [0; 4]);
        assert_eq!(rgbe_encode([1.0, 0.5, 0.0]), [128, 64, 0, 129]);
    }
}
