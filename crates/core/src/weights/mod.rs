//! The estimators: their registry, and the dispatch from a name to a monomorphised gathering
//! loop. The estimators differ only in the denominator `D` of docs/mathematics.md section 2
//! ([`Denominator`], in `denominators.rs`): a hit contributes `eta / (N P_l D)`. The closed form of
//! `cmis-exact` (section 3) is in `closed_form.rs`.
//!
//! Notation (docs/mathematics.md section 2): `det(beta) = (d(beta) x wl) . we = cos(beta) a_u + sin(beta) a_v`,
//! `g(beta) = width(beta, y') |det(beta)|`, the path density `p(x | beta)` of paper eq. (25) up to
//! factors shared by all orientations.

mod closed_form;
mod denominators;

pub use closed_form::{cmis_exact_mean, cmis_exact_mean_f32};
pub use denominators::{
    CmisCosine, CmisExact, CmisPlane, Denominator, HitLanes, HitLocal, Orientation, PlaneFrame, PlaneOrientations,
    SmisCosinePair, SmisExactPair, StratifiedK, Unweighted,
};

use crate::limits::MAX_ORIENTATIONS;
use std::fmt;

/// The weighting schemes: the closed list of estimators. Everything that names or dispatches
/// an estimator reads it from here ([`Estimator::ALL`], [`Estimator::info`],
/// [`Weighting::dispatch`]), so a new weighting is a variant, its [`Denominator`] (in `denominators.rs`),
/// one arm in `info` and one in `dispatch`, and its unit tests: this directory only.
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
    /// The denominator D of a hit's contribution eta / (N P_l D) (docs/mathematics.md section 2).
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
            Estimator::CmisExact => (
                "cmis-exact",
                "eq. 24, not evaluated in the paper: closed form",
                "(1/pi) integral of g over [0, pi)",
                false,
            ),
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

crate::named_choice!(Estimator, "estimator");

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
    /// `estimator` with K `orientations` (2 if `None`). The error names no source: the caller
    /// prefixes the flag, the keyword or the scene's key that gave K (a scene's
    /// `render.orientations` was told "--orientations applies to ...").
    pub fn new(estimator: Estimator, orientations: Option<u32>) -> Result<Self, String> {
        match orientations {
            None => Ok(Weighting { estimator, orientations: 2 }),
            Some(k) if !estimator.has_orientations() && k != 2 => {
                let with: Vec<_> = Estimator::ALL.iter().filter(|e| e.has_orientations()).map(|e| e.name()).collect();
                Err(format!("the number of orientations applies to {} only, not to {estimator}", with.join(" and ")))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_orientations_are_checked() {
        for e in Estimator::ALL {
            assert_eq!(e.name().parse::<Estimator>().unwrap(), e);
        }
        assert!("nope".parse::<Estimator>().is_err());
        assert!(Weighting::new(Estimator::SmisExact, Some(0)).is_err());
        assert!(Weighting::new(Estimator::CmisExact, Some(4)).is_err());
        // Worded for any source (the flag, the keyword, the scene's key), naming none itself.
        for k in [0, 4, 65] {
            let e = if k == 4 { Estimator::CmisExact } else { Estimator::SmisExact };
            let message = Weighting::new(e, Some(k)).unwrap_err();
            assert!(!message.contains("--") && message.starts_with("the number of orientations"), "{message}");
        }
        assert_eq!(Weighting::new(Estimator::SmisExact, Some(4)).unwrap().label(), "smis-exact-k4");
    }
}
