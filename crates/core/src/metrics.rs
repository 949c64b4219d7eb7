//! Error metrics (docs/mathematics.md section 5, as in the paper's Section 4.4 and Fig. 11).

use crate::error::{Error, Result};
use crate::film::Film;

/// The error of an image against a reference, over all pixels and channels.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ErrorMetrics {
    /// mean |r - e| / (|r| + |e|), a term with both zero counting 0.
    pub smape: f64,
    /// mean (e - r)^2.
    pub mse: f64,
    /// mean (e - r)^2 / (r^2 + 1e-2), relative MSE with the usual regulariser.
    pub rel_mse: f64,
    /// max |e - r|.
    pub max_abs_error: f64,
}

impl ErrorMetrics {
    /// SMAPE x 10^2 and MSE x 10^4, as the paper prints them.
    pub fn smape_e2(&self) -> f64 {
        self.smape * 1e2
    }
    pub fn mse_e4(&self) -> f64 {
        self.mse * 1e4
    }
}

/// Compares `image` against `reference`; they must have the same size and hold only finite
/// values.
///
/// A NaN or infinite value is refused ([`Error::NonFinitePixel`], naming the first one, image
/// before reference), not skipped and not propagated: skipped, an image of nothing but NaN
/// would score 0 (`f64::max` and a zero-denominator test both pass NaN over); propagated, one
/// bad pixel would turn every metric into NaN and say nothing of where it is.
pub fn compare(image: &Film, reference: &Film) -> Result<ErrorMetrics> {
    if (image.width, image.height) != (reference.width, reference.height) {
        return Err(Error::SizeMismatch {
            image: (image.width, image.height),
            reference: (reference.width, reference.height),
        });
    }
    image.check_finite("image")?;
    reference.check_finite("reference")?;
    let (mut smape, mut mse, mut rel, mut max) = (0.0, 0.0, 0.0, 0.0f64);
    for (e, r) in image.pixels.iter().zip(&reference.pixels) {
        for c in 0..3 {
            let (e, r) = (e[c] as f64, r[c] as f64);
            let denom = r.abs() + e.abs();
            if denom > 0.0 {
                smape += (r - e).abs() / denom;
            }
            let d2 = (e - r) * (e - r);
            mse += d2;
            rel += d2 / (r * r + 1e-2);
            max = max.max((e - r).abs());
        }
    }
    let n = 3.0 * image.pixels.len().max(1) as f64;
    Ok(ErrorMetrics { smape: smape / n, mse: mse / n, rel_mse: rel / n, max_abs_error: max })
}

/// A comparison against a noisy reference that accounts for its noise (docs/mathematics.md
/// section 10.4): `compare --ref-stderr`.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct NoisyComparison {
    /// mean (e - r)^2, as [`ErrorMetrics::mse`].
    pub mse: f64,
    /// mean s_r^2: what the reference's own noise adds to `mse` in expectation.
    pub reference_noise: f64,
    /// `mse - reference_noise`: an unbiased estimate of the image's MSE against the truth.
    pub mse_minus_reference_noise: f64,
    /// mean s_e^2, the image's own predicted variance, when its error image is given.
    pub image_noise: Option<f64>,
    /// `mse - reference_noise - image_noise`: what noise does not explain (bias^2 and
    /// misestimated noise); about 0 when both error images are right and the image unbiased.
    pub excess: Option<f64>,
    /// mean z^2 over pixels and channels, z = (e - r) / sqrt(s_r^2 + s_e^2): about 1 when the
    /// noise explains the difference.
    pub mean_z2: f64,
    /// The fraction of values with |z| > 3 (0.27% for normal noise).
    pub beyond_3: f64,
    /// The regions whose excess is largest, largest first.
    pub regions: Vec<Region>,
}

/// A connected group of pixels whose difference the noise does not explain: the pixels with
/// |z| > 2 in some channel, joined to their eight neighbours.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Region {
    /// Its bounding box: first column and row, last column and row.
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
    pub pixels: usize,
    /// Sum over its pixels and channels of (e - r)^2 - s_r^2 - s_e^2.
    pub excess: f64,
    /// Sum over its pixels and channels of s_r^2 + s_e^2.
    pub noise: f64,
    /// Mean of (e - r) / sqrt(s_r^2 + s_e^2) over its pixels and channels: the sign says
    /// which side is higher.
    pub mean_z: f64,
}

