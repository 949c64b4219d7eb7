//! The vector kernels: one plane against its runs of pixels in a band of rows, in blocks of
//! [`LANES`] (a span's last [`HALF_LANES`] as a half block). The loop body is the per-hit
//! arithmetic of [`crate::gather`] ([`PlaneJob::gather_block`]) and nothing else, written once
//! against the lane type of [`crate::simd`] in `plane_body` and compiled for each vector width
//! the CPU may have (AVX-512, AVX2 with FMA, the portable baseline), chosen at run time by
//! [`Kernel`].
//!
//! No operation is fused or reordered between them (every lane type does exactly rounded IEEE
//! operations, and Rust never contracts `a * b + c`; a fused multiply-add is written out as
//! [`Lanes::mul_add`], rounded once on every width), so every kernel gives bit-identical sums.
//!
//! Where a hit's time goes (issue 27; AMD EPYC Zen 4 under KVM, which exposes no hardware
//! counters): with the lane loops vectorised by the compiler, a 16-pixel block of `smis-exact`
//! was about 130 instructions with AVX-512 and the core retired about 1.5 a cycle; how fast it
//! ran moved by 10-20% with edits that did not change the arithmetic (an unused field, the order
//! of two checks), in opposite directions for different estimators, because the vectoriser's
//! registers, spills and scalarised remainders changed. Written out as intrinsics behind
//! [`crate::simd::Lanes`] (the same operations, the same bits), the gathering took 20% less
//! time for `unweighted` and 23% less for `smis-exact`. The speed still moves with the
//! compiler's register allocation, less: AVX2's smis-exact by up to 7% between builds that
//! differ in where one value is read (16 registers hold few of a plane's constants), and
//! cmis-exact, which keeps the compiler's vectorisation, by up to 9%. What did not help,
//! measured: splitting a block into a crossing pass and a weighting pass over batches of blocks
//! (the stores and loads between them cost more than the shorter chains saved), an arc tangent
//! reduced at tan(pi/8) (slower, cause not found), a reciprocal of D taken early,
//! software prefetch of the next span, blocks of two rows by eight columns (a plane's slant
//! cost as much as the rounding saved: 1.22 tests per hit), and for `cmis-exact` a two-pass
//! closed form holding fewer values (slower) and the closed form on the lane types (5% slower
//! than the compiler's vectorisation of its lane loops, which it keeps: its four sectors' fields
//! spill either way; with fused multiply-adds, still 3-4% slower). Half blocks cut the pixels
//! tested past a span's end (1.12 tests per hit, from 1.21): 3-5% with AVX2, nothing with
//! AVX-512, where the span's parity is a branch the predictor misses as often as the half block
//! saves. A degree-5 minimax exponential gained 2-4% but errs by up to 2.4e-7 relative (2.5e-7
//! without fused multiply-adds), over exp's tested 2e-7: left. Fused multiply-adds
//! ([`Lanes::mul_add`]) took 5-7% off the gathering of every estimator and 10% off cmis-exact's.
//! Also measured and left: blocks of 32 lanes as two AVX-512 registers, for the core to overlap
//! two blocks' dependency chains (no change for smis-exact and unweighted, cmis-exact 10%
//! slower: the block is bound by its operations, not its chains; replacing D's division by a
//! multiply, for the count, saved 2.5%), and AVX2 blocks of 8 lanes in one register instead of
//! 16 in two (fewer spills, more blocks: smis-exact 1.05x).
//! One bounds check per span instead of eight per block (unsafe loads, behind one assert per
//! span) took 1.3% off the benchmark's CPU time (perf stat task-clock, 7 runs, alternating).
//! Summing a light's hits without its power and multiplying once per light and band ([`fold`];
//! [the sums light by light](crate::gather#sums-light-by-light)) took 9% off smis-exact's and 7%
//! off unweighted's CPU time: in a grey medium a block loads, adds and stores one sum, not
//! three, and multiplies by no scale. A 16-pixel block of `smis-exact` is now about 80 AVX-512
//! operations. cmis-exact with its sectors' arc tangents and logarithms taken after the arcs to
//! the zeros of det, so that fewer of its values are live at once, was 13-16% slower (the same
//! bits): left. Its sectors summed as |dF| with one correction per zero of det, on the edge the
//! zero's direction leaves through, instead of each sector split by selects, took 4% off its
//! CPU time with AVX-512 and 14% with AVX2 (fewer values live: 47 of the hot instructions touch
//! the stack, from 65); on the lane types, rather than the compiler's vectorisation, it was
//! still 6% slower. Its arc tangents and logarithms are 28% of its time (measured by replacing
//! them with the identity), its twelve divisions 5%.

