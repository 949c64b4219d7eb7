//! How long a render takes to stop once cancelled: sets the flag from another thread after a
//! delay and prints the time from setting it to the render's return (a measurement, not a
//! test). `cargo run --release -p fogplanes-bench --example cancel_latency -- SCENE [PLANES]`.

use fogplanes::accel::Accelerator;
use fogplanes::control::Control;
use fogplanes::reference::{ReferenceOptions, render_reference};
use fogplanes::render::{render, render_for};
use fogplanes::scene::Scene;
use fogplanes::settings::Overrides;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// Runs `job` with a flag set after `delay`; returns (units of progress before, latency).
fn cancel_after(delay: Duration, job: impl FnOnce(Control) -> fogplanes::Result<()> + Send) -> (usize, Duration) {
    let (cancel, units) = (AtomicBool::new(false), AtomicUsize::new(0));
    let progress = || {
        units.fetch_add(1, Ordering::Relaxed);
    };
    std::thread::scope(|s| {
        let worker = s.spawn(|| {
            let r = job(Control::new(&progress, &cancel));
            (r, Instant::now())
        });
        std::thread::sleep(delay);
        let set = Instant::now();
        let before = units.load(Ordering::Relaxed);
        cancel.store(true, Ordering::Relaxed);
        let (result, returned) = worker.join().unwrap();
        assert!(matches!(result, Err(fogplanes::Error::Cancelled)), "the job ended before the flag");
        (before, returned - set)
    })
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene = Scene::load(std::path::Path::new(&args[1])).unwrap();
    let planes: usize = args.get(2).map_or(2_000_000, |p| p.parse().unwrap());
    for (accelerator, delays) in [
        (Accelerator::Raster, &[0.5, 2.0, 8.0, 20.0][..]),
        (Accelerator::Bvh, &[1.0, 8.0]),
        (Accelerator::BruteForce, &[8.0]),
    ] {
        for &d in delays {
            let given =
                Overrides { planes: Some(planes as u64), accelerator: Some(accelerator), ..Overrides::default() };
            let opts = given.resolve(&scene).unwrap().options;
            let (units, latency) = cancel_after(Duration::from_secs_f64(d), |c| render(&scene, &opts, c).map(|_| ()));
            println!(
                "render {planes} planes {accelerator}: cancelled after {d} s ({units} units done), stopped in {:.1} ms",
                latency.as_secs_f64() * 1e3
            );
        }
    }
    for d in [0.5, 3.0, 10.0] {
        let opts = Overrides::default().resolve(&scene).unwrap().options;
        let (units, latency) = cancel_after(Duration::from_secs_f64(d), |c| {
            render_for(&scene, &opts, Duration::from_secs(3600), c).map(|_| ())
        });
        println!(
            "render_for 1 h budget: cancelled after {d} s ({units} units done), stopped in {:.1} ms",
            latency.as_secs_f64() * 1e3
        );
    }
    for d in [0.5, 3.0] {
        let opts = ReferenceOptions { spp: 1024, uniform: false, seed: 1, pixel_center: false };
        let (units, latency) =
            cancel_after(Duration::from_secs_f64(d), |c| render_reference(&scene, &opts, c).map(|_| ()));
        println!(
            "reference 1024 spp: cancelled after {d} s ({units} rows done), stopped in {:.1} ms",
            latency.as_secs_f64() * 1e3
        );
    }
}
