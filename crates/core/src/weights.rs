//! The estimators' weights: the denominator `D` of docs/mathematics.md section 2, the only thing in which the
//! estimators differ. A hit contributes `K / (N P_l D)`.
//!
//! Notation (docs/mathematics.md section 2): `det(beta) = (d(beta) x wl) . we = cos(beta) a_u + sin(beta) a_v`,
//! `g(beta) = width(beta, y') |det(beta)|`, the path density `p(x | beta)` of paper eq. (25) up to
//! factors shared by all orientations.

// Lane loops (`for l in 0..L`) index several arrays in step, as the vector code they become.
#![allow(clippy::needless_range_loop)]

use crate::light::{ChordDirection, chord_width};
use crate::limits::MAX_ORIENTATIONS;
use std::f64::consts::PI;
use std::fmt;
use std::str::FromStr;

/// The weighting schemes: the closed list of estimators. Everything that names or dispatches
/// an estimator reads it from here ([`Estimator::ALL`], [`Estimator::info`],
/// [`Weighting::dispatch`]), so a new weighting is a variant, its [`Denominator`] below, one
/// arm in `info` and one in `dispatch`, and its unit tests: this file only.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Estimator {
    /// Paper eq. (22): `D = g(alpha)`.
    Unweighted,
    /// Deng et al.'s analytic weight, paper eq. (26): `D = width(alpha) (1/pi) int |det|`.
    CmisCosine,
    /// Paper eq. (27) with the cosine weight over K stratified orientations.
    SmisCosine,
    /// Paper eq. (27) with exact densities over K stratified orientations.
    SmisExact,
    /// The optimal CMIS balance heuristic, paper eq. (24), in closed form: `D = (1/pi) int g`.
    CmisExact,
}

/// What the documentation, the command line and the reports say about an estimator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EstimatorInfo {
    /// The command-line name.
    pub name: &'static str,
    /// Where the weighting comes from in the paper (West et al. 2020).
    pub source: &'static str,
    /// The denominator D of a hit's contribution K / (N P_l D) (docs/mathematics.md section 2).
    pub denominator: &'static str,
    /// Whether `--orientations K` applies.
    pub orientations: bool,
}

impl Estimator {
    /// Every estimator, in the order of the paper (and of the tables).
    pub const ALL: [Estimator; 5] = [
        Estimator::Unweighted,
        Estimator::CmisCosine,
        Estimator::SmisCosine,
        Estimator::SmisExact,
        Estimator::CmisExact,
    ];

    /// The estimator the others are measured against in the tables.
    pub const BASELINE: Estimator = Estimator::Unweighted;

    /// The estimator rendered when none is named.
    pub const DEFAULT: Estimator = Estimator::SmisExact;

    pub const fn info(self) -> EstimatorInfo {
        let (name, source, denominator, orientations) = match self {
            Estimator::Unweighted => ("unweighted", "eq. 22", "g(alpha) = width(alpha, y') |det(alpha)|", false),
            Estimator::CmisCosine => (
                "cmis-cosine",
                "eq. 26, Deng et al.'s analytic weight",
                "width(alpha, y') (2/pi) sqrt(a_u^2 + a_v^2)",
                false,
            ),
            Estimator::SmisCosine => {
                ("smis-cosine", "eq. 27, cosine weight", "width(alpha, y') mean_k |det(alpha_k)|", true)
            }
            Estimator::SmisExact => ("smis-exact", "eq. 27, exact densities", "mean_k g(alpha_k)", true),
            Estimator::CmisExact => {
                ("cmis-exact", "eq. 24, not in the paper: closed form", "(1/pi) integral of g over [0, pi)", false)
            }
        };
        EstimatorInfo { name, source, denominator, orientations }
    }

    pub const fn name(self) -> &'static str {
        self.info().name
    }

    /// Whether `--orientations K` applies.
    pub const fn has_orientations(self) -> bool {
        self.info().orientations
    }

    /// The names, for help texts and error messages.
    pub fn names() -> Vec<&'static str> {
        Estimator::ALL.iter().map(|e| e.name()).collect()
    }
}

impl fmt::Display for Estimator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Estimator {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        crate::parse_name("estimator", s, &Estimator::ALL, Estimator::name)
    }
}

/// An estimator with its number of stratified orientations K (2 for the paper's pair).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Weighting {
    pub estimator: Estimator,
    pub orientations: u32,
}

impl Default for Weighting {
    fn default() -> Self {
        Weighting { estimator: Estimator::DEFAULT, orientations: 2 }
    }
}

impl Weighting {
    pub fn new(estimator: Estimator, orientations: Option<u32>) -> Result<Self, String> {
        match orientations {
            None => Ok(Weighting { estimator, orientations: 2 }),
            Some(k) if !estimator.has_orientations() && k != 2 => {
                let with: Vec<_> = Estimator::ALL.iter().filter(|e| e.has_orientations()).map(|e| e.name()).collect();
                Err(format!("--orientations applies to {} only, not to {estimator}", with.join(" and ")))
            }
            Some(k) if k == 0 || k > MAX_ORIENTATIONS => {
                Err(format!("the number of orientations must be between 1 and {MAX_ORIENTATIONS}, got {k}"))
            }
            Some(k) => Ok(Weighting { estimator, orientations: k }),
        }
    }

