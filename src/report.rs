//! The estimator comparison: table, image panel and error-versus-time plot (SPEC section 4).
//!
//! Every estimator gathers the same planes along the same camera rays (pixel centres by
//! default), so the planes are the only source of difference between them, and each is timed on
//! its own. Speed against error is reported as efficiency 1 / (MSE x seconds), with both the
//! gathering time and the whole time (plane sampling, structure build, rays and gathering).

use crate::film::{Film, save_rgb8_png, write_file_atomically};
use crate::metrics::{ErrorMetrics, compare};
use crate::raster::GatherStats;
use crate::render::{Accelerator, PreparedPlanes, camera_rays};
use crate::scene::Scene;
use crate::weights::{Estimator, Weighting};
use anyhow::{Context, Result};
use glam::Vec3;
use plotters::coord::ranged1d::Ranged;
use plotters::prelude::*;
use std::path::PathBuf;
use std::time::Instant;

pub struct TableOptions {
    pub planes: usize,
    pub seed: u64,
    pub pixel_center: bool,
    /// Plane counts of the error-versus-time sweep (empty: no sweep).
    pub sweep: Vec<usize>,
    pub sweep_seeds: u32,
    /// Weightings measured besides the five estimators with their defaults.
    pub extra: Vec<Weighting>,
    pub out: PathBuf,
    pub exposure: f32,
    pub quiet: bool,
    pub reference_path: PathBuf,
}

/// One estimator's row.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Row {
    pub estimator: String,
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
    /// Ratios to `unweighted`: MSE, gather time, efficiency (gather), efficiency (total).
    pub mse_vs_unweighted: f64,
    pub gather_time_vs_unweighted: f64,
    pub efficiency_gather_vs_unweighted: f64,
    pub efficiency_total_vs_unweighted: f64,
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
    /// Shared by all estimators: plane sampling, structure build, camera rays.
    pub shared_seconds: f64,
    pub rows: Vec<Row>,
    pub sweep: Vec<SweepPoint>,
}

/// The weightings of the table: the five estimators, then the extra ones.
pub fn table_weightings(extra: &[Weighting]) -> Vec<Weighting> {
    let mut all: Vec<Weighting> = Estimator::ALL.iter().map(|&e| Weighting::new(e, None).expect("defaults")).collect();
    for w in extra {
        if !all.contains(w) {
            all.push(*w);
        }
    }
    all
}

/// One measurement: every weighting over one plane set. Returns (weighting, image, hits,
/// gather seconds) and the shared seconds.
fn measure(
    scene: &Scene,
    weightings: &[Weighting],
    planes: usize,
    seed: u64,
    pixel_center: bool,
) -> (Vec<(Weighting, Film, GatherStats, f64)>, f64) {
    let start = Instant::now();
    let prepared = PreparedPlanes::new(scene, planes, seed, Accelerator::Raster);
    let pass = camera_rays(scene, seed, 0, pixel_center);
    let shared = start.elapsed().as_secs_f64();
    let out = weightings
        .iter()
        .map(|&w| {
            let t = Instant::now();
            let mut sums = vec![Vec3::ZERO; pass.rays.len()];
            let stats = prepared.gather(w, &pass.rays, &mut sums, &|| {});
            let seconds = t.elapsed().as_secs_f64();
            let mut film = Film::new(scene.camera.width, scene.camera.height);
            for ((f, s), e) in film.pixels.iter_mut().zip(&sums).zip(&pass.emission) {
                *f = *s + *e;
            }
            (w, film, stats, seconds)
        })
        .collect();
    (out, shared)
}

