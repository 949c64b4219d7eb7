//! What the library accepts and what it assumes when nothing is said: every default of a
//! render, every range check of a setting and the memory rule live here, so that scene files,
//! the command line and the Python bindings refuse the same things with the same words.

// ---------------------------------------------------------------------------------------------
// Defaults (a scene's `[render]` table and the caller override them)

/// Planes of a render when neither the caller nor the scene says: the paper's setting.
pub const DEFAULT_PLANES: u64 = 40_960;
/// The seed of a render when neither the caller nor the scene says.
pub const DEFAULT_SEED: u64 = 1;
/// Ray sets per pixel when neither the command line nor the scene says (`--spp`): chosen by
/// measurement (docs/measurements.md, "Whole pixels").
pub const DEFAULT_RAY_SETS: u32 = 16;
/// The share of a light's planes swept along its lobe ([`crate::photon_plane::Lobe`]) in fog
/// that scatters forward or back, unless a render says otherwise (the `lobes` setting: 0 sweeps
/// every plane by the cosine, as the paper does). Measured from 0 to 1 (docs/mathematics.md
/// section 2.5, `scripts/lobe_shares.sh`): looking toward the lights through strong forward fog
/// every error falls as the share grows, but a side view's dim pixels and weak fog lose beyond
/// about 0.5; at 0.5 a pixel that gains nothing from the lobe loses at most half its planes, its
/// variance at most doubled.
pub const DEFAULT_LOBES: f64 = 0.5;
/// Planes per canonical chunk ([`crate::partial`]): a power of two, fixed (it never depends on
/// the number of workers or of planes), small enough that one chunk is a task of a fraction of
/// a second at 640x360 and holds little memory, large enough that the per-chunk costs (one
/// pass over the image's tiles, the f64 conversion) stay near 1% of a render.
pub const CHUNK_PLANES: usize = 16_384;

/// The most chunks a render gathers at once ([`crate::raster::chunks_at_once`]; it prepares as
/// many more meanwhile).
pub const MAX_CHUNKS_AT_ONCE: usize = 8;

/// The most pixels of a window's chunks' sums together (a chunk's f32 sums and f64 partial,
/// [`WINDOW_BYTES_PER_PIXEL`]): a large image gathers one chunk at a time.
pub const MAX_WINDOW_PIXELS: usize = 1 << 22;

/// Bytes of a chunk's sums per pixel while its window is gathered: f32 and f64 RGB.
pub const WINDOW_BYTES_PER_PIXEL: u64 = 36;

/// Planes per unit of work of the parallel loops over planes (sampling, preparing, projecting):
/// a few hundred microseconds each, a unit of the schedule's record ([`crate::schedule`]).
pub const PLANE_UNIT: usize = 256;

/// How a render's process keeps the memory it frees, under glibc's allocator (Linux): blocks up
/// to this many bytes come from the heap rather than each mapped afresh. A render allocates
/// and frees each piece's planes, views and footprints (megabytes each), and glibc's own
/// thresholds, which move with the last block freed, make the reuse of that memory a matter of
/// the order of allocations (a change that only moved one vector's allocation made a render of
/// 655,360 planes at 32x18 take 82,550 page faults instead of 10,380; with these settings both
/// took 6,470). The command line sets both thresholds for itself ([`keep_freed_memory`]); the
/// Python module leaves its host's allocator alone, and gives them to the workers of the Dask
/// cluster it starts ([`ALLOCATOR_ENVIRONMENT`]), where Dask's own setting (a trim threshold of
/// 64 KiB) cost a render of the benchmark about a tenth more CPU time.
pub const MMAP_THRESHOLD: usize = 32 << 20;
/// Free heap kept rather than handed back, in bytes: twice [`MMAP_THRESHOLD`], as glibc's
/// moving thresholds keep them (256 MiB gave the same page faults).
pub const TRIM_THRESHOLD: usize = 64 << 20;
/// [`MMAP_THRESHOLD`] and [`TRIM_THRESHOLD`] as the environment variables glibc reads when a
/// process starts (its tunables' older names, which Dask's nanny also sets).
pub const ALLOCATOR_ENVIRONMENT: [(&str, usize); 2] =
    [("MALLOC_MMAP_THRESHOLD_", MMAP_THRESHOLD), ("MALLOC_TRIM_THRESHOLD_", TRIM_THRESHOLD)];

/// Sets [`MMAP_THRESHOLD`] and [`TRIM_THRESHOLD`] for this process (glibc's `mallopt`; nothing
/// elsewhere): large blocks from the heap rather than each mapped afresh, and free heap kept
/// rather than handed back. The cost: the process keeps what it freed (the benchmark's peak
/// about 63 MB instead of 51 on 2 threads; not measured on more, where each thread's arena
/// keeps its own). The library never calls it: a program does, first thing (the command line,
/// `benches/examples/prepare_planes.rs`, which times the preparation as the command line
/// runs it); the Python module leaves its host's allocator alone.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets the allocator's parameters (called before the program starts a
    // thread). A value it refuses is ignored (it returns 0); either call alone still fixes
    // thresholds that glibc would otherwise move, which is harmless.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD as libc::c_int);
        libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD as libc::c_int);
    }
}

