//! The experiments the command line runs: the estimator table with its error-versus-time sweep
//! (docs/mathematics.md section 5) and the scaling study. Each gathers numbers and hands them to
//! [`crate::pictures`] to draw.
//!
//! Every estimator gathers the same planes along the same camera rays (pixel centres by
//! default), so the planes are the only source of difference between them, and each is timed on
//! its own. Speed against error is reported as efficiency 1 / (MSE x seconds), with both the
//! gathering time and the whole time (plane sampling, structure build, rays and gathering).

use crate::page::{PageImage, PageInput, comparison_page, html_table};
use crate::pictures::{plot_error_vs_time, plot_scaling, save_panel};
use crate::system::{cpu_seconds, peak_memory_bytes};
use anyhow::{Context, Result};
use fogplanes::control::Control;
use fogplanes::film::{Film, write_file_atomically};
use fogplanes::gather::GatherStats;
use fogplanes::kernel::Kernel;
use fogplanes::metrics::{ErrorMetrics, compare};
use fogplanes::render::{Accelerator, PreparedPlanes, RenderOptions, camera_rays, render, render_for};
use fogplanes::sampling::Sampler;
use fogplanes::scene::Scene;
use fogplanes::weights::{Estimator, Weighting};
use glam::Vec3;
use std::path::PathBuf;
use std::time::Instant;

pub struct TableOptions {
    pub planes: usize,
    pub seed: u64,
    pub pixel_center: bool,
    /// Plane counts of the error-versus-time sweep (empty: no sweep).
    pub sweep: Vec<usize>,
    pub sweep_seeds: u32,
    /// The weightings of the table, the baseline ([`Estimator::BASELINE`]) among them.
    pub weightings: Vec<Weighting>,
    /// The plane samplers; every weighting is measured with each.
    pub samplers: Vec<Sampler>,
    /// Seconds of each render at equal time (none: no equal-time comparison).
    pub equal_time: Option<f64>,
    pub out: PathBuf,
    pub exposure: f32,
    pub quiet: bool,
    pub reference_path: PathBuf,
}

/// One line of the table: a weighting gathering the planes of one sampler.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Entry {
    pub weighting: Weighting,
    pub sampler: Sampler,
}

impl Entry {
    /// `smis-exact` for the default sampler, `smis-exact/independent` for another.
    pub fn label(&self) -> String {
        if self.sampler == Sampler::default() {
            self.weighting.label()
        } else {
            format!("{}/{}", self.weighting.label(), self.sampler)
        }
    }
}

/// One estimator's row.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Row {
    /// The label: the weighting, with `/independent` for independent planes.
    pub estimator: String,
    pub weighting: String,
    pub sampler: String,
    pub planes: usize,
    pub hits: u64,
    /// Ray-plane tests per hit, and wall nanoseconds of gathering per hit.
    pub tests_per_hit: f64,
    pub gather_ns_per_hit: f64,
    pub gather_seconds: f64,
    pub total_seconds: f64,
    pub metrics: ErrorMetrics,
    pub smape_e2: f64,
    pub mse_e4: f64,
    /// 1 / (MSE x gather seconds) and 1 / (MSE x total seconds).
    pub efficiency_gather: f64,
    pub efficiency_total: f64,
    /// Ratios to the baseline (`unweighted` with independent planes, the paper's, when
    /// measured): MSE, gather time, efficiency (gather), efficiency (total).
    pub mse_vs_unweighted: f64,
    pub gather_time_vs_unweighted: f64,
    pub efficiency_gather_vs_unweighted: f64,
    pub efficiency_total_vs_unweighted: f64,
    /// MSE over the same weighting's with independent planes (1 for those).
    pub mse_vs_independent: Option<f64>,
}

/// One point of the sweep: mean over seeds at one plane count.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SweepPoint {
    pub estimator: String,
    pub planes: usize,
    pub seeds: u32,
    pub mse: f64,
    pub smape: f64,
    pub gather_seconds: f64,
    pub total_seconds: f64,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Table {
    pub scene: String,
    pub reference: String,
    pub resolution: [u32; 2],
    pub pixel_center: bool,
    pub seed: u64,
    /// Shared by all estimators of the first sampler: plane sampling, structure build, rays.
    pub shared_seconds: f64,
    pub rows: Vec<Row>,
    pub sweep: Vec<SweepPoint>,
    /// Every entry rendered for the same wall time ([`fogplanes::render::render_for`]).
    pub equal_time: Vec<EqualTimeRow>,
}