/// Renders, measures and writes table.md, table.json, panel.png, error_vs_time.png/.svg.
pub fn run_table(scene: &Scene, reference: &Film, opts: &TableOptions) -> Result<String> {
    let weightings = table_weightings(&opts.extra);
    let log = |s: String| {
        if !opts.quiet {
            eprintln!("{s}");
        }
    };
    log(format!("table: {} estimators, {} planes", weightings.len(), opts.planes));
    let (results, shared) = measure(scene, &weightings, opts.planes, opts.seed, opts.pixel_center);
    let mut rows = Vec::new();
    for (w, film, stats, gather) in &results {
        let m = compare(film, reference)?;
        let total = shared + gather;
        rows.push(Row {
            estimator: w.label(),
            planes: opts.planes,
            hits: stats.hits,
            tests_per_hit: stats.tests as f64 / stats.hits.max(1) as f64,
            gather_ns_per_hit: 1e9 * gather / stats.hits.max(1) as f64,
            gather_seconds: *gather,
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
        });
    }
    let base = rows[0].clone();
    for r in &mut rows {
        r.mse_vs_unweighted = r.metrics.mse / base.metrics.mse;
        r.gather_time_vs_unweighted = r.gather_seconds / base.gather_seconds;
        r.efficiency_gather_vs_unweighted = r.efficiency_gather / base.efficiency_gather;
        r.efficiency_total_vs_unweighted = r.efficiency_total / base.efficiency_total;
    }

    let mut sweep = Vec::new();
    for &n in &opts.sweep {
        let mut acc: Vec<(f64, f64, f64, f64)> = vec![(0.0, 0.0, 0.0, 0.0); weightings.len()];
        for s in 0..opts.sweep_seeds {
            let seed = opts.seed.wrapping_add(1000).wrapping_add(s as u64);
            let (results, shared) = measure(scene, &weightings, n, seed, opts.pixel_center);
            for (a, (_, film, _, gather)) in acc.iter_mut().zip(&results) {
                let m = compare(film, reference)?;
                *a = (a.0 + m.mse, a.1 + m.smape, a.2 + gather, a.3 + shared + gather);
            }
        }
        let k = opts.sweep_seeds.max(1) as f64;
        for (w, a) in weightings.iter().zip(&acc) {
            sweep.push(SweepPoint {
                estimator: w.label(),
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

    let table = Table {
        scene: scene.name.clone(),
        reference: opts.reference_path.display().to_string(),
        resolution: [scene.camera.width, scene.camera.height],
        pixel_center: opts.pixel_center,
        seed: opts.seed,
        shared_seconds: shared,
        rows,
        sweep,
    };
    let markdown = table.markdown();
    write_file_atomically(&opts.out.join("table.md"), markdown.as_bytes())?;
    let json = serde_json::to_string_pretty(&table).context("cannot format the table as JSON")?;
    write_file_atomically(&opts.out.join("table.json"), json.as_bytes())?;
    let images: Vec<(String, &Film)> = results.iter().map(|(w, f, _, _)| (w.label(), f)).collect();
    save_panel(&images, reference, opts.exposure, &opts.out.join("panel.png"))?;
    if !table.sweep.is_empty() {
        plot_error_vs_time(&table, &opts.out)?;
    }
    Ok(markdown)
}

impl Table {
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "{} at {}x{}, {} rays, seed {}, against `{}`; {:.3} s shared (planes, structure, rays).\n\n",
            self.scene,
            self.resolution[0],
            self.resolution[1],
            if self.pixel_center { "pixel-centre" } else { "jittered" },
            self.seed,
            self.reference,
            self.shared_seconds
        );
        s += "| estimator | planes | hits | ns/hit | gather s | total s | SMAPE x10^2 | MSE x10^4 | 1/(MSE s) gather | 1/(MSE s) total | MSE vs unweighted | gather time vs unweighted | efficiency vs unweighted (gather / total) |\n";
        s += "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
        for r in &self.rows {
            s += &format!(
                "| {} | {} | {:.3e} | {:.2} | {:.3} | {:.3} | {:.4} | {:.4} | {:.4e} | {:.4e} | {:.3} | {:.3} | {:.2} / {:.2} |\n",
                r.estimator,
                r.planes,
                r.hits as f64,
                r.gather_ns_per_hit,
                r.gather_seconds,
                r.total_seconds,
                r.smape_e2,
                r.mse_e4,
                r.efficiency_gather,
                r.efficiency_total,
                r.mse_vs_unweighted,
                r.gather_time_vs_unweighted,
                r.efficiency_gather_vs_unweighted,
                r.efficiency_total_vs_unweighted
            );
        }
        s
    }
}

/// A perceptual colour map (viridis, by its five anchor colours) of `t` in [0, 1].
pub fn viridis(t: f32) -> [u8; 3] {
    const ANCHORS: [[f32; 3]; 5] =
        [[68.0, 1.0, 84.0], [59.0, 82.0, 139.0], [33.0, 145.0, 140.0], [94.0, 201.0, 98.0], [253.0, 231.0, 37.0]];
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 } * 4.0;
    let i = (t.floor() as usize).min(3);
    let f = t - i as f32;
    let (a, b) = (ANCHORS[i], ANCHORS[i + 1]);
    [0, 1, 2].map(|c| (a[c] + (b[c] - a[c]) * f).round() as u8)
}

/// Decades of the error colour scale: per-pixel SMAPE from 10^-LO to 1.
const ERROR_DECADES: f32 = 3.0;

/// Per-pixel SMAPE (mean over channels of |e - r| / (|e| + |r|)) on a log colour scale.
fn error_image(image: &Film, reference: &Film) -> image::RgbImage {
    image::RgbImage::from_fn(image.width, image.height, |x, y| {
        let (e, r) = (image.get(x, y), reference.get(x, y));
        let mut smape = 0.0;
        for c in 0..3 {
            let d = e[c].abs() + r[c].abs();
            if d > 0.0 {
                smape += (e[c] - r[c]).abs() / d / 3.0;
            }
        }
        let t = if smape > 0.0 { (smape.log10() + ERROR_DECADES) / ERROR_DECADES } else { 0.0 };
        image::Rgb(viridis(t))
    })
}

fn register_fonts() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    });
}