use crate::camera::CameraRay;
use crate::control::Control;
use crate::error::{Error, Result};
use crate::gather::{GatherContext, GatherStats, PlaneJob, RayBlock};
#[cfg(target_arch = "x86_64")]
use crate::simd::{Avx2, Avx512, Ymm};
use crate::simd::{Lanes, Portable};
use crate::weights::Denominator;
use glam::Vec3;
use rayon::prelude::*;
use std::ops::Range;

/// How the gathering loop runs over the pixels of a span.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Kernel {
    /// The widest vector kernel this CPU has.
    #[default]
    Auto,
    /// 16 lanes (x86-64 with AVX-512 F/VL/DQ/BW).
    Avx512,
    /// 8 lanes (x86-64 with AVX2 and FMA).
    Avx2,
    /// What the compiler makes of the loop for the baseline target (4 lanes with SSE2).
    Portable,
    /// One pixel at a time ([`PlaneJob::gather_block`] with one lane): for checking the vector
    /// kernels.
    PerHit,
}

impl Kernel {
    pub const ALL: [Kernel; 5] = [Kernel::Auto, Kernel::Avx512, Kernel::Avx2, Kernel::Portable, Kernel::PerHit];

    pub fn name(self) -> &'static str {
        match self {
            Kernel::Auto => "auto",
            Kernel::Avx512 => "avx512",
            Kernel::Avx2 => "avx2",
            Kernel::Portable => "portable",
            Kernel::PerHit => "per-hit",
        }
    }

    /// Whether this CPU can run the kernel.
    pub fn is_available(self) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => {
                std::arch::is_x86_feature_detected!("avx512f")
                    && std::arch::is_x86_feature_detected!("avx512vl")
                    && std::arch::is_x86_feature_detected!("avx512dq")
                    && std::arch::is_x86_feature_detected!("avx512bw")
                    && Kernel::Avx2.is_available()
            }
            #[cfg(target_arch = "x86_64")]
            // popcnt counts a block's hits in one instruction (without it, a dozen).
            Kernel::Avx2 => {
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                    && std::arch::is_x86_feature_detected!("popcnt")
            }
            #[cfg(not(target_arch = "x86_64"))]
            Kernel::Avx512 | Kernel::Avx2 => false,
            Kernel::Auto | Kernel::Portable | Kernel::PerHit => true,
        }
    }

    /// Every kernel this CPU can run, `auto` excepted.
    pub fn available() -> Vec<Kernel> {
        Kernel::ALL.into_iter().filter(|&k| k != Kernel::Auto && k.is_available()).collect()
    }

    /// The widest vector kernel this CPU has: what `auto` runs.
    pub fn widest() -> Kernel {
        [Kernel::Avx512, Kernel::Avx2].into_iter().find(|k| k.is_available()).unwrap_or(Kernel::Portable)
    }

    /// The kernel that runs: `auto` becomes the widest available; one the CPU lacks is an error.
    pub fn resolve(self) -> Result<Kernel> {
        match self {
            Kernel::Auto => Ok(Kernel::widest()),
            k if k.is_available() => Ok(k),
            k => Err(Error::option(crate::error::Setting::Kernel, format!("this CPU cannot run the {k} kernel"))),
        }
    }
}

crate::named_choice!(Kernel, "kernel");

/// What one gathering call runs: the planes prepared for rays from the camera, the estimator's
/// weights and the kernel (resolved, see [`Kernel::resolve`]). A new per-call setting is one
/// field here.
pub struct Gathering<'a, D: Denominator> {
    pub ctx: &'a GatherContext,
    pub weights: &'a D,
    pub kernel: Kernel,
}

