//! What the GPU's reach costs and saves on a scene's planes (docs/gpu.md, "The planes, prepared on
//! the CPU"): per plane, the CPU's time to project and clip its screen polygon, to find its reach
//! on the CPU (`gpu::tile_reach`, the specification) and to make what crosses for the GPU to find
//! it there (`gpu::screen_reach`); the rows of tiles, (tile, plane) pairs and tested pixels of the
//! reach, the bound on the pairs that sizes the binning's buffers, the gather's warps that test a
//! plane and the share of their lanes that its columns fill, and the vertices that cross.
//!
//! ```text
//! cargo run --release -p fogplanes-bench --example screen_reach -- SCENE [PLANES]
//! ```

use fogplanes::gpu::{screen_reach, tile_reach};
use fogplanes::photon_plane::sample_planes;
use fogplanes::raster::screen_polygon;
use fogplanes::scene::Scene;
use std::path::Path;
use std::time::Instant;

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        return Err("usage: screen_reach SCENE [PLANES]".into());
    };
    let n: usize = match args.get(2) {
        Some(n) => n.parse().map_err(|_| format!("{n}: expected a number of planes"))?,
        None => 40_960,
    };
    let scene = Scene::load(Path::new(path)).map_err(|e| e.to_string())?;
    let (cam, medium) = (&scene.camera, &scene.medium);
    let planes = sample_planes(&scene, Default::default(), n, 1);
    // One thread each, timed apart.
    let per_plane = |t: Instant| t.elapsed().as_secs_f64() * 1e6 / n.max(1) as f64;
    let t = Instant::now();
    let polygons: Vec<_> = planes.iter().map(|p| screen_polygon(cam, p, medium)).collect();
    let polygon_us = per_plane(t);
    let t = Instant::now();
    let reach: Vec<_> = polygons.iter().map(|p| tile_reach(p, cam.width, cam.height)).collect();
    let reach_us = per_plane(t);
    let t = Instant::now();
    let crossing: Vec<_> = polygons.iter().map(|p| screen_reach(p, cam.width, cam.height)).collect();
    let crossing_us = per_plane(t);
    let rows: usize = reach.iter().map(|r| r.spans.len()).sum();
    let pairs: u64 = reach.iter().map(|r| r.tiles()).sum();
    let tests: u64 = reach.iter().map(|r| r.tests(cam.height)).sum();
    let bound: u64 = crossing.iter().map(|c| c.pairs).sum();
    let warps = |blocks: bool| reach.iter().map(|r| r.warps(cam.width, cam.height, blocks)).sum::<u64>();
    let (by_rows, by_blocks) = (warps(false), warps(true));
    let vertices: usize = crossing.iter().filter(|c| c.rows > 0).map(|c| c.polygon.len).sum();
    println!("{path} at {}x{}, {n} planes (one thread):", cam.width, cam.height);
    println!(
        "  screen polygon {polygon_us:.3} us a plane, reach on the CPU {reach_us:.3} us, what crosses for the GPU's {crossing_us:.3} us"
    );
    println!(
        "  {rows} rows of tiles ({:.1} a plane), {pairs} pairs, bound {bound} ({:.2} times), {tests} pixels tested",
        rows as f64 / n.max(1) as f64,
        bound as f64 / pairs.max(1) as f64
    );
    let filled = |warps: u64| tests as f64 / (32 * warps.max(1)) as f64;
    println!(
        "  the gather's warps of 32 lanes that test a plane: {by_rows} by rows, {:.1}% of their lanes in its columns; {by_blocks} by blocks of 8 x 4, {:.1}%",
        100.0 * filled(by_rows),
        100.0 * filled(by_blocks)
    );
    println!(
        "  {vertices} vertices cross ({:.2} a plane, {} bytes) instead of the rows ({} bytes)",
        vertices as f64 / n.max(1) as f64,
        vertices * 8,
        rows * 20
    );
    Ok(())
}
