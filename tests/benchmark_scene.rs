//! Every estimator on the benchmark scene at reduced resolution gives only finite,
//! non-negative pixels.

use fogplanes::render::{Accelerator, RenderOptions, render};
use fogplanes::scene::Scene;
use fogplanes::weights::{Estimator, Weighting};

#[test]
fn every_estimator_gives_finite_non_negative_pixels() {
    let s =
        Scene::load(std::path::Path::new("media_scenes/six_lights.toml")).unwrap().with_resolution(160, 90).unwrap();
    let mut weightings: Vec<Weighting> = Estimator::ALL.iter().map(|&e| Weighting::new(e, None).unwrap()).collect();
    for k in [1, 3, 4, 8] {
        weightings.push(Weighting::new(Estimator::SmisExact, Some(k)).unwrap());
        weightings.push(Weighting::new(Estimator::SmisCosine, Some(k)).unwrap());
    }
    for w in weightings {
        let opts = RenderOptions {
            planes: 10_240,
            weighting: w,
            seed: 1,
            spp: 1,
            pixel_center: false,
            accelerator: Accelerator::Raster,
        };
        let (film, stats) = render(&s, &opts, &|| {});
        assert!(film.all_finite_non_negative(), "{w}: a pixel is negative, NaN or infinite");
        assert!(film.mean() > 0.01 && stats.hits > 1_000_000, "{w}: mean {} hits {}", film.mean(), stats.hits);
        println!("{}: mean {:.5} max {:.3}", w, film.mean(), film.max());
    }
}