// ---------------------------------------------------------------------------------------------
// Ranges

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
/// The widest field of view accepted, in degrees: toward 180 the image plane's coordinates grow
/// without bound (tan(vfov / 2)), and at 179.999 the raster and the GPU missed hits that the
/// brute force found (0.8% at 64x36); at 179 a pixel at the edge is 115 times the centre's.
pub const MAX_VFOV_DEG: f64 = 179.0;
/// The narrowest field of view accepted, in degrees (3.6 arcseconds, narrower than any view
/// through fog): at 1e-10 degrees with the camera 1e-4 from the box the raster missed 0.09% of
/// the brute force's hits (64x36), at 1e-15 degrees 9% (the screen's coordinates, in f64, no
/// longer resolve a pixel), and below about 2.2e-308 (where tan(vfov / 2) is no normal f64) all
/// of them: an image too dark, or black, with no word.
pub const MIN_VFOV_DEG: f64 = 1e-3;
/// The largest fog box, by its diagonal in world units: every position is held in f32 relative
/// to the camera (largest about 3.4e38), and squared lengths in f64.
pub const MAX_BOX_DIAGONAL: f64 = 1e30;
/// The smallest fog box, by its diagonal in world units: positions are held in f32 (smallest
/// normal about 1.2e-38) and a light's edge may be 1e-9 of the diagonal, and a hit's value grows
/// as one over the box's size, summed in f32 over a chunk. The benchmark scaled to 1e-40 found
/// no hit (the fog vanished from its image, without a word), and to 1e-37 overflowed a chunk's
/// sums; at 1e-20 every estimator and accelerator gives the unscaled image.
pub const MIN_BOX_DIAGONAL: f64 = 1e-20;
/// The farthest the camera may be from the fog box, in box diagonals: a plane is held in f32
/// relative to the camera, so the box's detail is kept to about 6e-8 times this distance over
/// the box's size (a camera 2,900 diagonals away moved a scene's mean by 1.2e-4, 29,000 by
/// 9e-4, 290,000 by 0.65%).
pub const MAX_CAMERA_DISTANCE_DIAGONALS: f64 = 1e3;
/// The most worker threads.
pub const MAX_THREADS: usize = 1024;
/// The longest time budget of one render, in seconds (about 11 days).
pub const MAX_TIME_BUDGET_SECONDS: f64 = 1e6;
/// The longest equal-time render of one table entry, in seconds.
pub const MAX_EQUAL_TIME_SECONDS: f64 = 1e5;
/// The most seeds per plane count in the table's error-versus-time sweep.
pub const MAX_SWEEP_SEEDS: u32 = 1000;

/// The most seconds of rendering a part may record (about 32 years): what a merge adds up stays
/// finite.
pub const MAX_RECORDED_SECONDS: f64 = 1e9;

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

/// The share of a light's planes swept along its lobe (docs/mathematics.md section 2.5): 0
/// (the cosine's planes alone) to 1 (the lobe's alone; every direction's density stays
/// positive, so the estimate stays unbiased, but the weights of directions far from the lobe
/// grow large).
pub fn check_lobes(share: f64) -> Result<(), String> {
    if !(0.0..=1.0).contains(&share) {
        let share = crate::error::Number(share);
        return Err(format!("the share of the planes swept along the lobe must be between 0 and 1, got {share}"));
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
        return Err(format!(
            "must be a positive number of seconds up to {max:e}, got {}",
            crate::error::Number(seconds)
        ));
    }
    Ok(())
}

/// Seconds of rendering recorded by a part (a file, a pickle): non-negative, at most
/// [`MAX_RECORDED_SECONDS`] (NaN refused).
pub fn check_recorded_seconds(seconds: f64) -> Result<(), String> {
    if !(0.0..=MAX_RECORDED_SECONDS).contains(&seconds) {
        return Err(format!("{seconds}, not between 0 and {MAX_RECORDED_SECONDS:e}"));
    }
    Ok(())
}

/// An exposure in stops: any finite number (a NaN would turn every pixel black).
pub fn check_exposure(stops: f32) -> Result<(), String> {
    if !stops.is_finite() {
        // An f32: a number beyond about 3.4e38 given as text reads as infinite.
        let beyond = if stops.is_infinite() { " (an infinity, or a number beyond about 3.4e38)" } else { "" };
        return Err(format!("must be a finite number of stops, got {stops}{beyond}"));
    }
    Ok(())
}

pub fn check_sweep_seeds(seeds: u32) -> Result<(), String> {
    if seeds == 0 || seeds > MAX_SWEEP_SEEDS {
        return Err(format!("the seeds per plane count must be between 1 and {MAX_SWEEP_SEEDS}, got {seeds}"));
    }
    Ok(())
}