impl<D: Denominator> Clone for Gathering<'_, D> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<D: Denominator> Copy for Gathering<'_, D> {}

/// An intersection structure over prepared planes (as pbrt-v4's aggregate): what every
/// accelerator answers, so that a render gathers through one call whichever it built.
pub trait Aggregate {
    /// Gathers every plane of `with.ctx` along `rays` (one per pixel, row-major), adding each
    /// ray's estimate to its entry of `sums`. Reports each unit of work (a band of rows, a chunk
    /// of rays) to `control`; once it is cancelled, the work stops before the next plane (or
    /// ray) and `sums` is incomplete.
    fn gather<D: Denominator>(
        &self,
        with: Gathering<D>,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        control: Control,
    ) -> GatherStats;
}

/// Rays per parallel work item of the per-ray structures.
pub const RAY_CHUNK: usize = 4096;

/// The loop of the per-ray structures: chunks of rays in parallel, one progress unit per
/// chunk, the cancel flag read before each ray (against every plane, a brute-force ray is the
/// longest unit of work: milliseconds at a million planes). `one` is a ray's estimate.
pub fn gather_per_ray(
    rays: &[CameraRay],
    sums: &mut [Vec3],
    control: Control,
    one: impl Fn(&CameraRay) -> (Vec3, GatherStats) + Sync,
) -> GatherStats {
    sums.par_chunks_mut(RAY_CHUNK)
        .zip(rays.par_chunks(RAY_CHUNK))
        .map(|(sums, rays)| {
            let mut stats = GatherStats::default();
            for (sum, ray) in sums.iter_mut().zip(rays) {
                if control.is_cancelled() {
                    return stats;
                }
                let (value, s) = one(ray);
                *sum += value;
                stats += s;
            }
            control.progress();
            stats
        })
        .reduce(GatherStats::default, |mut a, b| {
            a += b;
            a
        })
}

/// Pixels per block: the vector kernels take the rays of a span 16 at a time, as one AVX-512
/// vector, two AVX2 vectors or four SSE2 vectors, and a span's last 8 (when its length is an
/// odd number of half blocks) as a half block in one AVX2 vector. Spans are whole half blocks
/// (the raster pads its rows), so no kernel has a scalar remainder loop.
pub const LANES: usize = 16;

/// The lanes of a half block, and the multiple a span's length is rounded to: half blocks halve
/// the pixels tested past a span's end (a span is 30-odd pixels on the benchmark, and rounding
/// it to whole blocks added 13% to the pixels tested).
pub const HALF_LANES: usize = LANES / 2;

/// The rays of a band of rows as a structure of arrays (directions and segments).
pub struct BandRays<'a> {
    pub x: &'a [f32],
    pub y: &'a [f32],
    pub z: &'a [f32],
    pub t0: &'a [f32],
    pub t1: &'a [f32],
}

/// The sums of a band, a structure of arrays laid out like its rays: the current light's
/// contributions without its power ([`PlaneJob::gather_block`]; a grey medium's in `r` alone),
/// until [`fold`] adds them to the band's [`BandTotals`].
pub struct BandSums<'a> {
    pub r: &'a mut [f32],
    pub g: &'a mut [f32],
    pub b: &'a mut [f32],
}

/// The RGB sums of a band of the lights already folded, laid out like its rays (the same three
/// arrays as [`BandSums`], in another role).
pub type BandTotals<'a> = BandSums<'a>;

/// What a kernel reads and writes of a band of rows: its rays and their sums. A new per-band
/// input is one field here.
pub struct Band<'a> {
    pub rays: BandRays<'a>,
    pub sums: BandSums<'a>,
}

impl Band<'_> {
    /// The pixels every array of the band holds.
    pub fn pixels(&self) -> usize {
        let (r, s) = (&self.rays, &self.sums);
        [r.x.len(), r.y.len(), r.z.len(), r.t0.len(), r.t1.len(), s.r.len(), s.g.len(), s.b.len()]
            .into_iter()
            .min()
            .unwrap_or(0)
    }
}

