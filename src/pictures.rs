//! The pictures the experiments draw: the image panel with false-colour errors, the
//! error-versus-time plot and the scaling plot (PNG and SVG, each written whole).

use crate::report::{ScalingPoint, SweepPoint, Table};
use anyhow::{Context, Result};
use fogplanes::film::{Film, save_rgb8_png, write_file_atomically};
use plotters::coord::ranged1d::Ranged;
use plotters::prelude::*;

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
    Ok(save_rgb8_png(&img, path)?)
}

fn plot_error<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow::anyhow!("drawing failed: {e:?}")
}

/// MSE against time, log-log, one line per estimator, as PNG and SVG. Returns the SVG text, or
/// `None` (and no files) when no sweep point can be shown on log axes
/// ([`SweepPoint::plottable`]; the table's notes say which were left out).
pub fn plot_error_vs_time(table: &Table, out: &std::path::Path) -> Result<Option<String>> {
    let points: Vec<&SweepPoint> = table.sweep.iter().filter(|p| p.plottable()).collect();
    if points.is_empty() {
        return Ok(None);
    }
    save_plot(
        out,
        "error_vs_time",
        |a| draw_error_vs_time(table, &points, a),
        |a| draw_error_vs_time(table, &points, a),
    )
    .map(Some)
}

/// A plot as `<stem>.png` and `<stem>.svg` in `out`, each written whole; returns the SVG text.
/// The same drawing function is passed twice, once per backend.
fn save_plot(
    out: &std::path::Path,
    stem: &str,
    png: impl FnOnce(DrawingArea<BitMapBackend, plotters::coord::Shift>) -> Result<()>,
    svg: impl FnOnce(DrawingArea<SVGBackend, plotters::coord::Shift>) -> Result<()>,
) -> Result<String> {
    register_fonts();
    let (w, h) = (900u32, 600u32);
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    png(BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area())?;
    let img = image::RgbImage::from_raw(w, h, buffer).context("plot buffer size")?;
    save_rgb8_png(&img, &out.join(format!("{stem}.png")))?;
    let mut text = String::new();
    svg(SVGBackend::with_string(&mut text, (w, h)).into_drawing_area())?;
    write_file_atomically(&out.join(format!("{stem}.svg")), text.as_bytes())?;
    Ok(text)
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

fn draw_error_vs_time<DB: DrawingBackend>(
    table: &Table,
    points: &[&SweepPoint],
    root: DrawingArea<DB, plotters::coord::Shift>,
) -> Result<()> {
    root.fill(&WHITE).map_err(plot_error)?;
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

/// Seconds against hits, log-log, one line per resolution, as PNG and SVG (renders timed at
/// zero seconds, which a log axis cannot show, left out; no files when none is left).
pub fn plot_scaling(name: &str, points: &[ScalingPoint], out: &std::path::Path) -> Result<()> {
    let points: Vec<&ScalingPoint> =
        points.iter().filter(|p| p.seconds_total.is_finite() && p.seconds_total > 0.0).collect();
    if !points.is_empty() {
        save_plot(out, "seconds_vs_hits", |a| draw_scaling(name, &points, a), |a| draw_scaling(name, &points, a))?;
    }
    Ok(())
}

fn draw_scaling<DB: DrawingBackend>(
    name: &str,
    points: &[&ScalingPoint],
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
    if let Some(big) = points.iter().copied().max_by_key(|p| p.hits) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::tests::table;
    use std::time::Duration;

    /// Runs the error-versus-time plot of sweep points (MSE, seconds) into a fresh directory on
    /// another thread, and fails if it has not returned after a generous time (log axes asked
    /// to span 0, NaN or infinity used to spin forever).
    fn plot(name: &str, sweep: &[(f64, f64)]) -> (Option<String>, std::path::PathBuf) {
        let dir = std::env::temp_dir().join(format!("fogplanes-plot-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (t, out) = (table(sweep), dir.clone());
        let (send, receive) = std::sync::mpsc::channel();
        std::thread::spawn(move || send.send(plot_error_vs_time(&t, &out).map_err(|e| e.to_string())));
        let result = receive.recv_timeout(Duration::from_secs(60)).expect("the plot did not return within 60 s");
        (result.unwrap(), dir)
    }

    #[test]
    fn a_sweep_that_a_log_axis_cannot_show_makes_no_plot() {
        for (name, sweep) in [
            ("zero", vec![(0.0, 0.5), (0.0, 0.6)]),
            ("nan", vec![(f64::NAN, 0.5), (f64::NAN, 0.6)]),
            ("mixed", vec![(0.0, 0.5), (f64::INFINITY, 0.6), (1e-3, 0.0), (f64::NAN, f64::NAN)]),
        ] {
            let (svg, dir) = plot(name, &sweep);
            assert!(svg.is_none(), "{name}");
            assert!(!dir.join("error_vs_time.png").exists() && !dir.join("error_vs_time.svg").exists(), "{name}");
            std::fs::remove_dir_all(dir).unwrap();
        }
    }

    #[test]
    fn the_plot_leaves_out_only_the_points_it_cannot_show() {
        let (svg, dir) = plot("some", &[(1e-3, 0.5), (0.0, 0.6), (5e-4, 1.0), (f64::NAN, 1.2)]);
        let svg = svg.expect("two points can be shown");
        // The smis-exact points (MSE 0 and NaN) are left out, and with them their line.
        assert!(svg.contains("<svg") && svg.contains("unweighted") && !svg.contains("smis-exact"), "{svg}");
        assert!(dir.join("error_vs_time.png").exists());
        std::fs::remove_dir_all(dir).unwrap();
    }
}
