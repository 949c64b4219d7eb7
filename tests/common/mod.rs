//! Shared by the statistical tests: the mean of independent estimates, its standard error, and
//! how many standard errors it lies from a truth.
#![allow(dead_code)] // each test file uses its own part

use fogplanes::camera::CameraRay;
use fogplanes::gather::GatherContext;
use fogplanes::options::RenderOptions;
use fogplanes::scene::Scene;
use fogplanes::settings::Overrides;
use fogplanes::weights::{Denominator, WithDenominator};
use std::path::PathBuf;
use std::process::{Command, Output, Stdio};

/// The options `given` resolve to for `scene`: the one way to make render options, as every
/// front end makes them.
pub fn options(scene: &Scene, given: Overrides) -> RenderOptions {
    given.resolve(scene).unwrap().options
}

/// A small fog box with two lights that cannot shadow each other (each lies behind the other's
/// plane): a ceiling panel facing down, and a small panel tilted in the slab above it facing +x
/// and down. RGB coefficients so that each channel is checked on its own.
pub const TWO_LIGHTS: &str = r#"
[camera]
position = [0.0, 1.5, 6.0]
look_at = [0.0, 1.5, 0.0]
up = [0.0, 1.0, 0.0]
vfov_deg = 50.0
resolution = [64, 48]

[medium]
min = [-2.0, 0.0, -2.0]
max = [2.0, 3.0, 2.0]
sigma_s = [0.5, 0.3, 0.2]
sigma_a = [0.1, 0.2, 0.05]

[[light]]
name = "ceiling"
corner = [-0.5, 2.9, -0.25]
edge_u = [1.0, 0.0, 0.0]
edge_v = [0.0, 0.0, 0.5]
radiance = [4.0, 3.0, 2.0]

[[light]]
name = "tilted"
corner = [1.2, 2.9, -0.5]
edge_u = [0.2, 0.1, 0.0]
edge_v = [0.0, 0.0, 1.0]
radiance = [1.0, 2.0, 6.0]
"#;

/// One weighting's estimate for a ray from a set of prepared planes, every plane tested.
pub struct BruteForce<'a> {
    pub ctx: &'a GatherContext,
    pub ray: &'a CameraRay,
}

impl WithDenominator for BruteForce<'_> {
    type Output = glam::Vec3;
    fn run<D: Denominator>(self, weights: &D) -> glam::Vec3 {
        self.ctx.gather_brute_force(weights, self.ray).0
    }
}

/// Values computed once per key for the process, each kept for its lifetime: the first test
/// that asks for a key's value makes it, and a second that wants it meanwhile waits for it,
/// while values of other keys are made beside it (the lock is held only to find or add the
/// key's cell). For costly values that tests share, made the same way each time.
pub struct Memo<K, V: 'static> {
    cells: std::sync::Mutex<Vec<(K, &'static std::sync::OnceLock<V>)>>,
}

impl<K: PartialEq, V> Memo<K, V> {
    pub const fn new() -> Self {
        Memo { cells: std::sync::Mutex::new(Vec::new()) }
    }

    pub fn get(&self, key: K, make: impl FnOnce() -> V) -> &'static V {
        let cell = {
            let mut cells = self.cells.lock().unwrap_or_else(|p| p.into_inner());
            match cells.iter().find(|(k, _)| *k == key) {
                Some(&(_, cell)) => cell,
                None => {
                    let cell: &'static std::sync::OnceLock<V> = Box::leak(Box::new(std::sync::OnceLock::new()));
                    cells.push((key, cell));
                    cell
                }
            }
        };
        cell.get_or_init(make)
    }
}

/// Running sums of independent estimates of one quantity.
#[derive(Clone, Copy, Debug, Default)]
pub struct MeanEstimate {
    sum: f64,
    sum_sq: f64,
    n: f64,
}

impl MeanEstimate {
    pub fn add(&mut self, x: f64) {
        self.sum += x;
        self.sum_sq += x * x;
        self.n += 1.0;
    }

    pub fn count(&self) -> usize {
        self.n as usize
    }

    pub fn mean(&self) -> f64 {
        self.sum / self.n
    }

    /// The standard error of the mean: the sample standard deviation (n - 1) over sqrt(n).
    pub fn stderr(&self) -> f64 {
        let m = self.mean();
        ((self.sum_sq / self.n - m * m).max(0.0) * self.n / (self.n - 1.0) / self.n).sqrt()
    }

    /// (mean - truth) in standard errors, with `truth_stderr` (the truth's own noise, 0 for an
    /// exact value) combined in quadrature.
    pub fn z(&self, truth: f64, truth_stderr: f64) -> f64 {
        (self.mean() - truth) / self.stderr().hypot(truth_stderr)
    }
}

/// One [`MeanEstimate`] per RGB channel.
#[derive(Clone, Copy, Debug, Default)]
pub struct MeanRgb(pub [MeanEstimate; 3]);

impl MeanRgb {
    pub fn add(&mut self, v: glam::Vec3) {
        for c in 0..3 {
            self.0[c].add(v[c] as f64);
        }
    }
}

#[test]
fn the_standard_error_of_known_samples() {
    let mut m = MeanEstimate::default();
    for x in [1.0, 2.0, 3.0, 4.0] {
        m.add(x);
    }
    // Sample variance 5/3, standard error sqrt(5/3 / 4).
    assert!((m.mean() - 2.5).abs() < 1e-15);
    assert!((m.stderr() - (5.0f64 / 12.0).sqrt()).abs() < 1e-15);
    assert!((m.z(2.0, 0.0) - 0.5 / (5.0f64 / 12.0).sqrt()).abs() < 1e-12);
}

/// Runs the command line with `args`, its output captured.
pub fn fogplanes(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fogplanes")).args(args).output().expect("the binary runs")
}

/// The one error line and exit code 2 of a refused command.
pub fn refused(args: &[&str]) -> String {
    let o = fogplanes(args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    err
}

/// Runs `command` with its output captured; kills it and fails the test if it runs longer than
/// `seconds` (a hostile input must be refused, not read forever).
pub fn output_within(seconds: u64, mut command: Command, what: &str) -> Output {
    let mut child = command.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("the binary runs");
    let start = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed().as_secs() >= seconds {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("{what} did not finish within {seconds} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// An empty directory of this test process's own, named `name`.
pub fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fogplanes-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
