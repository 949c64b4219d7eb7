//! The report's results: what the table, its sweep, the equal-time comparison and the scaling
//! study measured, as plain data, and how the table prints (Markdown and the page's HTML).
//! [`crate::experiments`] fills them in, [`crate::pictures`] draws them.

use crate::page::html_table;
use fogplanes::error::Fixed;
use fogplanes::film::Film;
use fogplanes::gather::GatherStats;
use fogplanes::metrics::ErrorMetrics;
use fogplanes::sampling::Sampler;
use fogplanes::weights::Weighting;

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

/// One point of the sweep: mean over seeds at one plane count (at least one seed).
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

impl SweepPoint {
    /// Whether the log-log error-versus-time plot can show it: an MSE and a time both positive
    /// and finite (a log axis asked to span 0, NaN or infinity never ends its ticks).
    pub fn plottable(&self) -> bool {
        let loggable = |x: f64| x.is_finite() && x > 0.0;
        loggable(self.mse) && loggable(self.total_seconds)
    }
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Table {
    pub scene: String,
    pub reference: String,
    pub resolution: [u32; 2],
    pub pixel_center: bool,
    /// The pixel filter, in words ([`pixel_filter`]); the reference must use the same.
    pub filter: String,
    pub seed: u64,
    /// The share of each light's planes swept along its lobe, in fog that scatters forward or
    /// back (none in isotropic fog, where there is no lobe).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lobes: Option<f64>,
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

/// A column of a printed table: its heading, and whether it holds text (aligned left) or
/// numbers (aligned right).
#[derive(Clone, Copy, Debug)]
pub struct Column {
    pub heading: &'static str,
    pub numbers: bool,
}

const fn text(heading: &'static str) -> Column {
    Column { heading, numbers: false }
}

const fn number(heading: &'static str) -> Column {
    Column { heading, numbers: true }
}

/// The table's columns, in the Markdown table and the page's HTML table alike.
const COLUMNS: [Column; 15] = [
    text("estimator"),
    text("sampler"),
    number("planes"),
    number("hits"),
    number("ns/hit"),
    number("gather s"),
    number("total s"),
    number("SMAPE x10^2"),
    number("MSE x10^4"),
    number("1/(MSE s) gather"),
    number("1/(MSE s) total"),
    number("MSE vs unweighted"),
    number("gather time vs unweighted"),
    number("efficiency vs unweighted (gather / total)"),
    number("MSE vs independent"),
];

/// The columns of the equal-time table.
const EQUAL_TIME_COLUMNS: [Column; 8] = [
    text("estimator"),
    text("sampler"),
    number("seconds"),
    number("planes"),
    number("plane passes"),
    number("SMAPE x10^2"),
    number("MSE x10^4"),
    number("MSE vs unweighted"),
];

/// The columns of the scaling study's table.
pub const SCALING_COLUMNS: [Column; 7] = [
    text("resolution"),
    number("planes"),
    number("hits"),
    number("total s"),
    number("gather s"),
    number("ns/hit wall, all included"),
    number("ns/hit CPU, all included"),
];

/// A Markdown table's heading and alignment rows, both made from its columns.
pub fn markdown_heading(columns: &[Column]) -> String {
    let headings: Vec<&str> = columns.iter().map(|c| c.heading).collect();
    let alignments: Vec<&str> = columns.iter().map(|c| if c.numbers { "---:" } else { "---" }).collect();
    format!("| {} |\n|{}|\n", headings.join(" | "), alignments.join("|"))
}

/// One Markdown row: the label, then the cells.
fn markdown_row(label: &str, cells: &[String]) -> String {
    format!("| {label} | {} |\n", cells.join(" | "))
}

fn html_columns(columns: &[Column]) -> Vec<&'static str> {
    columns.iter().map(|c| c.heading).collect()
}

/// The pixel filter of a render, in the words of the reports: whole pixels (the box filter)
/// sampled by `ray_sets` ray sets, or pixel centres.
pub fn pixel_filter(pixel_center: bool, ray_sets: u32) -> String {
    if pixel_center {
        "pixel-centre rays".to_string()
    } else {
        format!("whole pixels (box filter, {ray_sets} ray set{})", if ray_sets == 1 { "" } else { "s" })
    }
}

impl EqualTimeRow {
    fn cells(&self) -> Vec<String> {
        vec![
            self.sampler.clone(),
            format!("{:.2}", self.seconds),
            self.planes.to_string(),
            self.plane_passes.to_string(),
            format!("{:.4}", Fixed(self.metrics.smape_e2())),
            format!("{:.4}", Fixed(self.metrics.mse_e4())),
            figure(self.mse_vs_unweighted, |v| format!("{v:.3}")),
        ]
    }
}

/// A figure of a table's cell, or `-` where it is no number: an efficiency of an MSE of 0 (a
/// black scene, or a reference that is the render itself), a ratio of two of them, a time per
/// hit without hits. JSON holds them as null.
fn figure(v: f64, cell: impl Fn(f64) -> String) -> String {
    if v.is_finite() { cell(v) } else { "-".to_string() }
}

impl Row {
    /// The cells after the row's label, as both tables print them.
    fn cells(&self) -> Vec<String> {
        vec![
            self.sampler.clone(),
            self.planes.to_string(),
            format!("{:.3e}", self.hits as f64),
            figure(self.gather_ns_per_hit, |v| format!("{v:.2}")),
            format!("{:.3}", self.gather_seconds),
            format!("{:.3}", self.total_seconds),
            format!("{:.4}", Fixed(self.smape_e2)),
            format!("{:.4}", Fixed(self.mse_e4)),
            figure(self.efficiency_gather, |v| format!("{v:.4e}")),
            figure(self.efficiency_total, |v| format!("{v:.4e}")),
            figure(self.mse_vs_unweighted, |v| format!("{v:.3}")),
            figure(self.gather_time_vs_unweighted, |v| format!("{v:.3}")),
            format!(
                "{} / {}",
                figure(self.efficiency_gather_vs_unweighted, |v| format!("{v:.2}")),
                figure(self.efficiency_total_vs_unweighted, |v| format!("{v:.2}"))
            ),
            self.mse_vs_independent.map_or("-".to_string(), |v| figure(v, |v| format!("{v:.3}"))),
        ]
    }
}

impl Table {
    /// What was rendered: scene, resolution, rays and seed.
    fn setting(&self) -> String {
        let [w, h] = self.resolution;
        let lobes = self.lobes.map_or(String::new(), |s| format!(", lobes {}", fogplanes::error::Number(s)));
        format!("{} at {w}x{h}, {}, seed {}{lobes}", self.scene, self.filter, self.seed)
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
        let mut s = format!("{}\n\n{}", self.summary(), markdown_heading(&COLUMNS));
        for r in &self.rows {
            s += &markdown_row(&r.weighting, &r.cells());
        }
        if let Some(first) = self.equal_time.first() {
            s += &format!(
                "\nAt equal time: {:.2} s of wall time for each (a render on a time budget, planes in passes).\n\n{}",
                first.budget_seconds,
                markdown_heading(&EQUAL_TIME_COLUMNS)
            );
            for r in &self.equal_time {
                s += &markdown_row(&r.weighting, &r.cells());
            }
        }
        if let Some(note) = self.unplotted_note() {
            s += &format!("\n{note}\n");
        }
        s
    }

