//! fogplanes: single scattering in a homogeneous fog box lit by rectangular lights, rendered
//! with photon planes and weighted by continuous and stochastic multiple importance sampling
//! (West et al., "Continuous Multiple Importance Sampling", TOG 2020, Section 6).
//!
//! This is the core library: no command line, no plots, no progress bars. The mathematics it
//! follows is written out in [`mathematics`] (the file `docs/mathematics.md`); "section N" in
//! the documentation below refers to it, "eq. (N)" to the paper.
//!
//! One module per concept (a directory where a concept has parts), in layers that read like
//! `docs/mathematics.md`: a module takes names only from the layers above it in this table
//! (lower layers first), never from its own layer's later rows or from below.
//!
//! | layer | module | what it holds |
//! |---|---|---|
//! | foundations | [`numeric`] | generic scalar arithmetic and the branch-free exponential |
//! | | [`error`] | the library's typed errors, and the closed list of settings they name |
//! | | [`schedule`] | a record of a job's units of work and their order, for the schedule model (`scripts/scaling_model.py`) |
//! | | [`control`] | following and stopping a long job: progress callback and cancel flag |
//! | | [`limits`] | every default of a render, every range a setting must lie in, the memory rule |
//! | | [`sampling`] | the plane samplers (Owen-scrambled Sobol, independent), the one hash and its random streams, warps, the Kronecker sequence of the reference (section 4), the chi-square test |
//! | the scene | [`medium`] | the homogeneous medium box: clipping and transmittance |
//! | | [`light`] | rectangular lights, their chords, and the ray-rectangle test |
//! | | [`camera`] | the pinhole camera and its rays, [`camera::CameraRay`] (section 7) |
//! | | [`scene`] | scene files: schema, validation, the validated [`scene::Scene`] and its light choice by power |
//! | planes | [`photon_plane`] | photon-plane sampling (section 2), the plane set, the clipped plane polygon |
//! | | [`weights`] | the estimators: their registry and dispatch (`mod.rs`), their denominators D (`denominators.rs`, section 2), the closed form of cmis-exact (`closed_form.rs`, section 3) |
//! | one hit | [`gather`] | one ray against one plane: hit test and weighted contribution `C = eta / (N P_l D)` (summed light by light, its factor `power / N` applied once per light), written once for every vector width |
//! | | [`occlusion`] | which other panels may shadow a plane, and the per-hit test (section 2.3) |
//! | traversal | [`kernel`] | the span kernels (AVX-512, AVX2, portable, per-hit) and the choice between them; the [`kernel::Aggregate`] interface every structure answers |
//! | | [`raster`] | planes rasterised in screen space: the fast structure for camera rays |
//! | | [`bvh`] | a bounding volume hierarchy over planes, for arbitrary rays |
//! | | [`gpu`] | the GPU through wgpu: the planes binned to tiles and gathered in WGSL compute shaders (`gather.wgsl`, `bin.wgsl`), the adapter found once (docs/gpu.md) |
//! | | [`accel`] | the prepared planes of a render behind one gather, whatever the structure |
//! | pixels and film | [`pixel`] | the pixel: the ray sets that sample it, their plane groups, the one cache of ray sets (section 8.1) |
//! | | [`emission`] | direct emission integrated over the pixel (section 8.2) |
//! | | [`film`] | pixel buffers, the one place an image is finished ([`film::Film::finish`]), EXR / PNG files written whole or not at all, each EXR recording how it was made |
//! | | [`spread`] | a render's error image, from the spread of its plane groups (section 10) |
//! | | [`display`] | a live view of a running job in the tev image viewer, over its TCP protocol |
//! | | [`metrics`] | SMAPE, MSE and friends (section 5) |
//! | | [`outputs`] | every output path checked before any work |
//! | options | [`options`] | a render's options resolved (built by [`settings`] alone) and what a render measured |
//! | partials | [`partial`] | canonical chunks of the plane set, their f64 sums, the canonical merge tree and its plan; the part files and checkpoints |
//! | drivers | [`render`] | the renders: the one loop over plane groups and ray sets, in canonical chunks, in plane passes, for the table |
//! | | [`reference`](mod@reference) | the independent reference renderer (section 4) |
//! | | [`quadrature`] | deterministic quadrature, the ground truth for single rays |
//! | | [`export`] | the scene as a Mitsuba 3 XML file, to check against an outside renderer |
//! | settings | [`settings`] | what a user may set, resolved once: defaults, overrides, checks |
//! | | [`merge`] | part files merged into images, their recorded settings resolved like a caller's |

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
pub mod display;
pub mod emission;
pub mod error;
pub mod export;
pub mod film;
pub mod gather;
pub mod gpu;
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
pub mod schedule;
pub mod settings;
pub mod simd;
pub mod spread;
pub mod trace;
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