    /// Every estimator with its default K, then those with orientations at each K of `ks`
    /// (besides 2): the list the tables, tests and benchmarks iterate over.
    pub fn all(ks: &[u32]) -> Vec<Weighting> {
        let mut all: Vec<Weighting> =
            Estimator::ALL.iter().map(|&e| Weighting { estimator: e, orientations: 2 }).collect();
        for &k in ks {
            for e in Estimator::ALL.into_iter().filter(|e| e.has_orientations()) {
                let w = Weighting { estimator: e, orientations: k };
                if !all.contains(&w) {
                    all.push(w);
                }
            }
        }
        all
    }

    /// A label such as `smis-exact` or `smis-exact-k4`.
    pub fn label(&self) -> String {
        if self.estimator.has_orientations() && self.orientations != 2 {
            format!("{}-k{}", self.estimator, self.orientations)
        } else {
            self.estimator.to_string()
        }
    }

    /// Runs `f` with this weighting's denominator as a concrete type: the one dispatch from a
    /// name to its monomorphised gathering loop.
    pub fn dispatch<F: WithDenominator>(&self, f: F) -> F::Output {
        match (self.estimator, self.orientations) {
            (Estimator::Unweighted, _) => f.run(&Unweighted),
            (Estimator::CmisCosine, _) => f.run(&CmisCosine),
            (Estimator::CmisExact, _) => f.run(&CmisExact),
            (Estimator::SmisCosine, 2) => f.run(&SmisCosinePair),
            (Estimator::SmisExact, 2) => f.run(&SmisExactPair),
            (Estimator::SmisCosine, k) => f.run(&StratifiedK::new(false, k)),
            (Estimator::SmisExact, k) => f.run(&StratifiedK::new(true, k)),
        }
    }
}

/// Work generic over the denominator, for [`Weighting::dispatch`].
pub trait WithDenominator {
    type Output;
    fn run<D: Denominator>(self, weights: &D) -> Self::Output;
}

impl fmt::Display for Weighting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.label())
    }
}

/// What the weights need to know about a plane, in its light's local frame (f32, gathered often).
#[derive(Clone, Copy, Debug)]
pub struct PlaneFrame {
    /// width(alpha, y'): the plane's own chord, the same for every hit on it.
    pub width: f32,
    /// (cos alpha, sin alpha), sin >= 0.
    pub cos_a: f32,
    pub sin_a: f32,
    /// Local coordinates (p, q) of the chord's start; y' = start + a (cos alpha, sin alpha).
    pub p0: f32,
    pub q0: f32,
    /// The light's side lengths W and H.
    pub light_w: f32,
    pub light_h: f32,
    /// The perpendicular direction alpha_perp = (alpha + pi/2) mod pi, ready for chords.
    pub perp: ChordDirection<f32>,
}

impl PlaneFrame {
    pub fn new(width: f64, alpha: f64, p0: f64, q0: f64, light_w: f64, light_h: f64) -> Self {
        let (sin_a, cos_a) = alpha.sin_cos();
        // (-sin, cos) has a negative sine when cos < 0; the same line is (sin, -cos).
        let (pc, ps) = if cos_a >= 0.0 { (-sin_a, cos_a) } else { (sin_a, -cos_a) };
        PlaneFrame {
            width: width as f32,
            cos_a: cos_a as f32,
            sin_a: sin_a.max(0.0) as f32,
            p0: p0 as f32,
            q0: q0 as f32,
            light_w: light_w as f32,
            light_h: light_h as f32,
            perp: ChordDirection::<f32>::from_cos_sin(pc as f32, ps as f32),
        }
    }

    /// Light-local coordinates of the light vertex y' at chord parameter `a`, kept inside.
    #[inline(always)]
    pub fn vertex(&self, a: f32) -> (f32, f32) {
        // Compare-and-select rather than clamp: no panic or NaN path, so loops vectorise.
        let inside = |x: f32, hi: f32| {
            let x = if x > 0.0 { x } else { 0.0 };
            if x < hi { x } else { hi }
        };
        (inside(self.p0 + a * self.cos_a, self.light_w), inside(self.q0 + a * self.sin_a, self.light_h))
    }
}

/// What the weights need to know about one hit.
#[derive(Clone, Copy, Debug)]
pub struct HitLocal {
    /// det(alpha) = (d(alpha) x wl) . we and det(alpha_perp).
    pub det: f32,
    pub det_perp: f32,
    /// Chord parameter of the light vertex y'.
    pub a: f32,
}

/// L hits on one plane, lane by lane (L = 1 on the per-hit path, [`crate::kernel::LANES`] in the
/// vector kernels).
#[derive(Clone, Copy, Debug)]
pub struct HitLanes<const L: usize> {
    pub det: [f32; L],
    pub det_perp: [f32; L],
    pub a: [f32; L],
}

/// (a_u, a_v), undoing the rotation det(alpha) = cos a_u + sin a_v,
/// det(alpha_perp) = -sin a_u + cos a_v.
#[inline(always)]
fn a_uv(f: &PlaneFrame, det: f32, det_perp: f32) -> (f32, f32) {
    (f.cos_a * det - f.sin_a * det_perp, f.sin_a * det + f.cos_a * det_perp)
}