/// The largest |z| of [`compare_noisy`]'s z-image: a finite f32, whatever the noise.
const Z_MAX: f64 = 1e30;

/// Refuses a standard error per pixel, `what` ("reference's standard error"), that is not the
/// size of `image` or holds what no standard error is (NaN, an infinity, a negative value),
/// naming the first such pixel.
pub fn check_stderr(stderr: &Film, image: &Film, what: &str) -> Result<()> {
    if (stderr.width, stderr.height) != (image.width, image.height) {
        // Not Error::SizeMismatch, which would call it the reference.
        return Err(Error::NotComparable(format!(
            "the {what} is {}x{} pixels, the image {}x{}",
            stderr.width, stderr.height, image.width, image.height
        )));
    }
    if let Some(bad) = stderr.first_outside(f64::from(f32::MAX)) {
        return Err(Error::NotComparable(format!("the {what} holds {bad}: a standard error is a non-negative number")));
    }
    Ok(())
}

/// Compares `image` against `reference`, whose standard error per pixel is `reference_stderr`
/// (and the image's `image_stderr`, if known): the MSE with the reference's noise subtracted,
/// per-pixel z-scores (returned as an image: z per channel, 0 where both errors are 0 and the
/// values agree) and the `regions` regions whose excess is largest. Every image must have the
/// same size and hold finite values, the errors non-negative.
pub fn compare_noisy(
    image: &Film,
    reference: &Film,
    reference_stderr: &Film,
    image_stderr: Option<&Film>,
    regions: usize,
) -> Result<(NoisyComparison, Film)> {
    let m = compare(image, reference)?;
    check_stderr(reference_stderr, image, "reference's standard error")?;
    if let Some(e) = image_stderr {
        check_stderr(e, image, "image's standard error")?;
    }
    let (w, h) = (image.width as usize, image.height as usize);
    let mut z = Film::new(image.width, image.height);
    let (mut reference_noise, mut image_noise, mut z2, mut beyond) = (0.0, 0.0, 0.0, 0usize);
    let mut flagged = vec![false; w * h];
    for (p, flag) in flagged.iter_mut().enumerate() {
        for c in 0..3 {
            let d = image.pixels[p][c] as f64 - reference.pixels[p][c] as f64;
            let sr2 = (reference_stderr.pixels[p][c] as f64).powi(2);
            let se2 = image_stderr.map_or(0.0, |e| (e.pixels[p][c] as f64).powi(2));
            reference_noise += sr2;
            image_noise += se2;
            // Held to +-1e30, as where there is no noise: a difference of 3e38 over a
            // standard error of 1e-45 (2e83) was an infinity in the z-image.
            let zc = if sr2 + se2 > 0.0 {
                (d / (sr2 + se2).sqrt()).clamp(-Z_MAX, Z_MAX)
            } else if d == 0.0 {
                0.0
            } else {
                d.signum() * Z_MAX
            };
            z.pixels[p][c] = zc as f32;
            // Either sign alike (`min` alone let a negative z of 1e30 add 1e60).
            z2 += zc.clamp(-1e15, 1e15).powi(2);
            beyond += (zc.abs() > 3.0) as usize;
            *flag |= zc.abs() > 2.0;
        }
    }
    let n = 3.0 * (w * h).max(1) as f64;
    let (reference_noise, image_noise) = (reference_noise / n, image_noise / n);
    let mut found = Vec::new();
    let mut seen = vec![false; w * h];
    for start in 0..w * h {
        if !flagged[start] || seen[start] {
            continue;
        }
        let mut r = Region { x0: u32::MAX, y0: u32::MAX, ..Region::default() };
        let mut stack = vec![start];
        seen[start] = true;
        while let Some(p) = stack.pop() {
            let (x, y) = (p % w, p / w);
            (r.x0, r.y0) = (r.x0.min(x as u32), r.y0.min(y as u32));
            (r.x1, r.y1) = (r.x1.max(x as u32), r.y1.max(y as u32));
            r.pixels += 1;
            for c in 0..3 {
                let d = image.pixels[p][c] as f64 - reference.pixels[p][c] as f64;
                let noise = (reference_stderr.pixels[p][c] as f64).powi(2)
                    + image_stderr.map_or(0.0, |e| (e.pixels[p][c] as f64).powi(2));
                r.excess += d * d - noise;
                r.noise += noise;
                r.mean_z += z.pixels[p][c] as f64;
            }
            for (dx, dy) in [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)] {
                let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                    continue;
                }
                let q = ny as usize * w + nx as usize;
                if flagged[q] && !seen[q] {
                    seen[q] = true;
                    stack.push(q);
                }
            }
        }
        r.mean_z /= 3.0 * r.pixels as f64;
        found.push(r);
    }
    found.sort_by(|a, b| b.excess.total_cmp(&a.excess));
    found.truncate(regions);
    let comparison = NoisyComparison {
        mse: m.mse,
        reference_noise,
        mse_minus_reference_noise: m.mse - reference_noise,
        image_noise: image_stderr.map(|_| image_noise),
        excess: image_stderr.map(|_| m.mse - reference_noise - image_noise),
        mean_z2: z2 / n,
        beyond_3: beyond as f64 / n,
        regions: found,
    };
    Ok((comparison, z))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn film(values: &[[f32; 3]]) -> Film {
        Film { width: values.len() as u32, height: 1, pixels: values.iter().map(|v| Vec3::from_array(*v)).collect() }
    }

    #[test]
    fn known_answers() {
        let r = film(&[[1.0, 0.0, 2.0], [0.5, 0.5, 0.5]]);
        let e = film(&[[3.0, 0.0, 2.0], [0.5, 1.5, 0.5]]);
        let m = compare(&e, &r).unwrap();
        // SMAPE terms: 2/4, 0 (both zero), 0, 0, 1/2, 0.
        assert!((m.smape - 1.0 / 6.0).abs() < 1e-12);
        // Squared errors: 4, 0, 0, 0, 1, 0.
        assert!((m.mse - 5.0 / 6.0).abs() < 1e-12);
        assert!((m.rel_mse - (4.0 / 1.01 + 1.0 / 0.26) / 6.0).abs() < 1e-9);
        assert_eq!(m.max_abs_error, 2.0);
        assert!((m.smape_e2() - 100.0 / 6.0).abs() < 1e-9);
        assert_eq!(compare(&r, &r).unwrap(), ErrorMetrics::default());
        assert!(compare(&r, &film(&[[0.0; 3]])).is_err());
    }

    /// Skipped, an all-NaN image scored 0 against anything; now the first bad value is named.
    #[test]
    fn non_finite_values_are_refused_and_named() {
        let r = film(&[[1.0, 0.0, 2.0], [0.5, 0.5, 0.5]]);
        let all_nan = film(&[[f32::NAN; 3]; 2]);
        let e = compare(&all_nan, &r).unwrap_err();
        assert!(e.is_input());
        assert_eq!(
            e.to_string(),
            "the image holds a value that is not a finite number: pixel (x 0, y 0) channel R is NaN"
        );
        let e = compare(&r, &all_nan).unwrap_err().to_string();
        assert!(e.starts_with("the reference holds"), "{e}");
        let one_inf = film(&[[1.0, 0.0, 2.0], [0.5, f32::NEG_INFINITY, 0.5]]);
        let e = compare(&one_inf, &r).unwrap_err().to_string();
        assert!(e.ends_with("pixel (x 1, y 0) channel G is -inf"), "{e}");
        assert!(compare(&r, &one_inf).is_err());
    }

    /// A synthetic case with a known answer: truth t, a reference t + noise of deviation s_r
    /// (its error image s_r), an image t + noise of deviation s_e plus a bias b over a 6 x 5
    /// block. Over 256 x 256 pixels the MSE minus the reference's noise is s_e^2 plus the
    /// block's share of b^2, within 4 standard errors; with the image's error image the excess
    /// is the block's b^2 alone; and the largest region found is the block.
    #[test]
    fn noise_is_subtracted_and_the_biased_block_is_found() {
        use crate::sampling::{rng_for, unit_f64};
        use rand::RngCore;
        let (w, h) = (256u32, 256u32);
        let mut rng = rng_for(3, 0, 0);
        let mut gauss = || {
            let (u, v) = (unit_f64(rng.next_u64()).max(1e-300), unit_f64(rng.next_u64()));
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        let (sr, se, b) = (0.02f64, 0.01f64, 0.5f64);
        let block = |x: u32, y: u32| (100..106).contains(&x) && (40..45).contains(&y);
        let mut image = Film::new(w, h);
        let mut reference = Film::new(w, h);
        let mut sq = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let p = (y * w + x) as usize;
                for c in 0..3 {
                    let t = 1.0 + 0.5 * c as f64;
                    let r = t + sr * gauss();
                    let e = t + se * gauss() + if block(x, y) { b } else { 0.0 };
                    reference.pixels[p][c] = r as f32;
                    image.pixels[p][c] = e as f32;
                    sq.push((e - r) * (e - r) - sr * sr);
                }
            }
        }
        let ref_se = Film { width: w, height: h, pixels: vec![Vec3::splat(sr as f32); (w * h) as usize] };
        let img_se = Film { width: w, height: h, pixels: vec![Vec3::splat(se as f32); (w * h) as usize] };
        let n = sq.len() as f64;
        let mean = sq.iter().sum::<f64>() / n;
        let sd = (sq.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let tolerance = 4.0 * sd / n.sqrt();
        let block_share = b * b * 30.0 / (w * h) as f64;
        let (m, z) = compare_noisy(&image, &reference, &ref_se, None, 5).unwrap();
        assert!((m.mse_minus_reference_noise - (se * se + block_share)).abs() < tolerance, "{m:?}");
        let (m, _) = compare_noisy(&image, &reference, &ref_se, Some(&img_se), 5).unwrap();
        let excess = m.excess.unwrap();
        assert!((excess - block_share).abs() < tolerance, "{excess} against {block_share} +- {tolerance}");
        // Beyond the block, z is standard normal: mean z^2 near 1 (the block adds 90 values of
        // about (0.5 / 0.0224)^2 = 500 each to 196,608).
        let expected_z2 = 1.0 + 90.0 * (b * b / (sr * sr + se * se)) / n;
        assert!((m.mean_z2 - expected_z2).abs() < 0.05 * expected_z2, "{} against {expected_z2}", m.mean_z2);
        // The largest region holds the block (and perhaps a few noisy neighbours, |z| > 2 in
        // one channel of 4.5% of values), and its excess is the block's 90 values of b^2.
        let top = &m.regions[0];
        assert!(top.x0 <= 100 && top.y0 <= 40 && top.x1 >= 105 && top.y1 >= 44 && top.pixels <= 45, "{top:?}");
        assert!((top.excess - 90.0 * b * b).abs() < 0.1 * 90.0 * b * b && top.mean_z > 15.0, "{top:?}");
        assert!(m.regions.len() <= 5 && m.regions.windows(2).all(|r| r[0].excess >= r[1].excess));
        assert_eq!((z.width, z.height), (w, h));
        // A standard error of another size, or negative, is refused, and named as what it is.
        let e = compare_noisy(&image, &reference, &Film::new(3, 3), None, 5).unwrap_err().to_string();
        assert!(e.contains("reference's standard error is 3x3 pixels, the image 256x256"), "{e}");
        let e = compare_noisy(&image, &reference, &ref_se, Some(&Film::new(3, 3)), 5).unwrap_err().to_string();
        assert!(e.contains("image's standard error is 3x3"), "{e}");
        let mut bad = ref_se.clone();
        bad.pixels[7].y = -1.0;
        let e = compare_noisy(&image, &reference, &bad, None, 5).unwrap_err().to_string();
        assert!(e.contains("reference's standard error") && e.contains("-1"), "{e}");
    }

    /// A difference over a noise all but 0 is no f32: 3e38 over a standard error of 1e-45 made
    /// the z-image's pixel infinite, and a negative z escaped mean z^2's cap.
    #[test]
    fn the_z_image_is_finite_whatever_the_noise() {
        let (w, h) = (4u32, 3u32);
        let mut image = Film::new(w, h);
        image.pixels[5] = Vec3::new(f32::MAX, 3e38, 0.0);
        let mut reference = Film::new(w, h);
        reference.pixels[5].z = 3e38;
        let tiny = Film { width: w, height: h, pixels: vec![Vec3::splat(1e-45); (w * h) as usize] };
        for image_se in [None, Some(&tiny)] {
            let (m, z) = compare_noisy(&image, &reference, &tiny, image_se, 5).unwrap();
            assert!(z.first_non_finite().is_none(), "{:?}", z.pixels[5]);
            assert_eq!(z.pixels[5], Vec3::new(1e30, 1e30, -1e30));
            // Each of the three values counts (1e15)^2, whatever its sign.
            assert!((m.mean_z2 / (3e30 / 36.0) - 1.0).abs() < 1e-12, "{}", m.mean_z2);
            assert!(m.regions.iter().all(|r| r.mean_z.is_finite()), "{:?}", m.regions);
        }
    }
}
