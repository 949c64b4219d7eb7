//! What the library accepts: every range check of a setting lives here, so that scene files,
//! the command line and the Python bindings refuse the same things with the same words.

/// Scene files larger than this are refused before they are read.
pub const MAX_SCENE_FILE_BYTES: u64 = 1 << 20;
/// The most lights a scene may have (occluders are tracked as bits of a u64 per plane).
pub const MAX_LIGHTS: usize = 64;
/// The largest image side accepted.
pub const MAX_RESOLUTION_SIDE: u32 = 1 << 15;
/// The largest plane count accepted (about 30 GB of planes would be needed beyond it).
pub const MAX_PLANES: u64 = 1 << 27;
/// The most camera samples per pixel.
pub const MAX_SPP: u32 = 1 << 16;
/// The largest number of stratified orientations accepted.
pub const MAX_ORIENTATIONS: u32 = 64;
/// The largest total light power (area x luminance) accepted: images are f32 (largest about
/// 3.4e38), and a pixel sums the power of thousands of hits.
pub const MAX_TOTAL_POWER: f64 = 1e30;
/// The most worker threads.
pub const MAX_THREADS: usize = 1024;
/// The longest time budget of one render, in seconds (about 11 days).
pub const MAX_TIME_BUDGET_SECONDS: f64 = 1e6;
/// The longest equal-time render of one table entry, in seconds.
pub const MAX_EQUAL_TIME_SECONDS: f64 = 1e5;
/// The most seeds per plane count in the table's error-versus-time sweep.
pub const MAX_SWEEP_SEEDS: u32 = 1000;

/// Memory refused up front: a render that would need more than this is an input error.
pub const MEMORY_BUDGET_BYTES: u64 = 16 << 30;
/// Bytes per plane held while rendering (sampled plane, prepared view, screen polygon, bins).
pub const BYTES_PER_PLANE: u64 = 512;
/// Bytes per pixel held while rendering (rays, sums, emission, film).
pub const BYTES_PER_PIXEL: u64 = 96;

pub fn check_resolution(width: u32, height: u32) -> Result<(), String> {
    if width == 0 || height == 0 || width > MAX_RESOLUTION_SIDE || height > MAX_RESOLUTION_SIDE {
        return Err(format!("each side must be between 1 and {MAX_RESOLUTION_SIDE} pixels, got {width}x{height}"));
    }
    Ok(())
}

pub fn check_planes(planes: u64) -> Result<(), String> {
    if planes == 0 || planes > MAX_PLANES {
        return Err(format!("the plane count must be between 1 and {MAX_PLANES}, got {planes}"));
    }
    Ok(())
}

pub fn check_spp(spp: u32) -> Result<(), String> {
    if spp == 0 || spp > MAX_SPP {
        return Err(format!("samples per pixel must be between 1 and {MAX_SPP}, got {spp}"));
    }
    Ok(())
}

pub fn check_threads(threads: usize) -> Result<(), String> {
    if threads == 0 || threads > MAX_THREADS {
        return Err(format!("the thread count must be between 1 and {MAX_THREADS}, got {threads}"));
    }
    Ok(())
}

/// A span of wall time in seconds: positive, finite, at most `max`.
pub fn check_seconds(seconds: f64, max: f64) -> Result<(), String> {
    if !(seconds > 0.0 && seconds <= max) {
        return Err(format!("must be a positive number of seconds up to {max:e}, got {seconds}"));
    }
    Ok(())
}

/// An exposure in stops: any finite number (a NaN would turn every pixel black).
pub fn check_exposure(stops: f32) -> Result<(), String> {
    if !stops.is_finite() {
        return Err(format!("must be a finite number of stops, got {stops}"));
    }
    Ok(())
}

pub fn check_sweep_seeds(seeds: u32) -> Result<(), String> {
    if seeds == 0 || seeds > MAX_SWEEP_SEEDS {
        return Err(format!("the seeds per plane count must be between 1 and {MAX_SWEEP_SEEDS}, got {seeds}"));
    }
    Ok(())
}

/// Refuses, with the figure, a render that would exhaust memory.
pub fn check_memory(width: u32, height: u32, planes: u64) -> Result<(), String> {
    let bytes = planes
        .saturating_mul(BYTES_PER_PLANE)
        .saturating_add((width as u64 * height as u64).saturating_mul(BYTES_PER_PIXEL));
    if bytes > MEMORY_BUDGET_BYTES {
        return Err(format!(
            "{width}x{height} pixels with {planes} planes would need about {:.1} GiB; the limit is {} GiB",
            bytes as f64 / (1u64 << 30) as f64,
            MEMORY_BUDGET_BYTES >> 30
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_are_closed_at_both_ends() {
        assert!(check_planes(1).is_ok() && check_planes(MAX_PLANES).is_ok());
        assert!(check_planes(0).is_err() && check_planes(MAX_PLANES + 1).is_err());
        assert!(check_spp(MAX_SPP).is_ok() && check_spp(0).is_err());
        assert!(check_resolution(1, MAX_RESOLUTION_SIDE).is_ok() && check_resolution(0, 1).is_err());
        assert!(check_threads(1).is_ok() && check_threads(0).is_err());
        assert!(check_seconds(1e6, MAX_TIME_BUDGET_SECONDS).is_ok());
        for bad in [0.0, -1.0, 1.5e6, f64::NAN, f64::INFINITY] {
            assert!(check_seconds(bad, MAX_TIME_BUDGET_SECONDS).is_err(), "{bad}");
        }
        assert!(
            check_exposure(-3.0).is_ok() && check_exposure(f32::NAN).is_err() && check_exposure(f32::INFINITY).is_err()
        );
        assert!(check_sweep_seeds(1).is_ok() && check_sweep_seeds(0).is_err() && check_sweep_seeds(1001).is_err());
        let e = check_memory(32_000, 32_000, 40_960).unwrap_err();
        assert!(e.contains("91.6 GiB"), "{e}");
        assert!(check_memory(640, 360, 640_000).is_ok());
    }
}