/// One entry rendered within a time budget: as many planes as it can gather in that time.
#[derive(Clone, Debug, serde::Serialize)]
pub struct EqualTimeRow {
    pub estimator: String,
    pub weighting: String,
    pub sampler: String,
    pub budget_seconds: f64,
    pub seconds: f64,
    pub planes: usize,
    pub plane_passes: u32,
    pub metrics: ErrorMetrics,
    /// MSE over the baseline's at the same time.
    pub mse_vs_unweighted: f64,
}

/// Renders every entry for `budget` seconds (pixel centres as the table, the table's seed) and
/// measures each against the reference.
fn equal_time(
    scene: &Scene,
    reference: &Film,
    opts: &TableOptions,
    budget: f64,
    log: &dyn Fn(String),
) -> Result<Vec<EqualTimeRow>> {
    let mut rows = Vec::new();
    for &sampler in &opts.samplers {
        for &weighting in &opts.weightings {
            let entry = Entry { weighting, sampler };
            let options = RenderOptions {
                weighting,
                sampler,
                seed: opts.seed,
                pixel_center: opts.pixel_center,
                ..RenderOptions::default()
            };
            let (film, st) = render_for(scene, &options, std::time::Duration::from_secs_f64(budget), Control::none())?;
            let metrics = compare(&film, reference)?;
            log(format!("equal time: {} {} planes in {:.2} s", entry.label(), st.planes, st.seconds_total));
            rows.push(EqualTimeRow {
                estimator: entry.label(),
                weighting: weighting.label(),
                sampler: sampler.to_string(),
                budget_seconds: budget,
                seconds: st.seconds_total,
                planes: st.planes,
                plane_passes: st.plane_passes,
                metrics,
                mse_vs_unweighted: 0.0,
            });
        }
    }
    let base = rows
        .iter()
        .find(|r| r.weighting == Estimator::BASELINE.name() && r.sampler == Sampler::Independent.name())
        .or_else(|| rows.iter().find(|r| r.weighting == Estimator::BASELINE.name()))
        .map(|r| r.metrics.mse)
        .context("the equal-time table needs its baseline estimator")?;
    for r in &mut rows {
        r.mse_vs_unweighted = r.metrics.mse / base;
    }
    Ok(rows)
}

/// What one entry measured over one plane set.
pub struct Measured {
    pub entry: Entry,
    pub film: Film,
    pub stats: GatherStats,
    pub gather_seconds: f64,
    /// Sampling the planes, building the structure and making the rays, shared by every
    /// weighting of the same sampler.
    pub shared_seconds: f64,
}

/// One measurement: every weighting over the plane set of each sampler.
fn measure(
    scene: &Scene,
    weightings: &[Weighting],
    samplers: &[Sampler],
    planes: usize,
    seed: u64,
    pixel_center: bool,
) -> Vec<Measured> {
    let kernel = Kernel::Auto.resolve().expect("auto always resolves");
    let mut out = Vec::new();
    for &sampler in samplers {
        let start = Instant::now();
        let prepared = PreparedPlanes::new(scene, planes, seed, sampler, Accelerator::Raster, Control::none())
            .expect("never cancelled");
        let pass = camera_rays(scene, seed, 0, pixel_center);
        let shared_seconds = start.elapsed().as_secs_f64();
        for &weighting in weightings {
            let t = Instant::now();
            let mut sums = vec![Vec3::ZERO; pass.rays.len()];
            let stats =
                prepared.gather(weighting, kernel, &pass.rays, &mut sums, Control::none()).expect("never cancelled");
            let gather_seconds = t.elapsed().as_secs_f64();
            let mut film = Film::new(scene.camera.width, scene.camera.height);
            for ((f, s), e) in film.pixels.iter_mut().zip(&sums).zip(&pass.emission) {
                *f = *s + *e;
            }
            out.push(Measured { entry: Entry { weighting, sampler }, film, stats, gather_seconds, shared_seconds });
        }
    }
    out
}

