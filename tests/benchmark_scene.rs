//! Every estimator on the benchmark scene at reduced resolution gives only finite,
//! non-negative pixels.

use crate::common::options;
use fogplanes::control::Control;
use fogplanes::render::render;
use fogplanes::scene::Scene;
use fogplanes::settings::Overrides;
use fogplanes::weights::Weighting;

#[test]
fn every_estimator_gives_finite_non_negative_pixels() {
    let s =
        Scene::load(std::path::Path::new("media_scenes/six_lights.toml")).unwrap().with_resolution(160, 90).unwrap();
    for w in Weighting::all(&[1, 3, 4, 8]) {
        let opts = options(
            &s,
            Overrides {
                planes: Some(10_240),
                estimator: Some(w.estimator),
                orientations: Some(w.orientations),
                ..Overrides::default()
            },
        );
        let (film, stats) = render(&s, &opts, Control::none()).unwrap();
        assert!(film.all_finite_non_negative(), "{w}: a pixel is negative, NaN or infinite");
        assert!(film.mean() > 0.01 && stats.hits > 1_000_000, "{w}: mean {} hits {}", film.mean(), stats.hits);
        println!("{}: mean {:.5} max {:.3}", w, film.mean(), film.max());
    }
}