/// The panel: each estimator and the reference side by side, with its false-colour per-pixel
/// error under it, and a colour bar.
pub fn save_panel(images: &[(String, &Film)], reference: &Film, exposure: f32, path: &std::path::Path) -> Result<()> {
    register_fonts();
    // Keep the panel readable: columns at most 480 pixels wide.
    let scale = (480.0 / reference.width as f32).min(1.0);
    let (cw, ch) =
        (((reference.width as f32 * scale) as u32).max(1), ((reference.height as f32 * scale) as u32).max(1));
    let resize = |img: image::RgbImage| {
        if scale < 1.0 { image::imageops::resize(&img, cw, ch, image::imageops::FilterType::Triangle) } else { img }
    };
    let columns = images.len() + 1;
    let (title, gap, bar) = (24u32, 6u32, 60u32);
    let (width, height) = (columns as u32 * (cw + gap) + gap, title + 2 * (ch + gap) + gap + bar);
    let mut buffer = vec![255u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
        let font = ("sans-serif", 15).into_font().color(&BLACK);
        let column = |k: usize, label: &str, top: image::RgbImage, bottom: Option<image::RgbImage>| -> Result<()> {
            let x = gap + k as u32 * (cw + gap);
            root.draw(&Text::new(label.to_string(), (x as i32 + 2, 4), font.clone())).map_err(plot_error)?;
            let blit = |img: image::RgbImage, y: u32| -> Result<()> {
                let element = BitMapElement::<_>::with_owned_buffer((x as i32, y as i32), (cw, ch), img.into_raw())
                    .context("image buffer size")?;
                root.draw(&element).map_err(plot_error)
            };
            blit(top, title)?;
            if let Some(b) = bottom {
                blit(b, title + ch + gap)?;
            }
            Ok(())
        };
        for (k, (label, film)) in images.iter().enumerate() {
            column(k, label, resize(film.to_rgb8(exposure)), Some(resize(error_image(film, reference))))?;
        }
        column(images.len(), "reference", resize(reference.to_rgb8(exposure)), None)?;
        // Colour bar under the reference column's empty slot and along the bottom.
        let (bx, by, bw) = (gap as i32, (title + 2 * (ch + gap) + 8) as i32, (width - 2 * gap) as i32);
        for i in 0..bw {
            let c = viridis(i as f32 / (bw - 1) as f32);
            root.draw(&Rectangle::new([(bx + i, by), (bx + i + 1, by + 14)], RGBColor(c[0], c[1], c[2]).filled()))
                .map_err(plot_error)?;
        }
        let decades = ERROR_DECADES as i32;
        for d in 0..=decades {
            let x = bx + (d as f32 / decades as f32 * (bw - 1) as f32) as i32;
            let label = if d == decades { "1".to_string() } else { format!("1e-{}", decades - d) };
            root.draw(&Text::new(label, (x.min(bx + bw - 30), by + 17), font.clone())).map_err(plot_error)?;
        }
        let note = "bottom row: per-pixel SMAPE against the reference, mean over RGB (log scale)";
        root.draw(&Text::new(note, (bx + bw / 3, by + 34), font.clone())).map_err(plot_error)?;
        root.present().map_err(plot_error)?;
    }
    let img = image::RgbImage::from_raw(width, height, buffer).context("panel buffer size")?;
    save_rgb8_png(&img, path)
}

