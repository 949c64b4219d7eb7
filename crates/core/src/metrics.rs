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
}
