//! A render's error image: the standard error of each pixel, estimated from the render itself
//! by the spread of its plane groups (docs/mathematics.md section 10).
//!
//! A render's planes fall into groups, each gathered along one ray set (section 8.1): every
//! group's mean is an unbiased estimate of the pixel, and the image is their weighted mean. The
//! spread of the group means gives the error of the image if the groups were independent;
//! they are not quite (each is a block of one scrambled Sobol sequence and the ray sets are
//! stratified over the pixel, so the groups err less together than apart), and the image-wide
//! ratio of the two halves' measured spread to what the groups predict for it, carried one level
//! further with the quarters' ratio, corrects that. The direct emission's own variance
//! ([`crate::emission::direct_emission_and_variance`]) is added.

use crate::control::Control;
use crate::error::Result;
use crate::film::Film;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// Pixels per unit of work of [`GroupSpread::close`]'s parallel loop.
const CLOSE_UNIT: usize = 16_384;

/// The groups of a render so far, per pixel: what the error image is made from. A group is a
/// run of consecutive pieces gathered along the same ray set, in the same quarter of the
/// render, in two halves ([`crate::partial::halves`]; [`GroupSpread::add`]); the groups come
/// in plane order, each once.
#[derive(Clone, Debug)]
pub struct GroupSpread {
    /// Sum over the closed groups of `G^2 / n` (`G` a group's sum of planes weighted 1, `n`
    /// its planes), per channel.
    pub(crate) squares: Vec<DVec3>,
    /// Sum over the closed groups with two halves of `(A / n_A - B / n_B)^2 / (1 / n_A + 1 /
    /// n_B)`, the halves' sums `A`, `B` of `n_A`, `n_B` planes: each an estimate of one plane's
    /// variance along the group's ray, free of how the pixel varies from ray set to ray set.
    pub(crate) within: Vec<DVec3>,
    /// Sums of the closed groups of each quarter.
    pub(crate) quarters: [Vec<DVec3>; 4],
    /// The open group's sums so far, each half's.
    pub(crate) open: [Vec<DVec3>; 2],
    /// The open group's ray set and quarter, and each half's planes so far.
    pub(crate) open_key: Option<(u32, usize)>,
    pub(crate) open_planes: [usize; 2],
    /// Planes of each quarter's closed groups.
    pub(crate) planes: [usize; 4],
    pub(crate) groups: usize,
    /// Closed groups that had two halves (the terms of `within`).
    pub(crate) halved: usize,
}

impl GroupSpread {
    pub fn new(pixels: usize) -> Self {
        GroupSpread {
            squares: vec![DVec3::ZERO; pixels],
            within: vec![DVec3::ZERO; pixels],
            quarters: std::array::from_fn(|_| vec![DVec3::ZERO; pixels]),
            open: std::array::from_fn(|_| vec![DVec3::ZERO; pixels]),
            open_key: None,
            open_planes: [0; 2],
            planes: [0; 4],
            groups: 0,
            halved: 0,
        }
    }

    /// Memory per pixel, in bytes (for the memory rule).
    pub const BYTES_PER_PIXEL: u64 = 8 * 24;

    /// Adds a piece `(k, quarter, half, planes)`, `planes` planes gathered along ray set `k` in
    /// `quarter` (0 to 3) of the render and `half` (0 or 1) of its group, whose sums per pixel
    /// were `after - before` (the
    /// gather's buffer after it and before: the render's own sums stay bit for bit what they are
    /// without an error image). A piece of another ray set or quarter than the open group's
    /// closes it first.
    pub fn add(
        &mut self,
        (k, quarter, half, planes): (u32, usize, usize, usize),
        before: &[Vec3],
        after: &[Vec3],
        control: Control,
    ) {
        let half = half.min(1);
        for ((o, b), a) in self.open_group(k, quarter, control)[half].iter_mut().zip(before).zip(after) {
            *o += a.as_dvec3() - b.as_dvec3();
        }
        self.open_planes[half] += planes;
    }