/// Renders, measures and writes table.md, table.json, panel.png, error_vs_time.png/.svg and
/// index.html (the comparison page, [`crate::page`]).
pub fn run_table(scene: &Scene, reference: &Film, opts: &TableOptions) -> Result<String> {
    let weightings = &opts.weightings;
    let log = |s: String| {
        if !opts.quiet {
            eprintln!("{s}");
        }
    };
    log(format!("table: {} estimators x {} samplers, {} planes", weightings.len(), opts.samplers.len(), opts.planes));
    let results = measure(scene, weightings, &opts.samplers, opts.planes, opts.seed, opts.pixel_center);
    let mut rows = Vec::new();
    for r in &results {
        let (m, stats, gather) = (compare(&r.film, reference)?, r.stats, r.gather_seconds);
        let total = r.shared_seconds + gather;
        rows.push(Row {
            estimator: r.entry.label(),
            weighting: r.entry.weighting.label(),
            sampler: r.entry.sampler.to_string(),
            planes: opts.planes,
            hits: stats.hits,
            tests_per_hit: stats.tests as f64 / stats.hits.max(1) as f64,
            gather_ns_per_hit: 1e9 * gather / stats.hits.max(1) as f64,
            gather_seconds: gather,
            total_seconds: total,
            metrics: m,
            smape_e2: m.smape_e2(),
            mse_e4: m.mse_e4(),
            efficiency_gather: 1.0 / (m.mse * gather),
            efficiency_total: 1.0 / (m.mse * total),
            mse_vs_unweighted: 0.0,
            gather_time_vs_unweighted: 0.0,
            efficiency_gather_vs_unweighted: 0.0,
            efficiency_total_vs_unweighted: 0.0,
            mse_vs_independent: None,
        });
    }
    let find = |weighting: &str, sampler: Sampler| {
        rows.iter().find(|r| r.weighting == weighting && r.sampler == sampler.name()).cloned()
    };
    let base = find(Estimator::BASELINE.name(), Sampler::Independent)
        .or_else(|| find(Estimator::BASELINE.name(), opts.samplers[0]))
        .context("the table needs its baseline estimator")?;
    let independent: Vec<Option<Row>> = rows.iter().map(|r| find(&r.weighting, Sampler::Independent)).collect();
    for (r, ind) in rows.iter_mut().zip(independent) {
        r.mse_vs_unweighted = r.metrics.mse / base.metrics.mse;
        r.gather_time_vs_unweighted = r.gather_seconds / base.gather_seconds;
        r.efficiency_gather_vs_unweighted = r.efficiency_gather / base.efficiency_gather;
        r.efficiency_total_vs_unweighted = r.efficiency_total / base.efficiency_total;
        r.mse_vs_independent = ind.map(|i| r.metrics.mse / i.metrics.mse);
    }

    let mut sweep = Vec::new();
    for &n in &opts.sweep {
        let mut acc: Vec<(f64, f64, f64, f64)> = vec![(0.0, 0.0, 0.0, 0.0); results.len()];
        for s in 0..opts.sweep_seeds {
            let seed = opts.seed.wrapping_add(1000).wrapping_add(s as u64);
            for (a, r) in acc.iter_mut().zip(measure(scene, weightings, &opts.samplers, n, seed, opts.pixel_center)) {
                let m = compare(&r.film, reference)?;
                let g = r.gather_seconds;
                *a = (a.0 + m.mse, a.1 + m.smape, a.2 + g, a.3 + r.shared_seconds + g);
            }
        }
        let k = opts.sweep_seeds.max(1) as f64;
        for (r, a) in results.iter().zip(&acc) {
            sweep.push(SweepPoint {
                estimator: r.entry.label(),
                planes: n,
                seeds: opts.sweep_seeds,
                mse: a.0 / k,
                smape: a.1 / k,
                gather_seconds: a.2 / k,
                total_seconds: a.3 / k,
            });
        }
        log(format!("sweep: {n} planes done"));
    }

    let equal_time = match opts.equal_time {
        Some(budget) => equal_time(scene, reference, opts, budget, &log)?,
        None => Vec::new(),
    };

    let table = Table {
        scene: scene.name.clone(),
        reference: opts.reference_path.display().to_string(),
        resolution: [scene.camera.width, scene.camera.height],
        pixel_center: opts.pixel_center,
        seed: opts.seed,
        shared_seconds: results.first().map_or(0.0, |r| r.shared_seconds),
        rows,
        sweep,
        equal_time,
    };
    let markdown = table.markdown();
    write_file_atomically(&opts.out.join("table.md"), markdown.as_bytes())?;
    let json = serde_json::to_string_pretty(&table).context("cannot format the table as JSON")?;
    write_file_atomically(&opts.out.join("table.json"), json.as_bytes())?;
    // The panel shows the default sampler's images (the other's look alike at this size).
    let images: Vec<(String, &Film)> = results
        .iter()
        .filter(|r| r.entry.sampler == opts.samplers[0])
        .map(|r| (r.entry.weighting.label(), &r.film))
        .collect();
    save_panel(&images, reference, opts.exposure, &opts.out.join("panel.png"))?;
    let svg = if table.sweep.is_empty() { None } else { Some(plot_error_vs_time(&table, &opts.out)?) };

    // The comparison page: the reference and every entry's image, the table, the plot.
    let pixels = |film: &Film| film.pixels.iter().map(|p| p.to_array()).collect::<Vec<[f32; 3]>>();
    let (width, height) = (reference.width, reference.height);
    let reference_pixels = pixels(reference);
    // The images of the first sampler's planes, as in the panel (a page of every sampler's
    // would be twice the size for pictures that look alike); the table has every row.
    let shown: Vec<&Measured> = results.iter().filter(|r| r.entry.sampler == opts.samplers[0]).collect();
    let labels: Vec<String> = shown.iter().map(|r| r.entry.label()).collect();
    let estimator_pixels: Vec<Vec<[f32; 3]>> = shown.iter().map(|r| pixels(&r.film)).collect();
    let (title, table_html, notes) =
        (format!("fogplanes: {} estimators", table.scene), table.html(), table.notes(opts.planes));
    let page = comparison_page(&PageInput {
        title: &title,
        reference: PageImage { label: "reference", width, height, pixels: &reference_pixels },
        images: labels
            .iter()
            .zip(&estimator_pixels)
            .map(|(label, p)| PageImage { label, width, height, pixels: p })
            .collect(),
        table_html: &table_html,
        plot_svg: svg.as_deref(),
        notes: &notes,
    })
    .context("cannot make the comparison page")?;
    write_file_atomically(&opts.out.join("index.html"), page.as_bytes())?;
    Ok(markdown)
}

