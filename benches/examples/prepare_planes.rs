//! What preparing a plane costs the CPU, step by step (docs/gpu.md, "The planes, prepared on the
//! CPU"): per plane, on one thread, the time to draw its sampler's numbers, to sample it, to clip
//! it to the box, to find the lights that may shadow it, to project its screen polygon, to make its
//! view and occluders for the gather, to make what crosses for the GPU's reach
//! (`gpu::screen_reach`) and to bin it in the CPU's raster. A GPU render pays all but the last, a
//! CPU render all but the GPU's reach; at 655,360 planes they are the CPU's side of the render.
//! Then the render's own preparation, whole (`accel::CpuSide::prepare`, its parallel loops on
//! the threads of the pool: wall time a plane, and the process's CPU time a plane where the
//! platform has a clock for it, idle workers' spinning included), for the GPU and for the
//! raster, piece by piece. The process keeps the memory it frees as the command line's does
//! (`fogplanes::limits::keep_freed_memory`): without it each piece's preparation met fresh
//! pages, and the whole took about 0.9 to 1.1 µs a plane on one thread where the command
//! line's took about 0.55 (2026-12-03, docs/gpu_measurements.md).
//!
//! ```text
//! RAYON_NUM_THREADS=1 cargo run --release -p fogplanes-bench --example prepare_planes -- SCENE [PLANES [PIECE]]
//! ```

use fogplanes::accel::{Accelerator, CpuSide};
use fogplanes::control::Control;
use fogplanes::gather::GatherContext;
use fogplanes::gpu::screen_reach;
use fogplanes::occlusion::occluders_of_polygon;
use fogplanes::photon_plane::{PlaneSet, PlaneSources, sample_plane};
use fogplanes::raster::{ScreenRaster, Tiling, box_polygon, screen_polygon_of};
use fogplanes::sampling::Sampler;
use fogplanes::scene::Scene;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

fn main() -> Result<(), String> {
    fogplanes::limits::keep_freed_memory();
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        return Err("usage: prepare_planes SCENE [PLANES [PIECE]]".into());
    };
    let n: usize = match args.get(2) {
        Some(n) => n.parse().map_err(|_| format!("{n}: expected a number of planes"))?,
        None => 40_960,
    };
    let piece_planes: usize = match args.get(3) {
        Some(n) => {
            n.parse().ok().filter(|&n| n > 0).ok_or_else(|| format!("{n}: expected a number of planes a piece"))?
        }
        None => 2_560,
    };
    let scene = Scene::load(Path::new(path)).map_err(|e| e.to_string())?;
    let (cam, medium) = (&scene.camera, &scene.medium);
    let set = Sampler::default().numbers(1);
    let sources = PlaneSources::new(&scene, fogplanes::limits::DEFAULT_LOBES);
    // Timed in pieces, as a render prepares its planes (the benchmark's 40,960 planes are 16
    // pieces of 2,560, one per ray set, each with its own view and raster), each step's results
    // kept in vectors reused from piece to piece (not faulted in anew: the renderer keeps none
    // of them but the view and the raster).
    let (mut numbers, mut planes, mut world, mut masks, mut screen, mut reach) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut steps: Vec<(&str, f64)> = Vec::new();
    let mut time = |step: usize, name: &'static str, t: Instant| {
        if steps.len() <= step {
            steps.push((name, 0.0));
        }
        steps[step].1 += t.elapsed().as_secs_f64() * 1e9 / n.max(1) as f64;
    };
    for start in (0..n).step_by(piece_planes) {
        let piece = start as u64..(start + piece_planes).min(n) as u64;
        let t = Instant::now();
        numbers.clear();
        numbers.extend(piece.map(|i| set.plane(i)));
        time(0, "the sampler's numbers", t);
        let t = Instant::now();
        planes.clear();
        planes.extend(numbers.iter().map(|u| sample_plane(&scene, &sources, *u)));
        time(1, "the plane sampled", t);
        let t = Instant::now();
        world.clear();
        world.extend(planes.iter().map(|p| box_polygon(p, medium)));
        time(2, "its polygon in the box", t);
        let t = Instant::now();
        masks.clear();
        masks.extend(planes.iter().zip(&world).map(|(p, w)| occluders_of_polygon(&scene, p, w)));
        time(3, "the lights that may shadow it", t);
        let t = Instant::now();
        screen.clear();
        screen.extend(world.iter().map(|w| screen_polygon_of(cam, w, medium)));
        time(4, "its screen polygon", t);
        let t = Instant::now();
        let mut context = GatherContext::empty(&scene, cam.position);
        context.push_planes_with_occluders(&scene, &planes, &masks, 1);
        time(5, "its view and occluders", t);
        let t = Instant::now();
        reach.clear();
        reach.extend(screen.iter().map(|p| screen_reach(p, cam.width, cam.height)));
        time(6, "what crosses for the GPU's reach", t);
        black_box(&reach);
        black_box(&context);
        let t = Instant::now();
        let mut raster = ScreenRaster::empty(cam);
        raster.push_projected_in(&planes, |i| &screen[i], Control::none());
        time(7, "binned in the CPU's raster", t);
        black_box(&raster);
    }

    println!(
        "{path} at {}x{}, {n} planes in pieces of {piece_planes}, ns a plane (on this thread; the views' \
         and the raster's parallel loops on the pool's {} threads):",
        cam.width,
        cam.height,
        rayon::current_num_threads()
    );
    for (name, ns) in &steps {
        println!("  {ns:8.1}  {name}");
    }
    let sum = |skip: &str| steps.iter().filter(|(s, _)| *s != skip).map(|(_, ns)| ns).sum::<f64>();
    println!(
        "  {:8.1}  a GPU render's (all but the raster), {:.1} a CPU render's (all but the GPU's reach)",
        sum("binned in the CPU's raster"),
        sum("what crosses for the GPU's reach")
    );

    // The render's own preparation, piece by piece as above, on the pool's threads.
    let set = PlaneSet::new(Sampler::default(), 1);
    let threads = rayon::current_num_threads();
    println!(
        "the render's own preparation (accel::CpuSide::prepare) on {threads} threads, the command line's \
         allocator settings, ns a plane:"
    );
    for (name, accelerator) in [("for the GPU", Accelerator::Gpu(0)), ("for the raster", Accelerator::Raster)] {
        let tiling = Tiling::new(cam.width, cam.height, threads);
        let (wall, cpu) = (Instant::now(), process_cpu_seconds());
        // On a thread of the pool, as a render prepares its pieces: its parallel loops are not
        // injected from outside one by one, each waking a worker.
        rayon::scope(|_| {
            for start in (0..n).step_by(piece_planes) {
                let range = start..(start + piece_planes).min(n);
                let side = CpuSide::prepare(&scene, set, range, accelerator, tiling, Control::none())
                    .map_err(|e| e.to_string())?;
                black_box(&side);
            }
            Ok::<(), String>(())
        })?;
        let per_plane = |seconds: f64| seconds * 1e9 / n.max(1) as f64;
        let cpu = process_cpu_seconds().zip(cpu).map(|(b, a)| format!(", {:.1} of CPU", per_plane(b - a)));
        println!("  {:8.1}  wall{}  {name}", per_plane(wall.elapsed().as_secs_f64()), cpu.unwrap_or_default());
    }
    Ok(())
}

/// The process's CPU seconds (user and system, every thread), where the platform says.
fn process_cpu_seconds() -> Option<f64> {
    #[cfg(unix)]
    {
        let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: clock_gettime writes the timespec it is given, and nothing else.
        if unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) } == 0 {
            return Some(t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9);
        }
    }
    None
}