    /// The sums of the halves of group (`k`, `quarter`) so far (the open group's, closed first
    /// if it is another), for pieces to add their sums per pixel to, `after - before` of the
    /// render's own as [`GroupSpread::add`] adds them (the taps of
    /// [`crate::accel::gather_pieces`]); their planes are told after, [`GroupSpread::add_planes`].
    pub(crate) fn open_group(&mut self, k: u32, quarter: usize, control: Control) -> [&mut [DVec3]; 2] {
        let quarter = quarter.min(3);
        if self.open_key != Some((k, quarter)) {
            self.close(control);
            self.open_key = Some((k, quarter));
        }
        let [a, b] = &mut self.open;
        [a, b]
    }

    /// Counts `planes` more planes in each half of the open group: those of the pieces added to
    /// [`GroupSpread::open_group`]'s sums.
    pub(crate) fn add_planes(&mut self, planes: [usize; 2]) {
        debug_assert!(self.open_key.is_some(), "planes of no group");
        self.open_planes[0] += planes[0];
        self.open_planes[1] += planes[1];
    }

    /// Closes the open group, if any: the next piece starts another.
    pub fn close(&mut self, control: Control) {
        let Some((_, quarter)) = self.open_key.take() else { return };
        let [na, nb] = std::mem::take(&mut self.open_planes);
        let n = na + nb;
        if n == 0 {
            return;
        }
        let halved = na > 0 && nb > 0;
        // Reciprocals taken once: the loop is over every pixel, for every group.
        let (ia, ib, i_n) = (1.0 / na.max(1) as f64, 1.0 / nb.max(1) as f64, 1.0 / n as f64);
        let i_pair = if halved { 1.0 / (ia + ib) } else { 0.0 };
        let [first, second] = &mut self.open;
        // In parallel: a render closes a group per ray set, each a pass over five of the image's
        // f64 buffers (5 ms at 640x360 on one core, where a whole render takes 40 on 16).
        let unit = CLOSE_UNIT;
        let section = control.section("spread");
        self.squares
            .par_chunks_mut(unit)
            .zip(self.within.par_chunks_mut(unit))
            .zip(self.quarters[quarter].par_chunks_mut(unit))
            .zip(first.par_chunks_mut(unit))
            .zip(second.par_chunks_mut(unit))
            .for_each(|((((s, w), q), a), b)| {
                section.unit(|| {
                    for ((((s, w), q), a), b) in s.iter_mut().zip(w).zip(q).zip(a).zip(b) {
                        let g = *a + *b;
                        *s += g * g * i_n;
                        *q += g;
                        let d = *a * ia - *b * ib;
                        *w += d * d * i_pair;
                        (*a, *b) = (DVec3::ZERO, DVec3::ZERO);
                    }
                })
            });
        section.close();
        self.groups += 1;
        self.halved += halved as usize;
        self.planes[quarter] += n;
    }

    /// A render in passes starts another pass (section 10.2): the quarters so far become
    /// (the passes before the last, the last pass), and the new pass's groups go to quarters 2
    /// and 3 (its first and second half). So the halves are the planes before the last pass
    /// and the last pass, consecutive ranges of the sequence as a render in chunks has them.
    pub fn next_pass(&mut self, control: Control) {
        self.close(control);
        let [q0, q1, q2, q3] = &mut self.quarters;
        for (((a, b), c), d) in q0.iter_mut().zip(q1.iter_mut()).zip(q2.iter_mut()).zip(q3.iter_mut()) {
            *a += *b;
            *b = *c + *d;
            (*c, *d) = (DVec3::ZERO, DVec3::ZERO);
        }
        let n = self.planes;
        self.planes = [n[0] + n[1], n[2] + n[3], 0, 0];
    }

    /// Groups closed so far.
    pub fn groups(&self) -> usize {
        self.groups
    }