/// The memory rule of a render of `planes` planes at `width x height` (the scene loader and
/// every front end apply it, through [`crate::settings`]): it holds two windows of canonical
/// chunks' planes at a time (at most [`MAX_CHUNKS_AT_ONCE`] chunks of [`CHUNK_PLANES`] each: the
/// window being gathered and the next, prepared meanwhile), the window's sums (at most
/// [`MAX_WINDOW_PIXELS`] pixels' worth, or one chunk's) and, per pixel, besides
/// [`BYTES_PER_PIXEL`], the second ray set and one f64 sum per level of the canonical tree over
/// its chunks ([`crate::partial`]); so only the image can exceed the memory.
pub fn check_render_memory(width: u32, height: u32, planes: u64) -> Result<(), String> {
    check_render_memory_with(width, height, planes, 0)
}

/// [`check_render_memory`] with `extra` bytes per pixel (an error image's sums).
pub fn check_render_memory_with(width: u32, height: u32, planes: u64, extra: u64) -> Result<(), String> {
    let chunks = planes.div_ceil(CHUNK_PLANES as u64).max(1);
    let levels = (u64::BITS - chunks.leading_zeros()) as u64 + 1;
    let held = planes.min(2 * (MAX_CHUNKS_AT_ONCE * CHUNK_PLANES) as u64);
    let per_pixel = BYTES_PER_PIXEL + 20 + 24 * levels + extra;
    let pixels = width as u64 * height as u64;
    let window = WINDOW_BYTES_PER_PIXEL * pixels.max(MAX_WINDOW_PIXELS as u64);
    let bytes =
        held.saturating_mul(BYTES_PER_PLANE).saturating_add(pixels.saturating_mul(per_pixel)).saturating_add(window);
    budget(width, height, planes, bytes)
}

fn budget(width: u32, height: u32, planes: u64, bytes: u64) -> Result<(), String> {
    if bytes > MEMORY_BUDGET_BYTES {
        return Err(format!(
            "{width}x{height} pixels with {planes} planes would need about {:.1} GiB; the limit is {} GiB",
            bytes as f64 / (1u64 << 30) as f64,
            MEMORY_BUDGET_BYTES >> 30
        ));
    }
    Ok(())
}

/// Refuses, with the figure, work that holds `planes` planes at once (the table, a pass of a render
/// on a time budget) and would exhaust memory.
pub fn check_memory(width: u32, height: u32, planes: u64) -> Result<(), String> {
    let bytes = planes
        .saturating_mul(BYTES_PER_PLANE)
        .saturating_add((width as u64 * height as u64).saturating_mul(BYTES_PER_PIXEL));
    budget(width, height, planes, bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/scenes.md's memory rule, its formula and its figure: at the default planes a square of
    /// 8,752 pixels a side renders and one of 8,753 is refused.
    #[test]
    fn the_memory_rule_is_the_one_the_scene_reference_gives() {
        let documented = |w: u64, h: u64, planes: u64| {
            let chunks = planes.div_ceil(16_384);
            let levels = chunks.ilog2() as u64 + 2;
            planes.min(262_144) * 512 + w * h * (116 + 24 * levels) + (w * h).max(4_194_304) * 36
        };
        let cases =
            [(8752, 8752, DEFAULT_PLANES), (8753, 8753, DEFAULT_PLANES), (640, 360, 1), (20_000, 3_000, 1 << 20)];
        for (w, h, planes) in cases {
            let fits = documented(w, h, planes) <= 16 << 30;
            assert_eq!(check_render_memory(w as u32, h as u32, planes).is_ok(), fits, "{w}x{h}, {planes}");
        }
        assert!(check_render_memory(8752, 8752, DEFAULT_PLANES).is_ok());
        assert!(check_render_memory(8753, 8753, DEFAULT_PLANES).is_err());
        let pixels = (16u64 << 30) - 40_960 * 512;
        assert_eq!((pixels as f64 / (116.0 + 24.0 * 3.0 + 36.0) / 1e7 * 100.0).round() / 100.0, 7.66);
    }

    #[test]
    fn ranges_are_closed_at_both_ends() {
        assert!(check_planes(1).is_ok() && check_planes(MAX_PLANES).is_ok());
        assert!(check_planes(0).is_err() && check_planes(MAX_PLANES + 1).is_err());
        assert!(check_spp(MAX_SPP).is_ok() && check_spp(0).is_err());
        assert!([0.0, 1e-300, 0.5, 1.0].iter().all(|&s| check_lobes(s).is_ok()));
        assert!([-0.0 - 1e-300, 1.0 + 1e-15, f64::NAN, f64::INFINITY].iter().all(|&s| check_lobes(s).is_err()));
        // A share far out of range is told in a few digits, not 300.
        assert!(check_lobes(-1e-300).unwrap_err().ends_with("got -1e-300"));
        assert!(check_lobes(1e300).unwrap_err().ends_with("got 1e300"));
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
