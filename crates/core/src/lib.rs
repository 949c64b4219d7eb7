//! fogplanes: single scattering in a homogeneous fog box lit by rectangular lights, rendered
//! with photon planes and weighted by continuous and stochastic multiple importance sampling
//! (West et al., "Continuous Multiple Importance Sampling", TOG 2020, Section 6).
//!
//! This is the core library: no command line, no plots, no progress bars. The mathematics it
//! follows is written out in [`mathematics`] (the file `docs/mathematics.md`); "section N" in
//! the documentation below refers to it, "eq. (N)" to the paper.
//!
//! One module per concept (a directory where a concept has parts):
//!
//! | module | concept |
//! |---|---|
//! | [`scene`] | scene files: schema, validation, the validated [`scene::Scene`] and its light choice by power |
//! | [`limits`] | every range a setting must lie in, checked in one place |
//! | [`settings`] | what a user may set, resolved once: defaults, overrides, checks |
//! | [`outputs`] | every output path checked before any work |
//! | [`camera`] | the pinhole camera and its rays (section 7) |
//! | [`pixel`] | the pixel: its area, the ray sets and their plane groups (section 8) |
//! | [`emission`] | direct emission integrated over the pixel (section 8) |
//! | [`medium`] | the homogeneous medium box: clipping and transmittance |
//! | [`light`] | rectangular lights, their chords, and the ray-rectangle test |
//! | [`numeric`] | generic scalar arithmetic and the branch-free exponential |
//! | [`sampling`] | the plane samplers, the one hash and its random streams, warps, the chi-square test of samplers |
//! | [`sampling::sobol`] | the Owen-scrambled Sobol sequence (randomised quasi-Monte Carlo) |
//! | [`sampling::Kronecker`] | the reference's low-discrepancy sequence (section 4) |
//! | [`photon_plane`] | photon-plane sampling (section 2) and the clipped plane polygon |
//! | [`weights`] | the estimators: their registry and dispatch (`mod.rs`), their denominators D (`denominators.rs`, section 2), the closed form of cmis-exact in f64 and f32 (`closed_form.rs`, section 3) |
//! | [`gather`] | one ray against one plane: hit test and weighted contribution, written once |
//! | [`kernel`] | the span kernels (AVX-512, AVX2, portable) and the choice between them |
//! | [`raster`] | the intersection structure: planes rasterised in screen space |
//! | [`bvh`] | a bounding volume hierarchy over planes, for arbitrary rays |
//! | [`film`] | pixel buffers and EXR / PNG files, written whole or not at all, each EXR recording how it was made |
//! | [`render`] | the photon-plane renderer and its options |
//! | [`partial`] | partial renders: canonical chunks of the plane set, their f64 sums, the canonical merge |
//! | [`control`] | following and stopping a long job: progress callback and cancel flag |
//! | [`reference`](mod@reference) | the independent reference renderer (section 4) |
//! | [`metrics`] | SMAPE, MSE and friends (section 5) |
//! | [`quadrature`] | deterministic quadrature, the ground truth for single rays |
//! | [`export`] | the scene as a Mitsuba 3 XML file, to check against an outside renderer |
//! | [`error`] | the library's typed errors |

/// `Display` and `FromStr` of a named choice (estimator, sampler, kernel, accelerator) from its
/// `name()` and `ALL`: written once, so that every choice prints and parses alike.
#[macro_export]
#[doc(hidden)]
macro_rules! named_choice {
    ($t:ty, $what:literal) => {
        impl std::fmt::Display for $t {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }
        impl std::str::FromStr for $t {
            type Err = String;
            fn from_str(s: &str) -> std::result::Result<Self, String> {
                $crate::parse_name($what, s, &<$t>::ALL, <$t>::name)
            }
        }
    };
}

pub mod accel;
pub mod bvh;
pub mod camera;
pub mod control;
pub mod emission;
pub mod error;
pub mod export;
pub mod film;
pub mod gather;
pub mod kernel;
pub mod light;
pub mod limits;
pub mod medium;
pub mod merge;
pub mod metrics;
pub mod numeric;
pub mod occlusion;
pub mod options;
pub mod outputs;
pub mod partial;
pub mod photon_plane;
pub mod pixel;
pub mod quadrature;
pub mod raster;
pub mod reference;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod settings;
pub mod weights;

pub use error::{Error, Result};

/// Parses `s` as the member of the closed list `all` whose name it is, or says which names
/// there are: the `FromStr` of every named choice (estimator, sampler, kernel, accelerator).
#[doc(hidden)]
pub fn parse_name<T: Copy>(
    what: &str,
    s: &str,
    all: &[T],
    name: fn(T) -> &'static str,
) -> std::result::Result<T, String> {
    all.iter().copied().find(|&x| name(x) == s).ok_or_else(|| {
        let names: Vec<_> = all.iter().map(|&x| name(x)).collect();
        format!("unknown {what} {s:?}; expected one of {}", names.join(", "))
    })
}

#[doc = include_str!("../../../docs/mathematics.md")]
pub mod mathematics {}
