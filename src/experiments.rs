//! The experiments the command line runs: the estimator table with its error-versus-time sweep
//! (docs/mathematics.md section 5) and the scaling study. Each gathers numbers into the result
//! types of [`crate::report`] and hands them to [`crate::pictures`] to draw.
//!
//! Every estimator gathers the same planes along the same camera rays (whole pixels, the render's
//! ray sets, by default; pixel centres on request), so the planes are the only source of difference between them, and each is timed on
//! its own. Speed against error is reported as efficiency 1 / (MSE x seconds), with both the
//! gathering time and the whole time (plane sampling, structure build, rays and gathering).

use crate::page::{PageImage, PageInput, comparison_page};
use crate::pictures::{plot_error_vs_time, plot_scaling, save_panel};
use crate::report::{
    Entry, EqualTimeRow, Measured, Row, SCALING_COLUMNS, ScalingPoint, SweepPoint, Table, markdown_heading,
    pixel_filter,
};
use crate::system::{cpu_seconds, peak_memory_bytes};
use anyhow::{Context, Result};
use fogplanes::control::Control;
use fogplanes::emission::direct_emission;
use fogplanes::film::{Film, write_file_atomically};
use fogplanes::gather::GatherStats;
use fogplanes::metrics::compare;
use fogplanes::options::RenderOptions;
use fogplanes::render::{ChunkRenderer, render, render_for};
use fogplanes::sampling::Sampler;
use fogplanes::scene::Scene;
use fogplanes::settings::{ResolvedScaling, ResolvedTable};
use fogplanes::weights::Estimator;
use std::path::PathBuf;
use std::time::Instant;

/// What `table` needs besides its settings: the settings as [`settings::resolve_table`]
/// resolved and checked them (the scene among them), where to write, and how loudly.
pub struct TableOptions<'a> {
    pub settings: &'a ResolvedTable,
    pub out: PathBuf,
    pub quiet: bool,
    pub reference_path: PathBuf,
}