fn plot_error<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow::anyhow!("drawing failed: {e:?}")
}

/// MSE against time, log-log, one line per estimator, as PNG and SVG.
pub fn plot_error_vs_time(table: &Table, out: &std::path::Path) -> Result<()> {
    save_plot(out, "error_vs_time", |a| draw_error_vs_time(table, a), |a| draw_error_vs_time(table, a))
}

/// A plot as `<stem>.png` and `<stem>.svg` in `out`, each written whole. The same drawing
/// function is passed twice, once per backend.
fn save_plot(
    out: &std::path::Path,
    stem: &str,
    png: impl FnOnce(DrawingArea<BitMapBackend, plotters::coord::Shift>) -> Result<()>,
    svg: impl FnOnce(DrawingArea<SVGBackend, plotters::coord::Shift>) -> Result<()>,
) -> Result<()> {
    register_fonts();
    let (w, h) = (900u32, 600u32);
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    png(BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area())?;
    let img = image::RgbImage::from_raw(w, h, buffer).context("plot buffer size")?;
    save_rgb8_png(&img, &out.join(format!("{stem}.png")))?;
    let mut text = String::new();
    svg(SVGBackend::with_string(&mut text, (w, h)).into_drawing_area())?;
    write_file_atomically(&out.join(format!("{stem}.svg")), text.as_bytes())
}

/// Draws the legend at `position` and presents the plot.
fn finish_plot<'a, DB: DrawingBackend + 'a, X, Y>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    root: &DrawingArea<DB, plotters::coord::Shift>,
    position: SeriesLabelPosition,
) -> Result<()>
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(plot_error)?;
    root.present().map_err(plot_error)?;
    Ok(())
}

/// One series as a line with a dot at each point, labelled in the legend.
fn draw_series<DB: DrawingBackend, X, Y>(
    chart: &mut ChartContext<DB, Cartesian2d<X, Y>>,
    series: Vec<(f64, f64)>,
    colour: RGBAColor,
    label: String,
) -> Result<()>
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    chart
        .draw_series(LineSeries::new(series.clone(), colour.stroke_width(2)))
        .map_err(plot_error)?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
    chart.draw_series(series.iter().map(|&(x, y)| Circle::new((x, y), 3, colour.filled()))).map_err(plot_error)?;
    Ok(())
}