/// A denominator D, specialised per estimator so that the gathering loop is monomorphised.
///
/// D is computed for L hits of one plane at a time, each lane with the same operations in the
/// same order whatever L, so that the per-hit path (L = 1) and the vector kernels
/// (L = [`crate::kernel::LANES`]) give bit-identical values: one implementation for every width,
/// written as loops over lanes that the compiler turns into vector instructions.
pub trait Denominator: Sync + Send {
    /// What D needs of a plane beyond its [`PlaneFrame`], made once per plane before its hits
    /// are gathered (for K orientations: the K - 1 rotated chord directions).
    type Plane: Clone + Send + Sync;

    fn prepare(&self, f: &PlaneFrame) -> Self::Plane;

    /// D of each of `L` hits on the plane `p` was prepared for.
    fn denominators<const L: usize>(&self, p: &Self::Plane, h: &HitLanes<L>, out: &mut [f32; L]);

    /// D of one hit (preparing the plane for it): for tests and benchmarks.
    fn denominator(&self, f: &PlaneFrame, h: &HitLocal) -> f32 {
        let mut out = [0.0];
        self.denominators(&self.prepare(f), &HitLanes { det: [h.det], det_perp: [h.det_perp], a: [h.a] }, &mut out);
        out[0]
    }
}

/// `unweighted`: D = g(alpha), paper eq. (22).
pub struct Unweighted;
impl Denominator for Unweighted {
    type Plane = PlaneFrame;
    fn prepare(&self, f: &PlaneFrame) -> PlaneFrame {
        *f
    }
    #[inline(always)]
    fn denominators<const L: usize>(&self, f: &PlaneFrame, h: &HitLanes<L>, out: &mut [f32; L]) {
        for l in 0..L {
            out[l] = f.width * h.det[l].abs();
        }
    }
}

/// `cmis-cosine`: D = width(alpha) (2/pi) sqrt(a_u^2 + a_v^2), paper eq. (26).
/// a_u^2 + a_v^2 = det(alpha)^2 + det(alpha_perp)^2, a rotation of the same pair.
pub struct CmisCosine;
impl Denominator for CmisCosine {
    type Plane = PlaneFrame;
    fn prepare(&self, f: &PlaneFrame) -> PlaneFrame {
        *f
    }
    #[inline(always)]
    fn denominators<const L: usize>(&self, f: &PlaneFrame, h: &HitLanes<L>, out: &mut [f32; L]) {
        for l in 0..L {
            let (det, det_perp) = (h.det[l], h.det_perp[l]);
            out[l] = f.width * std::f32::consts::FRAC_2_PI * (det * det + det_perp * det_perp).sqrt();
        }
    }
}

/// `smis-cosine` with the paper's perpendicular pair: D = width(alpha) (|det(alpha)| +
/// |det(alpha_perp)|) / 2.
pub struct SmisCosinePair;
impl Denominator for SmisCosinePair {
    type Plane = PlaneFrame;
    fn prepare(&self, f: &PlaneFrame) -> PlaneFrame {
        *f
    }
    #[inline(always)]
    fn denominators<const L: usize>(&self, f: &PlaneFrame, h: &HitLanes<L>, out: &mut [f32; L]) {
        for l in 0..L {
            out[l] = f.width * 0.5 * (h.det[l].abs() + h.det_perp[l].abs());
        }
    }
}

/// `smis-exact` with the paper's perpendicular pair: D = (g(alpha) + g(alpha_perp)) / 2, the
/// perpendicular chord measured through the hit's light vertex y'.
pub struct SmisExactPair;
impl Denominator for SmisExactPair {
    type Plane = PlaneFrame;
    fn prepare(&self, f: &PlaneFrame) -> PlaneFrame {
        *f
    }
    #[inline(always)]
    fn denominators<const L: usize>(&self, f: &PlaneFrame, h: &HitLanes<L>, out: &mut [f32; L]) {
        for l in 0..L {
            let (p, q) = f.vertex(h.a[l]);
            let width_perp = chord_width(f.light_w, f.light_h, p, q, &f.perp);
            out[l] = 0.5 * (f.width * h.det[l].abs() + width_perp * h.det_perp[l].abs());
        }
    }
}

/// `smis-cosine` and `smis-exact` with K stratified orientations alpha + k pi / K.
pub struct StratifiedK {
    exact: bool,
    /// (cos, sin) of k pi / K for k = 1..K.
    rotations: Vec<(f32, f32)>,
}

impl StratifiedK {
    pub fn new(exact: bool, k: u32) -> Self {
        let rotations = (1..k).map(|i| i as f64 * PI / k as f64).map(|b| (b.cos() as f32, b.sin() as f32)).collect();
        StratifiedK { exact, rotations }
    }
}

/// One of the K - 1 further orientations beta_k = alpha + k pi / K of a plane, reduced to
/// [0, pi): its (cos, sin) and its chord direction.
#[derive(Clone, Copy, Debug)]
pub struct Orientation {
    pub cos: f32,
    pub sin: f32,
    pub chord: ChordDirection<f32>,
}

/// A plane prepared for K orientations: the rotations and their reciprocals (two divisions
/// each) are made once per plane, so that an orientation costs a hit a few multiplies.
#[derive(Clone, Debug)]
pub struct PlaneOrientations {
    pub frame: PlaneFrame,
    pub others: Vec<Orientation>,
}