    /// Refuses a spread that a render of `ray_sets` ray sets over `pixels` pixels cannot hold
    /// after `planes` planes (one read back from a checkpoint): the buffers' sizes, finite
    /// values, non-negative squares, the counts adding up.
    pub fn check(&self, pixels: usize, ray_sets: u32, planes: usize) -> std::result::Result<(), String> {
        let buffers = [&self.squares, &self.within].into_iter().chain(&self.quarters).chain(&self.open);
        if buffers.clone().any(|b| b.len() != pixels) {
            return Err(format!("its buffers do not hold the image's {pixels} pixels"));
        }
        let negative = |b: &[DVec3]| b.iter().any(|v| v.min_element() < 0.0);
        if buffers.flatten().any(|v| !v.is_finite()) || negative(&self.squares) || negative(&self.within) {
            return Err("it holds sums that are not finite, or negative squares".into());
        }
        // Counts read from a file may be anything: added without wrapping.
        let total = self.planes.iter().chain(&self.open_planes).try_fold(0usize, |a, &b| a.checked_add(b));
        let counts_fit = self.groups <= planes && self.halved <= self.groups;
        if total != Some(planes) || !counts_fit || self.open_key.is_some_and(|(k, q)| k >= ray_sets || q > 3) {
            return Err(format!(
                "its counts ({} planes in {} groups) are not those of {planes} planes",
                total.map_or("more than 2^64".into(), |t| t.to_string()),
                self.groups
            ));
        }
        Ok(())
    }

    /// Planes of the closed groups.
    pub fn planes(&self) -> usize {
        self.planes.iter().sum()
    }

    /// The error estimate of the image of the closed groups' planes (the whole render's, once
    /// the last group is closed), plus the direct emission's `emission_variance`: the variance
    /// of each pixel (section 10). `None` with fewer than two groups. While one half of the
    /// render has no closed group (the first half of a render's chunks), the groups are taken
    /// as independent (scale 1, which errs high).
    pub fn variance(&self, emission_variance: &[DVec3]) -> Option<Vec<DVec3>> {
        let n = self.planes.map(|p| p as f64);
        let total: f64 = n.iter().sum();
        let (h1, h2) = (n[0] + n[1], n[2] + n[3]);
        if self.groups < 2 {
            return None;
        }
        let both_halves = h1 > 0.0 && h2 > 0.0;
        // The closed groups' sums per pixel (every plane weighted 1).
        let sums: Vec<DVec3> = (0..self.squares.len()).map(|p| self.quarters.iter().map(|q| q[p]).sum()).collect();
        // One plane's variance in each pixel: from the groups' halves, which differ by the
        // planes alone, where two groups or more had two; else from the groups' spread (10.1),
        // which also holds how the pixel varies from ray set to ray set (section 10.2, "A light
        // in view").
        let dof = (self.groups - 1) as f64;
        let halved = self.halved as f64;
        let sigma2 = |p: usize| {
            if self.halved >= 2 {
                self.within[p] / halved
            } else {
                ((self.squares[p] - sums[p] * sums[p] / total) / dof).max(DVec3::ZERO)
            }
        };
        // The spreads of the halves and of the quarters within them, measured against what
        // the groups predict for them if they were independent (eqs. 10.2, 10.3).
        let quartered = n.iter().all(|&q| q > 0.0);
        if !both_halves {
            return Some((0..sums.len()).map(|p| sigma2(p) / total + emission_variance[p]).collect());
        }
        let (mut halves, mut halves_iid, mut quarters, mut quarters_iid) = [DVec3::ZERO; 4].into();
        for (p, sum) in sums.iter().enumerate() {
            let q = [self.quarters[0][p], self.quarters[1][p], self.quarters[2][p], self.quarters[3][p]];
            let first = q[0] + q[1];
            let d = first / h1 - (*sum - first) / h2;
            let s2 = sigma2(p);
            halves += d * d;
            halves_iid += s2 * (1.0 / h1 + 1.0 / h2);
            if quartered {
                let a = q[0] / n[0] - q[1] / n[1];
                let b = q[2] / n[2] - q[3] / n[3];
                quarters += a * a + b * b;
                quarters_iid += s2 * (1.0 / n[0] + 1.0 / n[1] + 1.0 / n[2] + 1.0 / n[3]);
            }
        }
        let ratio = |measured: DVec3, iid: DVec3| DVec3::select(iid.cmpgt(DVec3::ZERO), measured / iid, DVec3::ONE);
        let f_halves = ratio(halves, halves_iid);
        // The correlation of sibling units, the same at each level (eq. 10.3): the halves' ratio
        // is the quarters' times (1 + rho); the whole's is the halves' (1 - rho) undone and
        // (1 + rho) applied once more. Clamped: a wild rho is noise.
        let scale = if quartered {
            let rho = (f_halves / ratio(quarters, quarters_iid) - 1.0).clamp(DVec3::splat(-0.5), DVec3::splat(0.5));
            f_halves * (1.0 + rho) / (1.0 - rho)
        } else {
            f_halves
        };
        Some((0..sums.len()).map(|p| scale * sigma2(p) / total + emission_variance[p]).collect())
    }
}