/// The table's columns, in the Markdown table and the page's HTML table alike.
const COLUMNS: [&str; 15] = [
    "estimator",
    "sampler",
    "planes",
    "hits",
    "ns/hit",
    "gather s",
    "total s",
    "SMAPE x10^2",
    "MSE x10^4",
    "1/(MSE s) gather",
    "1/(MSE s) total",
    "MSE vs unweighted",
    "gather time vs unweighted",
    "efficiency vs unweighted (gather / total)",
    "MSE vs independent",
];

/// The columns of the equal-time table.
const EQUAL_TIME_COLUMNS: [&str; 8] =
    ["estimator", "sampler", "seconds", "planes", "plane passes", "SMAPE x10^2", "MSE x10^4", "MSE vs unweighted"];

impl EqualTimeRow {
    fn cells(&self) -> Vec<String> {
        vec![
            self.sampler.clone(),
            format!("{:.2}", self.seconds),
            self.planes.to_string(),
            self.plane_passes.to_string(),
            format!("{:.4}", self.metrics.smape_e2()),
            format!("{:.4}", self.metrics.mse_e4()),
            format!("{:.3}", self.mse_vs_unweighted),
        ]
    }
}

impl Row {
    /// The cells after the row's label, as both tables print them.
    fn cells(&self) -> Vec<String> {
        vec![
            self.sampler.clone(),
            self.planes.to_string(),
            format!("{:.3e}", self.hits as f64),
            format!("{:.2}", self.gather_ns_per_hit),
            format!("{:.3}", self.gather_seconds),
            format!("{:.3}", self.total_seconds),
            format!("{:.4}", self.smape_e2),
            format!("{:.4}", self.mse_e4),
            format!("{:.4e}", self.efficiency_gather),
            format!("{:.4e}", self.efficiency_total),
            format!("{:.3}", self.mse_vs_unweighted),
            format!("{:.3}", self.gather_time_vs_unweighted),
            format!("{:.2} / {:.2}", self.efficiency_gather_vs_unweighted, self.efficiency_total_vs_unweighted),
            self.mse_vs_independent.map_or("-".to_string(), |v| format!("{v:.3}")),
        ]
    }
}

impl Table {
    /// What was rendered: scene, resolution, rays and seed.
    fn setting(&self) -> String {
        let rays = if self.pixel_center { "pixel-centre" } else { "jittered" };
        let [w, h] = self.resolution;
        format!("{} at {w}x{h}, {rays} rays, seed {}", self.scene, self.seed)
    }

    /// The line above the table: the setting, the reference, the shared time.
    fn summary(&self) -> String {
        format!(
            "{}, against `{}`; {:.3} s shared (planes, structure, rays).",
            self.setting(),
            self.reference,
            self.shared_seconds
        )
    }

    pub fn markdown(&self) -> String {
        let mut s = format!("{}\n\n| {} |\n", self.summary(), COLUMNS.join(" | "));
        s += "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
        for r in &self.rows {
            s += &format!("| {} | {} |\n", r.weighting, r.cells().join(" | "));
        }
        if let Some(first) = self.equal_time.first() {
            s += &format!(
                "\nAt equal time: {:.2} s of wall time for each (a render on a time budget, planes in passes).\n\n| {} |\n|---|---|---:|---:|---:|---:|---:|---:|\n",
                first.budget_seconds,
                EQUAL_TIME_COLUMNS.join(" | ")
            );
            for r in &self.equal_time {
                s += &format!("| {} | {} |\n", r.weighting, r.cells().join(" | "));
            }
        }
        s
    }

