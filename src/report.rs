//! The estimator table, the image panel and the error-versus-time plot.

use crate::film::Film;
use crate::scene::Scene;
use crate::weights::Weighting;
use anyhow::Result;
use std::path::PathBuf;

pub struct TableOptions {
    pub planes: usize,
    pub seed: u64,
    pub pixel_center: bool,
    pub sweep: Vec<usize>,
    pub sweep_seeds: u32,
    pub extra: Vec<Weighting>,
    pub out: PathBuf,
    pub exposure: f32,
    pub quiet: bool,
    pub reference_path: PathBuf,
}

pub fn run_table(_scene: &Scene, _reference: &Film, _opts: &TableOptions) -> Result<String> {
    anyhow::bail!("not yet")
}