impl Denominator for StratifiedK {
    type Plane = PlaneOrientations;

    fn prepare(&self, f: &PlaneFrame) -> PlaneOrientations {
        let others = self
            .rotations
            .iter()
            .map(|&(ck, sk)| {
                // beta = alpha + k pi / K, reduced to [0, pi) so that sin(beta) >= 0.
                let (mut c, mut s) = (f.cos_a * ck - f.sin_a * sk, f.sin_a * ck + f.cos_a * sk);
                if s < 0.0 {
                    (c, s) = (-c, -s);
                }
                Orientation { cos: c, sin: s, chord: ChordDirection::<f32>::from_cos_sin(c, s) }
            })
            .collect();
        PlaneOrientations { frame: *f, others }
    }

    /// The orientations run in the outer loop and the lanes in the inner one, so that any K
    /// vectorises; each lane still sums its orientations in the order k = 0, 1, .., K - 1.
    #[inline(always)]
    fn denominators<const L: usize>(&self, plane: &PlaneOrientations, h: &HitLanes<L>, out: &mut [f32; L]) {
        let f = &plane.frame;
        let (mut a_u, mut a_v, mut p, mut q) = ([0.0f32; L], [0.0f32; L], [0.0f32; L], [0.0f32; L]);
        for l in 0..L {
            (a_u[l], a_v[l]) = a_uv(f, h.det[l], h.det_perp[l]);
            (p[l], q[l]) = f.vertex(h.a[l]);
            out[l] = if self.exact { f.width * h.det[l].abs() } else { h.det[l].abs() };
        }
        for o in &plane.others {
            for l in 0..L {
                let det = (o.cos * a_u[l] + o.sin * a_v[l]).abs();
                out[l] += if self.exact { chord_width(f.light_w, f.light_h, p[l], q[l], &o.chord) * det } else { det };
            }
        }
        let inv_k = 1.0 / (plane.others.len() + 1) as f32;
        for l in 0..L {
            let mean = out[l] * inv_k;
            out[l] = if self.exact { mean } else { f.width * mean };
        }
    }
}

/// `cmis-exact`: D = (1/pi) int_0^pi g(beta) d beta, the closed form of section 3 in f32
/// ([`cmis_exact_mean_f32`], vectorised over the lanes). The f64 form [`cmis_exact_mean`] is
/// its reference in the tests.
pub struct CmisExact;

/// A plane prepared for `cmis-exact`: the light's sides in units of W + H, so that the
/// logarithms of lengths stay near zero (D is proportional to the lengths: D = (W + H) D(unit)).
#[derive(Clone, Copy, Debug)]
pub struct CmisPlane {
    pub frame: PlaneFrame,
    pub unit: f32,
    pub inv_unit: f32,
}

impl Denominator for CmisExact {
    type Plane = CmisPlane;
    fn prepare(&self, f: &PlaneFrame) -> CmisPlane {
        let unit = f.light_w + f.light_h;
        CmisPlane { frame: *f, unit, inv_unit: 1.0 / unit }
    }
    #[inline(always)]
    fn denominators<const L: usize>(&self, c: &CmisPlane, h: &HitLanes<L>, out: &mut [f32; L]) {
        let f = &c.frame;
        let (w, hh) = (f.light_w * c.inv_unit, f.light_h * c.inv_unit);
        for l in 0..L {
            let (a_u, a_v) = a_uv(f, h.det[l], h.det_perp[l]);
            let (p, q) = f.vertex(h.a[l]);
            out[l] = cmis_exact_mean_f32(w, hh, p * c.inv_unit, q * c.inv_unit, a_u, a_v) * c.unit;
        }
    }
}