/// A run of pixels of one row to test against a plane: `start` and `len` index the band's
/// arrays, `len` a multiple of [`HALF_LANES`].
#[derive(Clone, Copy, Debug)]
pub struct Span {
    pub start: u32,
    pub len: u32,
}

/// One plane against its spans in a band with a vector kernel (`kernel` resolved, not
/// [`Kernel::PerHit`]): [`PlaneJob::gather_block`] on each block of [`LANES`] pixels. Adds each
/// pixel's contribution without the light's scale to the band's sums ([`fold`] applies it)
/// unless `CONTRIBUTE` is off (then only hits are counted). Returns the hit count.
#[inline(always)]
pub fn gather_plane<D: Denominator, const CONTRIBUTE: bool>(
    kernel: Kernel,
    job: &PlaneJob<D>,
    spans: &[Span],
    band: &mut Band,
) -> u64 {
    // Counting hits needs neither the channels nor the phase function: one copy of the kernel
    // counts (a branch on the constant `CONTRIBUTE`, whose dead side is never compiled). The
    // phase function is a branch per block ([`PlaneJob::gather_block`]), not a copy.
    macro_rules! run {
        ($f:ident) => {
            if !CONTRIBUTE {
                $f::<D, true, false>(job, spans, band)
            } else if job.extinction.grey {
                $f::<D, true, true>(job, spans, band)
            } else {
                $f::<D, false, true>(job, spans, band)
            }
        };
    }
    match kernel {
        // SAFETY: `resolve` returned these kernels only after checking the CPU's features.
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx512 => unsafe { run!(plane_avx512) },
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx2 => unsafe { run!(plane_avx2) },
        _ => run!(plane_portable),
    }
}