fn draw_error_vs_time<DB: DrawingBackend>(table: &Table, root: DrawingArea<DB, plotters::coord::Shift>) -> Result<()> {
    root.fill(&WHITE).map_err(plot_error)?;
    let points = &table.sweep;
    let (mut t0, mut t1, mut m0, mut m1) = (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64);
    for p in points {
        t0 = t0.min(p.total_seconds);
        t1 = t1.max(p.total_seconds);
        m0 = m0.min(p.mse);
        m1 = m1.max(p.mse);
    }
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "{}: MSE against time ({}x{}, mean over seeds)",
                table.scene, table.resolution[0], table.resolution[1]
            ),
            ("sans-serif", 20),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d((t0 / 1.2..t1 * 1.2).log_scale(), (m0 / 1.5..m1 * 1.5).log_scale())
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("seconds (planes + structure + rays + gathering)")
        .y_desc("MSE")
        .x_label_formatter(&|v| format!("{v:.3}").trim_end_matches('0').trim_end_matches('.').to_string())
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .draw()
        .map_err(plot_error)?;
    let mut labels: Vec<&str> = points.iter().map(|p| p.estimator.as_str()).collect();
    labels.dedup();
    let mut seen = Vec::new();
    for l in labels {
        if seen.contains(&l) {
            continue;
        }
        seen.push(l);
        let colour = Palette99::pick(seen.len() - 1).to_rgba();
        let series: Vec<(f64, f64)> =
            points.iter().filter(|p| p.estimator == l).map(|p| (p.total_seconds, p.mse)).collect();
        draw_series(&mut chart, series, colour, l.to_string())?;
    }
    finish_plot(&mut chart, &root, SeriesLabelPosition::UpperRight)
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
    planes: &[usize],
    resolutions: &[(u32, u32)],
    out: &std::path::Path,
    quiet: bool,
) -> Result<String> {
    use crate::render::{RenderOptions, render};
    let mut points = Vec::new();
    for &(w, h) in resolutions {
        let s = scene.with_resolution(w, h).map_err(anyhow::Error::msg)?;
        for &n in planes {
            let opts = RenderOptions {
                planes: n,
                weighting,
                seed: 1,
                spp: 1,
                pixel_center: false,
                accelerator: Accelerator::Raster,
            };
            let (_, st) = render(&s, &opts, &|| {});
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
                cpu_ns_per_hit: st.cpu_ns_per_hit(),
                peak_memory_bytes: st.peak_memory_bytes,
            });
        }
    }
    let mut md = format!(
        "{} with {}, jittered rays, seed 1, {} threads\n\n| resolution | planes | hits | total s | gather s | ns/hit wall | ns/hit CPU |\n|---|---:|---:|---:|---:|---:|---:|\n",
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
    let name = &scene.name;
    save_plot(out, "seconds_vs_hits", |a| draw_scaling(name, &points, a), |a| draw_scaling(name, &points, a))?;
    Ok(md)
}

fn draw_scaling<DB: DrawingBackend>(
    name: &str,
    points: &[ScalingPoint],
    root: DrawingArea<DB, plotters::coord::Shift>,
) -> Result<()> {
    root.fill(&WHITE).map_err(plot_error)?;
    let hits = |p: &ScalingPoint| p.hits.max(1) as f64;
    let (h0, h1) = points.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| (a.min(hits(p)), b.max(hits(p))));
    let (s0, s1) =
        points.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| (a.min(p.seconds_total), b.max(p.seconds_total)));
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("{name}: render time against ray-plane hits"), ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d((h0 / 1.5..h1 * 1.5).log_scale(), (s0 / 1.5..s1 * 1.5).log_scale())
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("hits")
        .y_desc("seconds (whole render)")
        .x_label_formatter(&|v| format!("{v:.0e}"))
        .y_label_formatter(&|v| format!("{v:.3}").trim_end_matches('0').trim_end_matches('.').to_string())
        .draw()
        .map_err(plot_error)?;
    // Slope 1 through the largest render: where a linear cost would put every point.
    if let Some(big) = points.iter().max_by_key(|p| p.hits) {
        let per_hit = big.seconds_total / hits(big);
        chart
            .draw_series(LineSeries::new([(h0, h0 * per_hit), (h1, h1 * per_hit)], BLACK.mix(0.5).stroke_width(1)))
            .map_err(plot_error)?
            .label("time proportional to hits")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.5)));
    }
    let mut resolutions: Vec<(u32, u32)> = points.iter().map(|p| (p.width, p.height)).collect();
    resolutions.dedup();
    for (k, &(w, h)) in resolutions.iter().enumerate() {
        let colour = Palette99::pick(k).to_rgba();
        let series: Vec<(f64, f64)> =
            points.iter().filter(|p| (p.width, p.height) == (w, h)).map(|p| (hits(p), p.seconds_total)).collect();
        draw_series(&mut chart, series, colour, format!("{w}x{h}"))?;
    }
    finish_plot(&mut chart, &root, SeriesLabelPosition::UpperLeft)
}