/// [`cmis_exact_mean`] in f32 and without branches, so that the lanes of a block run as vector
/// instructions: the same sectors and arcs (section 3), with the choices made by selects and
/// every quantity written so that f32 keeps it accurate:
///
/// - the turn of sector e is atan2(d_e len_e, r_start . r_end), as r_start x r_end = d_e len_e
///   (distance to the edge times its length): exact small angles for long thin lights;
/// - its change of ln cos(psi), ln|r_start| - ln|r_end|, is (1/2) ln(1 + delta / |r_end|^2) with
///   delta = |r_start|^2 - |r_end|^2 = -E_e . (r_start + r_end) (E_e the edge vector: one
///   product, no cancellation) when that ratio is near 1, and (1/2) ln(|r_start|^2 / |r_end|^2)
///   otherwise;
/// - each zero of det (z = (-a_v, a_u) and -z) lies in one sector, found by two cross-product
///   signs; the sector is split there into arcs on which det keeps its sign, and each arc
///   contributes |d_e (A_n turn - A_t delta ln cos)| (a sector without a zero is one arc: its
///   second arc is empty). The arc up to the zero turns by atan2(r_start x z, r_start . z) and
///   changes ln cos by (1/2) ln((n_e . z)^2 |r_start|^2 / (|z|^2 d_e^2)).
///
/// Six atan2, six logarithms and twelve divisions per hit. Agrees with the f64 form to a
/// few 1e-7 relative on the benchmark's hits and on random inputs (tests below).
#[inline(always)]
pub fn cmis_exact_mean_f32(w: f32, h: f32, p: f32, q: f32, a_u: f32, a_v: f32) -> f32 {
    use crate::numeric::atan2_f32;
    let (zx, zy) = (-a_v, a_u);
    let s = [
        sector::<0>(w, h, p, q, zx, zy),
        sector::<1>(w, h, p, q, zx, zy),
        sector::<2>(w, h, p, q, zx, zy),
        sector::<3>(w, h, p, q, zx, zy),
    ];
    // The start corner, (n_e . z)^2 and d_e^2 of the sectors holding z and -z, by selects.
    let pick = |has: fn(&Sector) -> bool| {
        let mut chosen = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for t in &s {
            chosen = if has(t) { (t.start.0, t.start.1, t.nz2, t.dist * t.dist) } else { chosen };
        }
        chosen
    };
    let z2 = zx * zx + zy * zy;
    // The arc from a sector's start corner (x, y) to the zero `sign` z: its turn and change of
    // ln cos.
    let to_zero = |(x, y, nz2, d2): (f32, f32, f32, f32), sign: f32| {
        let turn = atan2_f32(sign * (x * zy - y * zx), sign * (x * zx + y * zy));
        (turn, 0.5 * crate::numeric::ln_f32(nz2 * (x * x + y * y) / (d2 * z2)))
    };
    let (z_turn, z_ell) = to_zero(pick(|t| t.has_z), 1.0);
    let (n_turn, n_ell) = to_zero(pick(|t| t.has_neg), -1.0);
    let mut total = 0.0f32;
    for t in &s {
        let (first_turn, first_ell) = if t.has_z {
            (z_turn, z_ell)
        } else if t.has_neg {
            (n_turn, n_ell)
        } else {
            (t.turn, t.ell)
        };
        let first = t.a_n * first_turn - t.a_t * first_ell;
        let second = t.a_n * (t.turn - first_turn) - t.a_t * (t.ell - first_ell);
        let value = t.dist * (first.abs() + second.abs());
        // A sector whose edge passes through the vertex contributes nothing.
        total += if t.dist > 0.0 { value } else { 0.0 };
    }
    let mean = total * std::f32::consts::FRAC_1_PI;
    if mean > 0.0 { mean } else { 0.0 }
}

/// One sector of [`cmis_exact_mean_f32`]: the part of the circle of directions from the vertex
/// that meets edge E.
#[derive(Clone, Copy)]
struct Sector {
    /// Its turn and the change of ln cos(psi) across it.
    turn: f32,
    ell: f32,
    /// Whether z or -z lies strictly inside.
    has_z: bool,
    has_neg: bool,
    /// Its start corner relative to the vertex, and (n_e . z)^2.
    start: (f32, f32),
    nz2: f32,
    /// d_e, A_n = a . n_e and A_t = a . t_e (a = (a_u, a_v) = (z_y, -z_x)).
    dist: f32,
    a_n: f32,
    a_t: f32,
}

#[inline(always)]
fn sector<const E: usize>(w: f32, h: f32, p: f32, q: f32, zx: f32, zy: f32) -> Sector {
    use crate::numeric::{atan2_f32, ln_1p_f32, ln_f32};
    let (a_u, a_v) = (zy, -zx);
    // Corners counter-clockwise from (0, 0), relative to the vertex; edge E runs from corner E
    // to corner E + 1, with outward normal n_E, tangent t_E = n_E turned a quarter, distance
    // d_E and length len_E.
    let cx = [-p, w - p, w - p, -p];
    let cy = [-q, -q, h - q, h - q];
    let (start, end) = ((cx[E], cy[E]), (cx[(E + 1) % 4], cy[(E + 1) % 4]));
    let dist = [q, w - p, h - q, p][E];
    let len = [w, h, w, h][E];
    let (a_n, a_t) = [(-a_v, a_u), (a_u, a_v), (a_v, -a_u), (-a_u, -a_v)][E];
    // |r_start|^2 - |r_end|^2 = -E_e . (r_start + r_end).
    let delta = [-w * (start.0 + end.0), -h * (start.1 + end.1), w * (start.0 + end.0), h * (start.1 + end.1)][E];
    let nz = [-zy, zx, zy, -zx][E];
    let r2_end = end.0 * end.0 + end.1 * end.1;
    let turn = atan2_f32(dist * len, start.0 * end.0 + start.1 * end.1);
    // ln(|r_start|^2 / |r_end|^2) as ln(1 + x), x = delta / |r_end|^2, where that is accurate
    // (x small: the ratio would round away its difference from 1), else from the ratio (x near
    // -1: 1 + x would cancel).
    let inv = 1.0 / r2_end;
    let (x, ratio) = (delta * inv, (start.0 * start.0 + start.1 * start.1) * inv);
    let ell = 0.5 * if x.abs() < 0.5 { ln_1p_f32(x) } else { ln_f32(ratio) };
    let c_start = start.0 * zy - start.1 * zx;
    let c_end = zx * end.1 - zy * end.0;
    Sector {
        turn,
        ell,
        has_z: (c_start > 0.0) & (c_end > 0.0),
        has_neg: (c_start < 0.0) & (c_end < 0.0),
        start,
        nz2: nz * nz,
        dist,
        a_n,
        a_t,
    }
}