/// Ends a light's planes in a band ([the sums light by light](crate::gather#sums-light-by-light)):
/// over the pixels `range` (whole blocks of [`LANES`] inside the band), adds the light's `scale`
/// times the band's sums (in a grey medium the one sum, to all three channels) to `totals`, a
/// separate multiply and add ([`crate::gather::add_light`]: a channel whose scale is 0 is left
/// as it is), and zeroes the sums. `kernel` resolved, as for [`gather_plane`].
pub(crate) fn fold(
    kernel: Kernel,
    scale: Vec3,
    grey: bool,
    sums: &mut BandSums,
    totals: &mut BandTotals,
    range: Range<usize>,
) {
    let len = [sums.r.len(), sums.g.len(), sums.b.len(), totals.r.len(), totals.g.len(), totals.b.len()];
    assert!(
        range.start <= range.end && range.end <= len.into_iter().min().unwrap_or(0),
        "fold of pixels {range:?} outside the band"
    );
    assert!(
        range.start.is_multiple_of(LANES) && range.end.is_multiple_of(LANES),
        "fold of pixels {range:?}: not whole blocks"
    );
    match kernel {
        // SAFETY: `resolve` returned these kernels only after checking the CPU's features.
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx512 => unsafe { fold_avx512(scale, grey, sums, totals, range) },
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx2 => unsafe { fold_avx2(scale, grey, sums, totals, range) },
        _ => fold_body::<Portable<LANES>>(scale, grey, sums, totals, range),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma")]
fn fold_avx512(scale: Vec3, grey: bool, sums: &mut BandSums, totals: &mut BandTotals, range: Range<usize>) {
    fold_body::<Avx512>(scale, grey, sums, totals, range)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn fold_avx2(scale: Vec3, grey: bool, sums: &mut BandSums, totals: &mut BandTotals, range: Range<usize>) {
    fold_body::<Avx2>(scale, grey, sums, totals, range)
}

/// [`fold`] on the lane type `V`: the same operations on every width.
#[inline(always)]
fn fold_body<V: Lanes<LANES>>(
    scale: Vec3,
    grey: bool,
    sums: &mut BandSums,
    totals: &mut BandTotals,
    range: Range<usize>,
) {
    /// The block of `s` from `i`, bounds checked.
    #[inline(always)]
    fn at(s: &mut [f32], i: usize) -> &mut [f32; LANES] {
        (&mut s[i..i + LANES]).try_into().unwrap()
    }
    let zero = V::splat(0.0);
    for i in range.step_by(LANES) {
        let r = V::load(at(sums.r, i));
        let (g, b) = if grey { (r, r) } else { (V::load(at(sums.g, i)), V::load(at(sums.b, i))) };
        for (total, (sum, c)) in
            [&mut *totals.r, &mut *totals.g, &mut *totals.b].into_iter().zip([(r, scale.x), (g, scale.y), (b, scale.z)])
        {
            if c != 0.0 {
                let total = at(total, i);
                (V::load(total) + V::splat(c) * sum).store(total);
            }
        }
        zero.store(at(sums.r, i));
        if !grey {
            zero.store(at(sums.g, i));
            zero.store(at(sums.b, i));
        }
    }
}

/// The compiled copies of [`plane_body`]: one per vector width, with its lane types for whole
/// blocks and half blocks, chosen at run time.
macro_rules! plane_kernel {
    ($(#[$attr:meta])* $name:ident, $lanes:ty, $half:ty) => {
        $(#[$attr])*
        #[inline(never)]
        fn $name<D: Denominator, const GREY: bool, const CONTRIBUTE: bool>(
            job: &PlaneJob<D>,
            spans: &[Span],
            band: &mut Band,
        ) -> u64 {
            plane_body::<$lanes, $half, D, GREY, CONTRIBUTE>(job, spans, band)
        }
    };
}

plane_kernel!(
    /// [`plane_body`] in AVX-512 registers (half blocks in AVX2 ones).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma,popcnt")]
    plane_avx512,
    Avx512,
    Ymm
);
plane_kernel!(
    /// [`plane_body`] in pairs of AVX2 registers (half blocks in one).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,popcnt")]
    plane_avx2,
    Avx2,
    Ymm
);
plane_kernel!(
    /// [`plane_body`] for the baseline target.
    plane_portable,
    Portable<LANES>,
    Portable<HALF_LANES>
);

/// The kernel proper: the plane's spans block by block, each block [`PlaneJob::gather_block`]
/// on `V` (a span's last half block, if any, on `H`), the band's arrays loaded and stored in
/// place.
#[inline(always)]
fn plane_body<V: Lanes<LANES>, H: Lanes<HALF_LANES>, D: Denominator, const GREY: bool, const CONTRIBUTE: bool>(
    job: &PlaneJob<D>,
    spans: &[Span],
    band: &mut Band,
) -> u64 {
    let mut hits = 0u64;
    let len = band.pixels();
    for span in spans {
        let (start, end) = (span.start as usize, (span.start + span.len) as usize);
        // The one bounds check of the span's blocks (eight arrays each), which `block` relies
        // on: inside the band, and whole half blocks (so that the last one ends at `end`).
        assert!(
            start <= end && end <= len && (end - start) % HALF_LANES == 0,
            "span {start}..{end} is not whole half blocks inside the band's {len} pixels"
        );
        let whole = start + (end - start) / LANES * LANES;
        for i in (start..whole).step_by(LANES) {
            // SAFETY: i + LANES <= whole <= end <= len, checked above.
            hits += unsafe { block::<LANES, V, D, GREY, CONTRIBUTE>(job, band, i) } as u64;
        }
        if whole < end {
            // SAFETY: whole + HALF_LANES = end <= len (whole half blocks, checked above).
            hits += unsafe { block::<HALF_LANES, H, D, GREY, CONTRIBUTE>(job, band, whole) } as u64;
        }
    }
    hits
}

/// The block of `L` pixels from `i`: [`PlaneJob::gather_block`] on the band's arrays in place.
///
/// # Safety
///
/// `i + L <= band.pixels()`. (Checked per span by the caller: eight bounds checks per block were
/// about 1% of the benchmark's CPU time.)
#[inline(always)]
unsafe fn block<const L: usize, V: Lanes<L>, D: Denominator, const GREY: bool, const CONTRIBUTE: bool>(
    job: &PlaneJob<D>,
    band: &mut Band,
    i: usize,
) -> u32 {
    debug_assert!(i + L <= band.pixels());
    // Functions, not closures: a closure is compiled without the kernel's target features.
    /// SAFETY: `i + L <= s.len()`.
    #[inline(always)]
    unsafe fn lanes<const L: usize>(s: &[f32], i: usize) -> &[f32; L] {
        unsafe { &*(s.as_ptr().add(i) as *const [f32; L]) }
    }
    /// SAFETY: `i + L <= s.len()`.
    #[inline(always)]
    unsafe fn lanes_mut<const L: usize>(s: &mut [f32], i: usize) -> &mut [f32; L] {
        unsafe { &mut *(s.as_mut_ptr().add(i) as *mut [f32; L]) }
    }
    let (rays, sums) = (&band.rays, &mut band.sums);
    // SAFETY: i..i + L lies in every array of the band (the caller's contract, band.pixels()).
    let block = unsafe {
        RayBlock {
            x: V::load(lanes(rays.x, i)),
            y: V::load(lanes(rays.y, i)),
            z: V::load(lanes(rays.z, i)),
            t0: V::load(lanes(rays.t0, i)),
            t1: V::load(lanes(rays.t1, i)),
        }
    };
    // SAFETY: as above (three distinct arrays).
    let block_sums: [&mut [f32; L]; 3] = unsafe { [lanes_mut(sums.r, i), lanes_mut(sums.g, i), lanes_mut(sums.b, i)] };
    job.gather_block::<L, V, GREY, CONTRIBUTE>(&block, block_sums)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every kernel's fold adds `scale` times the sums as [`crate::gather::add_light`] does (a
    /// channel under a scale of 0 untouched, even by an infinite sum), in a grey medium and an
    /// RGB one, and zeroes the sums.
    #[test]
    fn every_fold_adds_a_light_as_add_light_does() {
        use crate::gather::add_light;
        let scale = Vec3::new(0.5, 0.0, 2.0);
        for kernel in Kernel::available().into_iter().filter(|&k| k != Kernel::PerHit) {
            for grey in [false, true] {
                let sum = |k: usize| Vec3::new(4.0 + k as f32, if grey { 4.0 + k as f32 } else { f32::INFINITY }, 1.0);
                let (mut r, mut g, mut b): (Vec<f32>, Vec<f32>, Vec<f32>) = (
                    (0..48).map(|k| sum(k).x).collect(),
                    (0..48).map(|k| sum(k).y).collect(),
                    (0..48).map(|k| sum(k).z).collect(),
                );
                let total = |k: usize| Vec3::new(1.0, 2.0, 3.0) * k as f32;
                let (mut tr, mut tg, mut tb): (Vec<f32>, Vec<f32>, Vec<f32>) = (
                    (0..48).map(|k| total(k).x).collect(),
                    (0..48).map(|k| total(k).y).collect(),
                    (0..48).map(|k| total(k).z).collect(),
                );
                let mut sums = BandSums { r: &mut r, g: &mut g, b: &mut b };
                let mut totals = BandTotals { r: &mut tr, g: &mut tg, b: &mut tb };
                fold(kernel, scale, grey, &mut sums, &mut totals, 16..48);
                for k in 0..48 {
                    let got = Vec3::new(totals.r[k], totals.g[k], totals.b[k]);
                    let want = if k < 16 {
                        total(k)
                    } else {
                        add_light(total(k), scale, if grey { Vec3::splat(sum(k).x) } else { sum(k) })
                    };
                    assert_eq!(got, want, "{kernel} grey {grey} pixel {k}");
                    let left = if k < 16 { sum(k).x } else { 0.0 };
                    assert_eq!(sums.r[k], left, "{kernel} grey {grey} pixel {k}");
                }
            }
        }
    }

    #[test]
    fn names_round_trip_and_auto_resolves_to_an_available_kernel() {
        for k in Kernel::ALL {
            assert_eq!(k.name().parse::<Kernel>().unwrap(), k);
        }
        assert!("sse9".parse::<Kernel>().is_err());
        let auto = Kernel::Auto.resolve().unwrap();
        assert!(auto != Kernel::Auto && auto.is_available());
        assert!(Kernel::available().contains(&Kernel::Portable));
        assert!(Kernel::available().contains(&Kernel::PerHit));
    }
}
