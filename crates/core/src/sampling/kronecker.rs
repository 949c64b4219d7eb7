//! The reference's low-discrepancy sequence (docs/mathematics.md section 4): Roberts' additive
//! recurrence, randomly shifted per replicate.

/// The additive-recurrence (Kronecker) low-discrepancy sequence of Roberts' generalised golden
/// ratio in `D` dimensions: x_i = frac(shift + i alpha), alpha_j = phi_D^-(j+1), with phi_D the
/// positive root of x^(D+1) = x + 1.
pub struct Kronecker<const D: usize> {
    alpha: [f64; D],
}

impl<const D: usize> Kronecker<D> {
    pub fn new() -> Self {
        let mut phi = 2.0f64;
        for _ in 0..60 {
            phi -= (phi.powi(D as i32 + 1) - phi - 1.0) / ((D as f64 + 1.0) * phi.powi(D as i32) - 1.0);
        }
        Kronecker { alpha: std::array::from_fn(|j| phi.powi(-(j as i32 + 1)).fract()) }
    }

    /// Point `i` of the sequence rotated by `shift` (Cranley-Patterson): uniform in [0, 1)^D
    /// for a uniform shift, so each replicate is an unbiased estimate.
    pub fn point(&self, i: u64, shift: &[f64; D]) -> [f64; D] {
        std::array::from_fn(|j| (shift[j] + (i as f64 * self.alpha[j]).fract()).fract())
    }
}

impl<const D: usize> Default for Kronecker<D> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// phi_D solves x^(D+1) = x + 1 (phi_1 is the golden ratio), and a shifted point stays in
    /// [0, 1)^D.
    #[test]
    fn the_generalised_golden_ratio_and_its_points() {
        let golden = (1.0 + 5f64.sqrt()) / 2.0;
        let k = Kronecker::<1>::new();
        assert!((k.alpha[0] - (1.0 / golden)).abs() < 1e-15, "{}", k.alpha[0]);
        let k = Kronecker::<6>::new();
        let phi = 1.0 / k.alpha[0];
        assert!((phi.powi(7) - phi - 1.0).abs() < 1e-12, "{phi}");
        for i in [0u64, 1, 17, 1 << 40] {
            let p = k.point(i, &[0.999_999, 0.5, 0.0, 0.25, 0.75, 0.1]);
            assert!(p.iter().all(|x| (0.0..1.0).contains(x)), "{p:?}");
        }
    }
}
