//! Criterion benchmarks: plane sampling, structure build, gathering per estimator, and the
//! per-hit cost of each weighting. `cargo bench -p fogplanes-bench` runs them all; `cargo bench -p
//! fogplanes-bench -- weight` one group.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use fogplanes::accel::{Accelerator, PreparedPlanes};
use fogplanes::control::Control;
use fogplanes::gather::GatherContext;
use fogplanes::kernel::Kernel;
use fogplanes::photon_plane::PlaneSet;
use fogplanes::photon_plane::sample_planes;
use fogplanes::pixel::ray_set_rays;
use fogplanes::raster::ScreenRaster;
use fogplanes::sampling::Sampler;
use fogplanes::scene::Scene;
use fogplanes::weights::{Denominator, HitLocal, PlaneFrame, Weighting, WithDenominator};
use glam::Vec3;
use std::hint::black_box;
use std::time::Duration;

fn scene() -> Scene {
    Scene::load(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../media_scenes/six_lights.toml"))).unwrap()
}

fn planes_and_structure(c: &mut Criterion) {
    let s = scene();
    let mut g = c.benchmark_group("setup");
    g.sample_size(10).measurement_time(Duration::from_secs(5));
    g.bench_function("sample 40960 planes", |b| b.iter(|| sample_planes(&s, Sampler::default(), 40_960, black_box(1))));
    let planes = sample_planes(&s, Sampler::default(), 40_960, 1);
    g.bench_function("prepare 40960 plane views", |b| {
        b.iter(|| GatherContext::new(&s, black_box(&planes), s.camera.position))
    });
    g.bench_function("raster 40960 planes at 640x360", |b| {
        b.iter(|| ScreenRaster::build(&s.camera, black_box(&planes), &s.medium))
    });
    g.finish();
}

fn gathering(c: &mut Criterion) {
    let s = scene().with_resolution(160, 90).unwrap();
    let prepared =
        PreparedPlanes::new(&s, PlaneSet::new(Sampler::default(), 1), 0..40_960, Accelerator::Raster, Control::none())
            .unwrap();
    let rays = ray_set_rays(&s, 1, 0, false);
    let mut sums = vec![Vec3::ZERO; rays.len()];
    let kernel = Kernel::Auto.resolve().unwrap();
    let hits = prepared.gather(Weighting::default(), kernel, &rays, &mut sums, Control::none()).unwrap().hits;
    let mut g = c.benchmark_group("gather 160x90, 40960 planes");
    g.sample_size(10).measurement_time(Duration::from_secs(4)).throughput(Throughput::Elements(hits));
    let raster = prepared.raster().unwrap();
    g.bench_function("intersections only", |b| {
        b.iter(|| raster.count_hits(prepared.context(), kernel, black_box(&rays)))
    });
    for w in Weighting::all(&[4]) {
        g.bench_function(BenchmarkId::from_parameter(w.label()), |b| {
            b.iter(|| prepared.gather(w, kernel, &rays, black_box(&mut sums), Control::none()))
        });
    }
    g.finish();
}

/// Real hits of the benchmark scene: (frame, hit) pairs from rays through the image.
fn sample_hits(n: usize) -> Vec<(PlaneFrame, HitLocal)> {
    let s = scene().with_resolution(32, 18).unwrap();
    let planes = sample_planes(&s, Sampler::default(), 40_960, 2);
    let ctx = GatherContext::new(&s, &planes, s.camera.position);
    let rays = ray_set_rays(&s, 2, 0, false);
    let mut out = Vec::with_capacity(n);
    'rays: for ray in &rays {
        for v in &ctx.views {
            let h = v.crossing(ray.dir.to_array(), ray.t0, ray.t1);
            if h.hit {
                out.push((v.frame, HitLocal { det: h.det, det_perp: ray.dir.dot(v.normal_perp), a: h.a }));
                if out.len() == n {
                    break 'rays;
                }
            }
        }
    }
    out
}

/// Times one weighting's D over a list of real hits.
struct PerHit<'a, 'g> {
    group: &'a mut criterion::BenchmarkGroup<'g, criterion::measurement::WallTime>,
    name: String,
    hits: &'a [(PlaneFrame, HitLocal)],
}

impl WithDenominator for PerHit<'_, '_> {
    type Output = ();
    fn run<D: Denominator>(self, d: &D) {
        let hits = self.hits;
        self.group.bench_function(self.name, |b| {
            b.iter(|| {
                let mut acc = 0.0f32;
                for (f, h) in hits {
                    acc += d.denominator(black_box(f), black_box(h));
                }
                acc
            })
        });
    }
}

fn weights(c: &mut Criterion) {
    let hits = sample_hits(4096);
    let mut g = c.benchmark_group("weight per hit");
    g.throughput(Throughput::Elements(hits.len() as u64)).measurement_time(Duration::from_secs(3));
    for w in Weighting::all(&[4, 8]) {
        w.dispatch(PerHit { group: &mut g, name: w.label(), hits: &hits });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    // No HTML plots: they need system fonts, which a fresh machine may lack.
    config = Criterion::default().without_plots();
    targets = weights, planes_and_structure, gathering
}
criterion_main!(benches);