    /// The same table as HTML, for the comparison page (rows named by the page's labels, so
    /// that clicking a row shows its image).
    pub fn html(&self) -> String {
        let rows: Vec<(&str, Vec<String>)> = self.rows.iter().map(|r| (r.estimator.as_str(), r.cells())).collect();
        let mut html = html_table(&html_columns(&COLUMNS), &rows);
        if !self.equal_time.is_empty() {
            let rows: Vec<(&str, Vec<String>)> =
                self.equal_time.iter().map(|r| (r.estimator.as_str(), r.cells())).collect();
            html += &html_table(&html_columns(&EQUAL_TIME_COLUMNS), &rows);
        }
        html
    }

    /// The page's notes: what was measured, against what.
    pub fn notes(&self, planes: usize) -> String {
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
        if let Some(note) = self.unplotted_note() {
            s += &format!("\n{note}");
        }
        s
    }

    /// What the error-versus-time plot leaves out: the sweep points its log axes cannot show.
    fn unplotted_note(&self) -> Option<String> {
        let left_out: Vec<&SweepPoint> = self.sweep.iter().filter(|p| !p.plottable()).collect();
        if left_out.is_empty() {
            return None;
        }
        let what = if left_out.len() == self.sweep.len() { "so there is no plot" } else { "left out of the plot" };
        Some(format!(
            "Error versus time: {} of {} sweep points have an MSE or a time of zero or not finite, which a log \
             axis cannot show ({what}); table.json lists them.",
            left_out.len(),
            self.sweep.len()
        ))
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A table of one row and one equal-time row, with the given sweep points' (MSE, seconds).
    pub(crate) fn table(sweep: &[(f64, f64)]) -> Table {
        let metrics = ErrorMetrics { smape: 0.1, mse: 2e-4, ..ErrorMetrics::default() };
        Table {
            scene: "fog".into(),
            reference: "ref.exr".into(),
            resolution: [32, 24],
            pixel_center: false,
            filter: pixel_filter(false, 16),
            seed: 7,
            lobes: None,
            shared_seconds: 0.5,
            rows: vec![Row {
                estimator: "smis-exact".into(),
                weighting: "smis-exact".into(),
                sampler: "sobol".into(),
                planes: 1024,
                hits: 5000,
                tests_per_hit: 2.0,
                gather_ns_per_hit: 3.0,
                gather_seconds: 0.1,
                total_seconds: 0.2,
                metrics,
                smape_e2: metrics.smape_e2(),
                mse_e4: metrics.mse_e4(),
                efficiency_gather: 5e4,
                efficiency_total: 2.5e4,
                mse_vs_unweighted: 0.5,
                gather_time_vs_unweighted: 1.1,
                efficiency_gather_vs_unweighted: 1.8,
                efficiency_total_vs_unweighted: 1.9,
                mse_vs_independent: None,
            }],
            sweep: sweep
                .iter()
                .enumerate()
                .map(|(i, &(mse, seconds))| SweepPoint {
                    estimator: if i % 2 == 0 { "unweighted" } else { "smis-exact" }.into(),
                    planes: 1024 << (i / 2),
                    seeds: 1,
                    mse,
                    smape: 0.1,
                    gather_seconds: seconds / 2.0,
                    total_seconds: seconds,
                })
                .collect(),
            equal_time: vec![EqualTimeRow {
                estimator: "smis-exact".into(),
                weighting: "smis-exact".into(),
                sampler: "sobol".into(),
                budget_seconds: 1.0,
                seconds: 1.01,
                planes: 4096,
                plane_passes: 2,
                metrics,
                mse_vs_unweighted: 0.4,
            }],
        }
    }

    /// Every line of each Markdown table, the alignment row among them, has one cell per
    /// column; text columns align left and numbers right.
    #[test]
    fn markdown_rows_have_one_cell_per_column() {
        let markdown = table(&[]).markdown();
        let cells = |line: &str| line.trim().trim_matches('|').split('|').count();
        let tables: Vec<Vec<&str>> = markdown
            .split("\n\n")
            .map(|block| block.lines().filter(|l| l.starts_with('|')).collect::<Vec<_>>())
            .filter(|lines| !lines.is_empty())
            .collect();
        assert_eq!(tables.len(), 2, "{markdown}");
        for (lines, columns) in tables.iter().zip([&COLUMNS[..], &EQUAL_TIME_COLUMNS[..]]) {
            assert_eq!(lines.len(), 3, "{lines:?}");
            for line in lines {
                assert_eq!(cells(line), columns.len(), "{line}");
            }
            assert!(lines[1].starts_with("|---|---|---:|") && lines[1].ends_with("---:|"), "{}", lines[1]);
        }
        assert_eq!(markdown_heading(&[text("a"), number("b")]), "| a | b |\n|---|---:|\n");
    }

    /// The setting comes from the table's own seed and rays.
    #[test]
    fn the_setting_names_the_rays_and_seed_used() {
        let mut t = table(&[]);
        assert!(
            t.markdown().starts_with("fog at 32x24, whole pixels (box filter, 16 ray sets), seed 7, against `ref.exr`")
        );
        (t.pixel_center, t.filter) = (true, pixel_filter(true, 16));
        t.seed = 12;
        assert!(t.notes(1024).starts_with("fog at 32x24, pixel-centre rays, seed 12, 1024 photon planes"));
    }

    /// Points a log axis cannot show are named in the notes and in table.md, and only then.
    #[test]
    fn unplottable_sweep_points_are_reported() {
        assert!(table(&[(1e-3, 0.5), (2e-3, 0.6)]).unplotted_note().is_none());
        let t = table(&[(1e-3, 0.5), (0.0, 0.6), (f64::NAN, 0.7), (1e-3, 0.0)]);
        let note = t.unplotted_note().unwrap();
        assert!(note.contains("3 of 4 sweep points") && note.contains("left out of the plot"), "{note}");
        assert!(t.markdown().contains(&note) && t.notes(1024).contains(&note));
        let none = table(&[(0.0, 0.5), (f64::INFINITY, 0.6)]).unplotted_note().unwrap();
        assert!(none.contains("2 of 2") && none.contains("no plot"), "{none}");
    }
}