    /// The same table as HTML, for the comparison page (rows named by the page's labels, so
    /// that clicking a row shows its image).
    fn html(&self) -> String {
        let rows: Vec<(&str, Vec<String>)> = self.rows.iter().map(|r| (r.estimator.as_str(), r.cells())).collect();
        let mut html = html_table(&COLUMNS, &rows);
        if !self.equal_time.is_empty() {
            let rows: Vec<(&str, Vec<String>)> =
                self.equal_time.iter().map(|r| (r.estimator.as_str(), r.cells())).collect();
            html += &html_table(&EQUAL_TIME_COLUMNS, &rows);
        }
        html
    }

    /// The page's notes: what was measured, against what.
    fn notes(&self, planes: usize) -> String {
        let mut s = format!(
            "{}, {planes} photon planes, every estimator gathering the same planes along the same rays (one \
             plane set per sampler).\nReference: {}.\nShared by the estimators of one sampler: {:.3} s (planes, \
             structure, rays).",
            self.setting(),
            self.reference,
            self.shared_seconds
        );
        if let (Some(first), Some(last)) = (self.sweep.first(), self.sweep.last()) {
            s += &format!(
                "\nError versus time: {} to {} planes, {} seed{} each (seed + 1000 onwards).",
                first.planes,
                last.planes,
                first.seeds,
                if first.seeds == 1 { "" } else { "s" }
            );
        }
        s
    }
}

/// One render of the scaling study.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ScalingPoint {
    pub planes: usize,
    pub width: u32,
    pub height: u32,
    pub hits: u64,
    pub seconds_total: f64,
    pub seconds_gather: f64,
    pub cpu_ns_per_hit: Option<f64>,
    pub peak_memory_bytes: Option<u64>,
}

/// Renders over a grid of plane counts and resolutions, and writes scaling.json, scaling.md and
/// seconds_vs_hits.png/.svg (log-log, one line per resolution): whether time grows linearly
/// with the number of hits.
pub fn run_scaling(
    scene: &Scene,
    weighting: Weighting,
    sampler: Sampler,
    planes: &[usize],
    resolutions: &[(u32, u32)],
    out: &std::path::Path,
    quiet: bool,
) -> Result<String> {
    let mut points = Vec::new();
    for &(w, h) in resolutions {
        let s = scene.with_resolution(w, h)?;
        for &n in planes {
            let opts = RenderOptions { planes: n, weighting, sampler, ..RenderOptions::default() };
            let cpu = cpu_seconds();
            let (_, st) = render(&s, &opts, Control::none())?;
            let cpu = cpu.zip(cpu_seconds()).map(|(a, b)| b - a);
            if !quiet {
                eprintln!("{w}x{h}, {n} planes: {}", st.summary());
            }
            points.push(ScalingPoint {
                planes: n,
                width: w,
                height: h,
                hits: st.hits,
                seconds_total: st.seconds_total,
                seconds_gather: st.seconds_gather,
                cpu_ns_per_hit: cpu.map(|c| 1e9 * c / st.hits.max(1) as f64),
                peak_memory_bytes: peak_memory_bytes(),
            });
        }
    }
    let mut md = format!(
        "{} with {}, {sampler} planes, jittered rays, seed 1, {} threads\n\n| resolution | planes | hits | total s | gather s | ns/hit wall | ns/hit CPU |\n|---|---:|---:|---:|---:|---:|---:|\n",
        scene.name,
        weighting,
        rayon::current_num_threads()
    );
    for p in &points {
        md += &format!(
            "| {}x{} | {} | {} | {:.3} | {:.3} | {:.2} | {} |\n",
            p.width,
            p.height,
            p.planes,
            p.hits,
            p.seconds_total,
            p.seconds_gather,
            1e9 * p.seconds_total / p.hits.max(1) as f64,
            p.cpu_ns_per_hit.map_or("-".into(), |v| format!("{v:.2}"))
        );
    }
    write_file_atomically(&out.join("scaling.md"), md.as_bytes())?;
    let json = serde_json::to_string_pretty(&points).context("cannot format JSON")?;
    write_file_atomically(&out.join("scaling.json"), json.as_bytes())?;
    plot_scaling(&scene.name, &points, out)?;
    Ok(md)
}