/// The error image of variances `variance` (standard errors, their square roots), refusing a
/// value that is not a finite number as every image is refused.
pub fn stderr_film(width: u32, height: u32, variance: &[DVec3]) -> Result<Film> {
    let film =
        Film { width, height, pixels: variance.iter().map(|v| v.max(DVec3::ZERO).powf(0.5).as_vec3()).collect() };
    film.check_finite("error image")?;
    Ok(film)
}

/// An image's estimated relative RMS error (docs/mathematics.md section 10.2) and the part of
/// it that more planes do not lower.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelativeError {
    /// `sqrt(mean Var_hat) / mean(image)`, the means over pixels and channels.
    pub total: f64,
    /// The direct emission's part, `sqrt(mean Var_hat(E_hat)) / mean(image)` (section 10.3):
    /// its samples are fixed by the ray sets and the grids, not by the planes, so no number of
    /// planes brings `total` below it.
    pub floor: f64,
}

/// The relative RMS error of `image` whose pixels have `variance`, of which `emission_variance`
/// is the direct emission's; `None` for a black image (mean 0), whose relative error is 0/0.
pub fn relative_rms_error(image: &Film, variance: &[DVec3], emission_variance: &[DVec3]) -> Option<RelativeError> {
    let count = 3.0 * variance.len().max(1) as f64;
    let mean_variance = variance.iter().map(|v| v.x + v.y + v.z).sum::<f64>() / count;
    let mean_emission = emission_variance.iter().map(|v| v.element_sum()).sum::<f64>() / count;
    let mean = image.mean();
    // `!(mean > 0)` also takes a NaN mean (a film is checked finite, but say so here too).
    if !(mean > 0.0) {
        return None;
    }
    Some(RelativeError { total: mean_variance.sqrt() / mean, floor: mean_emission.sqrt() / mean })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{rng_for, unit_f64};
    use rand::RngCore;

    /// Independent groups of unequal sizes (the halves' and quarters' ratios are 1 in
    /// expectation, rho 0): the mean estimated variance is the variance of the weighted mean,
    /// within 4 standard errors over 300 images of 4096 pixels. (The image-wide ratios are
    /// estimated from the image itself, so the estimate carries a bias of the order of their
    /// relative variance, a few 1e-4 here: images of tens of pixels would show it.)
    #[test]
    fn independent_groups_give_the_variance_of_the_mean() {
        let pixels = 4096;
        let sizes = [300usize, 301, 300, 300, 299, 301, 300, 300];
        let sigma = 2.0; // of one plane's value
        let mut rng = rng_for(5, 0, 0);
        let mut gauss = || {
            let (u, v) = (unit_f64(rng.next_u64()).max(1e-300), unit_f64(rng.next_u64()));
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        let n: usize = sizes.iter().sum();
        let truth = sigma * sigma / n as f64;
        let (runs, mut estimates) = (300, Vec::new());
        for _ in 0..runs {
            let mut spread = GroupSpread::new(pixels);
            for (g, &size) in sizes.iter().enumerate() {
                // A group's sum of `size` planes of mean 1 and deviation sigma, in two pieces.
                let quarter = g / 2;
                let mut before = vec![Vec3::ZERO; pixels];
                for (half, piece) in [size / 2, size - size / 2].into_iter().enumerate() {
                    let after: Vec<Vec3> = before
                        .iter()
                        .map(|b| *b + Vec3::splat((piece as f64 + sigma * (piece as f64).sqrt() * gauss()) as f32))
                        .collect();
                    spread.add((g as u32, quarter, half, piece), &before, &after, Control::none());
                    before = after;
                }
            }
            spread.close(Control::none());
            let v = spread.variance(&vec![DVec3::ZERO; pixels]).unwrap();
            estimates.extend(v.iter().map(|v| v.x));
            assert_eq!(spread.groups(), 8);
        }
        // The estimates of one image share its halves' ratio: count images, not pixels.
        let per_image: Vec<f64> = estimates.chunks(pixels).map(|c| c.iter().sum::<f64>() / pixels as f64).collect();
        let mean = per_image.iter().sum::<f64>() / runs as f64;
        let sd = (per_image.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (runs - 1) as f64).sqrt();
        let se = sd / (runs as f64).sqrt();
        assert!((mean - truth).abs() < 4.0 * se, "{mean} +- {se} against {truth}");
    }

    #[test]
    fn too_few_groups_give_no_estimate() {
        let mut spread = GroupSpread::new(1);
        spread.add((0, 0, 0, 10), &[Vec3::ZERO], &[Vec3::ONE], Control::none());
        spread.close(Control::none());
        assert!(spread.variance(&[DVec3::ZERO]).is_none());
        let mut spread = GroupSpread::new(1);
        spread.add((0, 0, 0, 10), &[Vec3::ZERO], &[Vec3::ONE], Control::none());
        spread.add((1, 1, 0, 10), &[Vec3::ZERO], &[Vec3::splat(3.0)], Control::none());
        spread.close(Control::none());
        // Two groups of the first half: taken as independent. Means 0.1 and 0.3 of 20 planes:
        // sigma^2 = (10 0.01 + 10 0.01) / 1 = 0.2, over 20 planes.
        let v = spread.variance(&[DVec3::ZERO]).unwrap()[0];
        assert!((v - DVec3::splat(0.01)).abs().max_element() < 1e-12, "{v}");
    }

    /// What a checkpoint gives back is checked: sizes, finite values, non-negative squares,
    /// counts that add up to the planes resumed from.
    #[test]
    fn a_spread_read_back_is_checked() {
        let mut spread = GroupSpread::new(2);
        spread.add((3, 1, 0, 10), &[Vec3::ZERO; 2], &[Vec3::ONE; 2], Control::none());
        spread.close(Control::none());
        spread.add((4, 2, 1, 5), &[Vec3::ZERO; 2], &[Vec3::ONE; 2], Control::none());
        assert_eq!(spread.check(2, 16, 15), Ok(()));
        assert!(spread.check(3, 16, 15).is_err(), "another image size");
        assert!(spread.check(2, 16, 16).is_err(), "other planes");
        assert!(spread.check(2, 4, 15).is_err(), "a ray set beyond the render's");
        let mut wraps = spread.clone();
        wraps.planes = [usize::MAX, 11, 0, 0];
        assert!(wraps.check(2, 16, 15).unwrap_err().contains("more than 2^64"), "counts that wrap to 15");
        let mut bad = spread.clone();
        bad.quarters[1][0].y = f64::NAN;
        assert!(bad.check(2, 16, 15).unwrap_err().contains("not finite"));
        let mut bad = spread.clone();
        bad.squares[1].x = -1.0;
        assert!(bad.check(2, 16, 15).is_err());
    }
}