/// Renders every entry for `budget` seconds (the table's pixel filter and seed) and
/// measures each against the reference.
fn equal_time(
    scene: &Scene,
    reference: &Film,
    opts: &TableOptions,
    budget: f64,
    log: &dyn Fn(String),
) -> Result<Vec<EqualTimeRow>> {
    let mut rows = Vec::new();
    for &sampler in &opts.settings.samplers {
        for &weighting in &opts.settings.weightings {
            let entry = Entry { weighting, sampler };
            let options = opts.settings.render_options(weighting, sampler, opts.settings.planes, opts.settings.seed);
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

/// One measurement: every weighting over the plane set of each sampler, the same planes along
/// the same rays as `render` (the same bits as its image), prepared once per sampler.
fn measure(settings: &ResolvedTable, planes: usize, seed: u64) -> Result<Vec<Measured>> {
    let scene = &settings.scene;
    let mut out = Vec::new();
    for &sampler in &settings.samplers {
        let t = Instant::now();
        let opts = settings.render_options(settings.weightings[0], sampler, planes, seed);
        let mut prepared = ChunkRenderer::prepared(scene, &opts, Control::none())?;
        let emission = direct_emission(scene, seed, opts.spp(), opts.pixel_center());
        let shared_seconds = t.elapsed().as_secs_f64();
        for &weighting in &settings.weightings {
            let before = prepared.stats().clone();
            let t = Instant::now();
            let partial = prepared.render_with(weighting, 0..planes)?;
            let film = Film::finish(scene.camera.width, scene.camera.height, &partial.sums, planes, &emission)?;
            let gather_seconds = t.elapsed().as_secs_f64();
            let after = prepared.stats();
            let stats = GatherStats {
                tests: after.tests - before.tests,
                hits: after.hits - before.hits,
                device_ns: ((after.seconds_device - before.seconds_device) * 1e9) as u64,
                device_gather_ns: ((after.seconds_device_gather - before.seconds_device_gather) * 1e9) as u64,
                upload_ns: ((after.seconds_upload - before.seconds_upload) * 1e9) as u64,
                wait_ns: ((after.seconds_waited - before.seconds_waited) * 1e9) as u64,
                bytes_crossed: after.bytes_crossed - before.bytes_crossed,
                submissions: after.submissions - before.submissions,
                dispatches: after.dispatches - before.dispatches,
            };
            out.push(Measured { entry: Entry { weighting, sampler }, film, stats, gather_seconds, shared_seconds });
        }
    }
    Ok(out)
}

/// Renders, measures and writes table.md, table.json, panel.png, error_vs_time.png/.svg and
/// index.html (the comparison page, [`crate::page`]).
pub fn run_table(reference: &Film, opts: &TableOptions) -> Result<String> {
    let scene = &opts.settings.scene;
    let weightings = &opts.settings.weightings;
    let log = |s: String| {
        if !opts.quiet {
            eprintln!("{s}");
        }
    };
    log(format!(
        "table: {} estimators x {} samplers, {} planes",
        weightings.len(),
        opts.settings.samplers.len(),
        opts.settings.planes
    ));
    let results = measure(opts.settings, opts.settings.planes, opts.settings.seed)?;
    let mut rows = Vec::new();
    for r in &results {
        let (m, stats, gather) = (compare(&r.film, reference)?, r.stats, r.gather_seconds);
        let total = r.shared_seconds + gather;
        rows.push(Row {
            estimator: r.entry.label(),
            weighting: r.entry.weighting.label(),
            sampler: r.entry.sampler.to_string(),
            planes: opts.settings.planes,
            hits: stats.hits,
            // NaN (JSON's null, the table's "-") where there is no hit to divide by.
            tests_per_hit: if stats.hits > 0 { stats.tests as f64 / stats.hits as f64 } else { f64::NAN },
            gather_ns_per_hit: if stats.hits > 0 { 1e9 * gather / stats.hits as f64 } else { f64::NAN },
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
        .or_else(|| find(Estimator::BASELINE.name(), opts.settings.samplers[0]))
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
    for &n in &opts.settings.sweep {
        let mut acc: Vec<(f64, f64, f64, f64)> = vec![(0.0, 0.0, 0.0, 0.0); results.len()];
        for s in 0..opts.settings.sweep_seeds {
            let seed = opts.settings.seed.wrapping_add(1000).wrapping_add(s as u64);
            for (a, r) in acc.iter_mut().zip(measure(opts.settings, n, seed)?) {
                let m = compare(&r.film, reference)?;
                let g = r.gather_seconds;
                *a = (a.0 + m.mse, a.1 + m.smape, a.2 + g, a.3 + r.shared_seconds + g);
            }
        }
        let k = opts.settings.sweep_seeds as f64;
        for (r, a) in results.iter().zip(&acc) {
            sweep.push(SweepPoint {
                estimator: r.entry.label(),
                planes: n,
                seeds: opts.settings.sweep_seeds,
                mse: a.0 / k,
                smape: a.1 / k,
                gather_seconds: a.2 / k,
                total_seconds: a.3 / k,
            });
        }
        log(format!("sweep: {n} planes done"));
    }

    let equal_time = match opts.settings.equal_time {
        Some(budget) => equal_time(scene, reference, opts, budget, &log)?,
        None => Vec::new(),
    };

    let table = Table {
        scene: scene.name.clone(),
        reference: opts.reference_path.display().to_string(),
        resolution: [scene.camera.width, scene.camera.height],
        pixel_center: opts.settings.pixel_center,
        filter: pixel_filter(opts.settings.pixel_center, opts.settings.spp),
        seed: opts.settings.seed,
        lobes: (scene.medium.g != 0.0).then_some(opts.settings.lobes),
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
        .filter(|r| r.entry.sampler == opts.settings.samplers[0])
        .map(|r| (r.entry.weighting.label(), &r.film))
        .collect();
    save_panel(&images, reference, opts.settings.exposure, &opts.out.join("panel.png"))?;
    let svg = plot_error_vs_time(&table, &opts.out)?;

    // The comparison page: the reference and every entry's image, the table, the plot.
    let pixels = |film: &Film| film.pixels.iter().map(|p| p.to_array()).collect::<Vec<[f32; 3]>>();
    let (width, height) = (reference.width, reference.height);
    let reference_pixels = pixels(reference);
    // The images of the first sampler's planes, as in the panel (a page of every sampler's
    // would be twice the size for pictures that look alike); the table has every row.
    let shown: Vec<&Measured> = results.iter().filter(|r| r.entry.sampler == opts.settings.samplers[0]).collect();
    let labels: Vec<String> = shown.iter().map(|r| r.entry.label()).collect();
    let estimator_pixels: Vec<Vec<[f32; 3]>> = shown.iter().map(|r| pixels(&r.film)).collect();
    let (title, table_html, notes) =
        (format!("fogplanes: {} estimators", table.scene), table.html(), table.notes(opts.settings.planes));
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

/// Renders over a grid of plane counts and resolutions, and writes scaling.json, scaling.md and
/// seconds_vs_hits.png/.svg (log-log, one line per resolution): whether time grows linearly
/// with the number of hits.
pub fn run_scaling(scene: &Scene, study: &ResolvedScaling, out: &std::path::Path, quiet: bool) -> Result<String> {
    let base = study.render_options(study.planes[0]);
    let mut points = Vec::new();
    for &(w, h) in &study.resolutions {
        let s = scene.with_resolution(w, h)?;
        for &n in &study.planes {
            let opts = study.render_options(n);
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
    let mut md = format!("{}\n\n{}", scaling_heading(scene, &base), markdown_heading(&SCALING_COLUMNS));
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

/// The line above the scaling table: what every render of the study shared (the lobes' share
/// where the fog scatters forward or back, as the table's heading names it: it changes the hits).
fn scaling_heading(scene: &Scene, opts: &RenderOptions) -> String {
    let lobes = if scene.medium.g != 0.0 {
        format!(", lobes {}", fogplanes::error::Number(opts.lobes()))
    } else {
        String::new()
    };
    format!(
        "{} with {}, {} planes, {}, seed {}{lobes}, {} threads",
        scene.name,
        opts.weighting(),
        opts.sampler(),
        pixel_filter(opts.pixel_center(), opts.ray_sets()),
        opts.seed(),
        rayon::current_num_threads()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The scaling table's heading says what the renders used, not what they once did.
    #[test]
    fn the_scaling_heading_comes_from_the_options() {
        let scene = Scene::load(std::path::Path::new("media_scenes/six_lights.toml")).unwrap();
        let given = fogplanes::settings::Overrides {
            seed: Some(9),
            pixel_center: true,
            sampler: Some(Sampler::Independent),
            ..Default::default()
        };
        let opts = given.resolve(&scene).unwrap().options;
        let heading = scaling_heading(&scene, &opts);
        assert!(
            heading.starts_with(&format!(
                "six_lights with {}, independent planes, pixel-centre rays, seed 9, ",
                opts.weighting()
            )),
            "{heading}"
        );
        let given = fogplanes::settings::Overrides { seed: Some(3), ..Default::default() };
        let heading = scaling_heading(&scene, &given.resolve(&scene).unwrap().options);
        assert!(heading.contains("whole pixels (box filter, 16 ray sets), seed 3, ") && !heading.contains("lobes"));
        // In forward fog the lobes' share changes the hits: the heading names it.
        let forward = Scene::load(std::path::Path::new("media_scenes/forward_fog.toml")).unwrap();
        let heading =
            scaling_heading(&forward, &fogplanes::settings::Overrides::default().resolve(&forward).unwrap().options);
        assert!(heading.contains(", seed 1, lobes 0.5, "), "{heading}");
    }
}