/// (1/pi) times the integral over beta in [0, pi) of g(beta) = width(beta, (p, q)) |det(beta)|,
/// det(beta) = cos(beta) a_u + sin(beta) a_v, for the light vertex at local (p, q) of a `w x h`
/// light: the marginal density of paper eq. (24) that the paper calls non-integrable.
///
/// The mathematics (section 3) splits [0, pi) at pi/2, the corner directions and the zero of det. The same
/// pieces are summed here over the full circle, which needs fewer transcendental calls:
/// width(beta) = fwd(beta) + fwd(beta + pi), with fwd(phi) the distance from (p, q) to the
/// boundary along direction phi, and |det| has period pi, so
///
///   int_0^pi g = int_0^{2 pi} fwd(phi) |det(phi)| d phi.
///
/// The directions to the four corners cut the circle into four sectors, one per edge e, with
/// outward normal n_e, tangent t_e (n_e turned a quarter counter-clockwise) and distance d_e.
/// In sector e, with psi the angle from n_e, fwd = d_e / cos(psi) and
/// det = A_n cos(psi) + A_t sin(psi), A_n = a . n_e, A_t = a . t_e, so
///
///   int fwd det d phi = d_e [A_n psi - A_t ln cos(psi)],
///
/// and at a corner r_k (offset from (p, q)) cos(psi) = d_e / |r_k|: between two corners the
/// logarithms leave ln|r_start| - ln|r_end|. A zero of det (directions +-(-a_v, a_u)) inside a
/// sector splits it, so that |det| is det times one sign on each arc. A sector whose edge
/// passes through the vertex (d_e = 0) contributes nothing and is skipped, avoiding 0 * inf.
/// Matches adaptive quadrature to ~1e-14 relative (tests below).
pub fn cmis_exact_mean(w: f64, h: f64, p: f64, q: f64, a_u: f64, a_v: f64) -> f64 {
    if a_u == 0.0 && a_v == 0.0 {
        return 0.0;
    }
    let cross = |a: (f64, f64), b: (f64, f64)| a.0 * b.1 - a.1 * b.0;
    let dot = |a: (f64, f64), b: (f64, f64)| a.0 * b.0 + a.1 * b.1;
    let det = |b: (f64, f64)| a_u * b.0 + a_v * b.1;
    // Corners counter-clockwise from (0, 0); edge e runs from corner e to corner e + 1.
    let corners = [(-p, -q), (w - p, -q), (w - p, h - q), (-p, h - q)];
    let edges = [((0.0, -1.0), q), ((1.0, 0.0), w - p), ((0.0, 1.0), h - q), ((-1.0, 0.0), p)];
    let zero = (-a_v, a_u);
    let mut total = 0.0;
    for (e, &(n, d)) in edges.iter().enumerate() {
        if !(d > 0.0) {
            continue;
        }
        let (a_n, a_t) = (det(n), det((-n.1, n.0)));
        let (start, end) = (corners[e], corners[(e + 1) % 4]);
        // The integral over an arc on which det keeps one sign, from the turn angle and the
        // change of ln cos(psi). On such an arc det(b0) and det(b1) share that sign or vanish,
        // and cannot both vanish (the arc is shorter than pi), so their sum carries it.
        let arc = |b0: (f64, f64), b1: (f64, f64), turn: f64, delta_ln_cos: f64| {
            d * (a_n * turn - a_t * delta_ln_cos) * (det(b0) + det(b1)).signum()
        };
        let turn = cross(start, end).atan2(dot(start, end));
        // ln cos(psi_end) - ln cos(psi_start) = ln |r_start| - ln |r_end|.
        let delta = 0.5 * (dot(start, start) / dot(end, end)).ln();
        // A zero of det strictly inside the sector (which spans less than pi) splits it.
        match [zero, (-zero.0, -zero.1)].into_iter().find(|&z| cross(start, z) > 0.0 && cross(z, end) > 0.0) {
            Some(z) => {
                let first_turn = cross(start, z).atan2(dot(start, z));
                // cos(psi) is d / |r_start| at the corner and n . z / |z| at the zero.
                let first_delta = 0.5 * (dot(n, z).powi(2) * dot(start, start) / (dot(z, z) * d * d)).ln();
                total += arc(start, z, first_turn, first_delta) + arc(z, end, turn - first_turn, delta - first_delta);
            }
            None => total += arc(start, end, turn, delta),
        }
    }
    // The integral of a non-negative function; rounding can leave a hair below zero.
    (total / PI).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quadrature::{chord_width_by_clipping, integrate_with_breaks};
    use rand::{Rng, SeedableRng};

    /// g(beta) computed directly (chord by clipping), independently of the closed form.
    fn g(w: f64, h: f64, p: f64, q: f64, a_u: f64, a_v: f64, beta: f64) -> f64 {
        chord_width_by_clipping(w, h, p, q, beta) * (beta.cos() * a_u + beta.sin() * a_v).abs()
    }

    /// Where g may have kinks: the zero of det and the directions to the four corners (mod pi).
    fn kinks(w: f64, h: f64, p: f64, q: f64, a_u: f64, a_v: f64) -> Vec<f64> {
        let corners = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)];
        let mut out: Vec<f64> = corners.iter().map(|&(x, y)| (y - q).atan2(x - p).rem_euclid(PI)).collect();
        out.push((-a_u).atan2(a_v).rem_euclid(PI));
        out
    }

    fn quadrature_mean(w: f64, h: f64, p: f64, q: f64, a_u: f64, a_v: f64) -> f64 {
        let scale = (w + h) * (a_u.abs() + a_v.abs());
        let f = |b| g(w, h, p, q, a_u, a_v, b);
        integrate_with_breaks(f, 0.0, PI, &kinks(w, h, p, q, a_u, a_v), 1e-13, 1e-15 * scale).value / PI
    }

    #[test]
    fn analytic_cosine_integral_matches_quadrature() {
        let check = |a_u: f64, a_v: f64| {
            let closed = std::f64::consts::FRAC_2_PI * (a_u * a_u + a_v * a_v).sqrt();
            let scale = a_u.abs() + a_v.abs();
            let zero = [(-a_u).atan2(a_v).rem_euclid(PI)];
            let det = |b: f64| (b.cos() * a_u + b.sin() * a_v).abs();
            let numeric = integrate_with_breaks(det, 0.0, PI, &zero, 1e-13, 1e-300).value / PI;
            if scale == 0.0 {
                assert_eq!(closed, 0.0);
                assert_eq!(numeric, 0.0);
            } else {
                assert!((closed - numeric).abs() <= 1e-10 * closed, "a_u={a_u} a_v={a_v}: {closed} vs {numeric}");
            }
        };
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        for _ in 0..1000 {
            check(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        }
        check(0.0, 0.0);
        for x in [1e-12, 0.3, -2.0, 1e6] {
            check(x, 0.0);
            check(0.0, x);
        }
        for e in 0..=12 {
            let r = 10f64.powi(e);
            check(1.0, r);
            check(-r, 1.0);
            check(1e-6, 1e-6 * r);
        }
    }

    #[test]
    fn cmis_exact_matches_quadrature_on_random_inputs() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(11);
        let mut worst = 0.0f64;
        for i in 0..10_000 {
            let (w, h) = (rng.random_range(0.01..5.0), rng.random_range(0.01..5.0));
            let (p, q) = (rng.random::<f64>() * w, rng.random::<f64>() * h);
            let (a_u, a_v) = (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let closed = cmis_exact_mean(w, h, p, q, a_u, a_v);
            let numeric = quadrature_mean(w, h, p, q, a_u, a_v);
            assert!(
                (closed - numeric).abs() <= 1e-9 * numeric,
                "#{i} w={w} h={h} p={p} q={q} a=({a_u},{a_v}): {closed} vs {numeric}"
            );
            worst = worst.max((closed - numeric).abs() / numeric);
        }
        println!("largest relative difference: {worst:.2e}");
    }

    #[test]
    fn cmis_exact_hard_cases() {
        let (w, h) = (3.0f64, 2.0f64);
        let vertices = [
            (0.0, 0.0),
            (w, 0.0),
            (w, h),
            (0.0, h),
            (0.0, 0.7),
            (w, 1.1),
            (1.3, 0.0),
            (2.2, h),
            (1.5, 1.0),
            (1e-14, 1e-14),
            (w - 1e-14, 0.5),
        ];
        let dets =
            [(1.0, 0.0), (0.0, 1.0), (-0.3, 0.0), (0.0, -2.0), (1.0, 1e-12), (1e-12, -1.0), (0.6, 0.8), (-0.6, 0.8)];
        for &(p, q) in &vertices {
            for &(a_u, a_v) in &dets {
                let closed = cmis_exact_mean(w, h, p, q, a_u, a_v);
                let numeric = quadrature_mean(w, h, p, q, a_u, a_v);
                assert!(closed.is_finite());
                assert!(
                    (closed - numeric).abs() <= 1e-9 * numeric,
                    "p={p} q={q} a=({a_u},{a_v}): {closed} vs {numeric}"
                );
            }
        }
        assert_eq!(cmis_exact_mean(w, h, 1.0, 1.0, 0.0, 0.0), 0.0);
        // Very thin lights, both ways round.
        for &(w, h) in &[(1.0, 1e-3), (1e-3, 1.0), (1000.0, 1.0), (1.0, 1e-6)] {
            for &(fp, fq) in &[(0.5, 0.5), (0.0, 0.3), (1.0, 1.0), (0.999, 0.001)] {
                for &(a_u, a_v) in &dets {
                    let (p, q) = (fp * w, fq * h);
                    let closed = cmis_exact_mean(w, h, p, q, a_u, a_v);
                    let numeric = quadrature_mean(w, h, p, q, a_u, a_v);
                    assert!(
                        (closed - numeric).abs() <= 1e-9 * numeric,
                        "w={w} h={h} p={p} q={q} a=({a_u},{a_v}): {closed} vs {numeric}"
                    );
                }
            }
        }
    }

    /// The f32 closed form against the f64 one: relative error over random vertices, light
    /// shapes (aspect ratios to 1e4) and hit directions, and on the hard cases.
    #[test]
    fn cmis_exact_f32_matches_the_f64_closed_form() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(12);
        let relative = |w: f32, h: f32, p: f32, q: f32, a_u: f32, a_v: f32| {
            let want = cmis_exact_mean(w as f64, h as f64, p as f64, q as f64, a_u as f64, a_v as f64);
            let got = cmis_exact_mean_f32(w, h, p, q, a_u, a_v) as f64;
            assert!(got.is_finite());
            if want == 0.0 { got.abs() } else { (got - want).abs() / want }
        };
        let mut errors = Vec::new();
        for _ in 0..200_000 {
            let aspect = 10f32.powf(rng.random_range(-2.0..2.0));
            let (w, h) = (1.0 / (1.0 + aspect), aspect / (1.0 + aspect));
            let (p, q) = (rng.random::<f32>() * w, rng.random::<f32>() * h);
            let (a_u, a_v) = (rng.random_range(-1.0f32..1.0), rng.random_range(-1.0f32..1.0));
            errors.push(relative(w, h, p, q, a_u, a_v));
        }
        errors.sort_by(f64::total_cmp);
        let (median, p999, worst) =
            (errors[errors.len() / 2], errors[errors.len() * 999 / 1000], errors[errors.len() - 1]);
        println!("f32 closed form, relative error: median {median:.1e}, 99.9% {p999:.1e}, largest {worst:.1e}");
        assert!(median < 1e-7 && p999 < 1e-6 && worst < 1e-5, "median {median:e}, 99.9% {p999:e}, largest {worst:e}");
        // Vertices on edges and corners, axis-aligned and near-zero directions.
        let (w, h) = (0.6f32, 0.4f32);
        for &(p, q) in &[(0.0, 0.0), (w, 0.0), (w, h), (0.0, h), (0.0, 0.2), (w, 0.1), (0.3, 0.0), (0.2, h), (0.3, 0.2)]
        {
            for &(a_u, a_v) in
                &[(1.0, 0.0), (0.0, 1.0), (-0.3, 0.0), (0.0, -2.0), (1.0, 1e-7), (1e-7, -1.0), (0.6, 0.8)]
            {
                let e = relative(w, h, p, q, a_u, a_v);
                assert!(e < 1e-5, "p={p} q={q} a=({a_u},{a_v}): relative error {e:e}");
            }
        }
        assert_eq!(cmis_exact_mean_f32(w, h, 0.3, 0.2, 0.0, 0.0), 0.0);
    }

    fn frame_and_hit(rng: &mut impl Rng) -> (PlaneFrame, HitLocal) {
        let (w, h) = (rng.random_range(0.1..3.0), rng.random_range(0.1..3.0));
        let alpha = rng.random::<f64>() * PI;
        let (p, q) = (rng.random::<f64>() * w, rng.random::<f64>() * h);
        let dir = ChordDirection::from_angle(alpha);
        let (back, fwd) = crate::light::chord_extent(w, h, p, q, &dir);
        let (p0, q0) = (p - back * alpha.cos(), q - back * alpha.sin());
        let f = PlaneFrame::new(back + fwd, alpha, p0, q0, w, h);
        let hit = HitLocal { det: rng.random_range(-1.0..1.0), det_perp: rng.random_range(-1.0..1.0), a: back as f32 };
        (f, hit)
    }

    #[test]
    fn stratified_k2_reproduces_the_pair_hit_by_hit() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(5);
        let (exact_k, cosine_k) = (StratifiedK::new(true, 2), StratifiedK::new(false, 2));
        for _ in 0..10_000 {
            let (f, hit) = frame_and_hit(&mut rng);
            let (a, b) = (SmisExactPair.denominator(&f, &hit), exact_k.denominator(&f, &hit));
            assert!((a - b).abs() <= 1e-5 * a.max(1e-6), "{a} vs {b}");
            let (a, b) = (SmisCosinePair.denominator(&f, &hit), cosine_k.denominator(&f, &hit));
            assert!((a - b).abs() <= 1e-5 * a.max(1e-6), "{a} vs {b}");
        }
    }

    #[test]
    fn many_orientations_approach_the_continuous_weights() {
        // The stratified averages are Riemann sums of the CMIS integrals.
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(6);
        let (exact_k, cosine_k) = (StratifiedK::new(true, 64), StratifiedK::new(false, 64));
        for _ in 0..1000 {
            let (f, hit) = frame_and_hit(&mut rng);
            let (c, e) = (CmisCosine.denominator(&f, &hit), cosine_k.denominator(&f, &hit));
            assert!((c - e).abs() <= 0.01 * c, "cosine {c} vs {e}");
            let (c, e) = (CmisExact.denominator(&f, &hit), exact_k.denominator(&f, &hit));
            assert!((c - e).abs() <= 0.05 * c, "exact {c} vs {e}");
        }
    }

    #[test]
    fn names_round_trip_and_orientations_are_checked() {
        for e in Estimator::ALL {
            assert_eq!(e.name().parse::<Estimator>().unwrap(), e);
        }
        assert!("nope".parse::<Estimator>().is_err());
        assert!(Weighting::new(Estimator::SmisExact, Some(0)).is_err());
        assert!(Weighting::new(Estimator::CmisExact, Some(4)).is_err());
        assert_eq!(Weighting::new(Estimator::SmisExact, Some(4)).unwrap().label(), "smis-exact-k4");
    }
}
