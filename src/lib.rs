//! fogplanes: single scattering in a homogeneous fog box lit by rectangular lights, rendered
//! with photon planes and weighted by continuous and stochastic multiple importance sampling.
//!
//! The mathematics and conventions are those of `SPEC.md` (kept beside the project as
//! `../shared/SPEC.md`); section numbers in the documentation below refer to it, equation
//! numbers to the source paper (West et al., "Continuous Multiple Importance Sampling", 2020).
//!
//! One module per concept:
//!
//! | module | concept |
//! |---|---|
//! | [`scene`] | scene files: schema, validation, the validated [`scene::Scene`] |
//! | [`camera`] | the pinhole camera and its rays (section 6) |
//! | [`medium`] | the homogeneous medium box: clipping and transmittance |
//! | [`light`] | rectangular lights and their chords |
//! | [`sampling`] | random numbers and elementary sampling routines |
//! | [`photon_plane`] | photon-plane sampling (section 2) and the clipped plane polygon |
//! | [`weights`] | the estimators' denominators D, including the closed-form CMIS one |
//! | [`gather`] | one ray against one plane: hit test and weighted contribution |
//! | [`raster`] | the intersection structure: planes rasterised in screen space |
//! | [`bvh`] | a bounding volume hierarchy over planes, for arbitrary rays |
//! | [`film`] | pixel buffers and EXR / PNG input and output |
//! | [`render`] | the photon-plane renderer |
//! | [`reference`] | the independent reference renderer (section 3) |
//! | [`metrics`] | SMAPE, MSE and friends (section 4) |
//! | [`report`] | the estimator table, image panel and error-versus-time plot |
//! | [`quadrature`] | deterministic quadrature, the ground truth for single rays |

pub mod bvh;
pub mod camera;
pub mod film;
pub mod gather;
pub mod light;
pub mod medium;
pub mod metrics;
pub mod photon_plane;
pub mod quadrature;
pub mod raster;
pub mod reference;
pub mod render;
pub mod report;
pub mod sampling;
pub mod scene;
pub mod weights;

/// Luminance of a linear RGB triple (Rec. 709 weights), used to choose lights by power.
pub fn luminance(rgb: glam::DVec3) -> f64 {
    0.2126 * rgb.x + 0.7152 * rgb.y + 0.0722 * rgb.z
}
