//! The MSE of images against a reference, over the whole image and over the glow: the pixels
//! more than two pixels away from any pixel that sees a light directly (the "Whole pixels"
//! figures of docs/measurements.md). The mask comes from the scene's geometry (the direct emission over each
//! pixel), not from the images. Also prints the reference's own noise over both regions, the
//! mean square of its standard-error image, which every MSE against it includes.
//!
//! ```text
//! cargo run --release -p fogplanes-bench --example glow_mse -- SCENE WxH REF.exr REF_STDERR.exr IMAGE.exr...
//! ```

use fogplanes::film::Film;
use fogplanes::scene::Scene;
use std::path::Path;

/// Pixels this close to a pixel that sees a light (in either direction) are not glow.
const MARGIN: i64 = 2;

fn load(path: &str) -> Result<Film, String> {
    Film::load_exr(Path::new(path)).map_err(|e| format!("{path}: {e}"))
}

/// The mean of `f(pixel index, channel)` over the channels of the pixels `mask` keeps.
fn mean(pixels: usize, mask: Option<&[bool]>, f: impl Fn(usize, usize) -> f64) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for k in (0..pixels).filter(|&k| mask.is_none_or(|m| m[k])) {
        for c in 0..3 {
            sum += f(k, c);
            n += 1;
        }
    }
    sum / n.max(1) as f64
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 6 {
        return Err("usage: glow_mse SCENE WxH REF.exr REF_STDERR.exr IMAGE.exr...".into());
    }
    let (w, h) = args[2]
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
        .ok_or_else(|| format!("{}: expected WxH", args[2]))?;
    let scene = Scene::load(Path::new(&args[1])).map_err(|e| e.to_string())?;
    let scene = scene.with_resolution(w, h).map_err(|e| e.to_string())?;
    let (reference, stderr) = (load(&args[3])?, load(&args[4])?);
    let emission = fogplanes::emission::direct_emission(&scene, 1, 16, false);
    let (w, h) = (w as i64, h as i64);
    let mut glow = vec![true; (w * h) as usize];
    for j in 0..h {
        for i in 0..w {
            if emission[(j * w + i) as usize].max_element() > 0.0 {
                for b in (j - MARGIN).max(0)..=(j + MARGIN).min(h - 1) {
                    for a in (i - MARGIN).max(0)..=(i + MARGIN).min(w - 1) {
                        glow[(b * w + a) as usize] = false;
                    }
                }
            }
        }
    }
    let pixels = glow.len();
    let fraction = glow.iter().filter(|&&g| g).count() as f64 / pixels as f64;
    let noise = |mask| mean(pixels, mask, |k, c| (stderr.pixels[k][c] as f64).powi(2));
    println!(
        "glow: {:.1}% of the pixels; the reference's noise: MSE whole {:.3e}, glow {:.3e}",
        100.0 * fraction,
        noise(None),
        noise(Some(&glow))
    );
    for path in &args[5..] {
        let image = load(path)?;
        if image.pixels.len() != pixels {
            return Err(format!("{path}: not {w}x{h}"));
        }
        let mse = |mask| mean(pixels, mask, |k, c| ((image.pixels[k][c] - reference.pixels[k][c]) as f64).powi(2));
        println!("{path}: MSE whole {:.3e}, glow {:.3e}", mse(None), mse(Some(&glow)));
    }
    Ok(())
}
