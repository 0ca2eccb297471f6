//! The metric tables of the reports (`demo`'s `metrics.md`, `eval`'s `results.md` and
//! `results.json`): one row per method, the chosen columns, lengths in mm; `eval`'s tables per
//! run, its ratios of the shipped defaults to the interpolations, and its JSON.

use super::methods::default_method;
use super::metrics::{SequenceMetrics, WrinkleStats};
use crate::io::json::{Object, Value};

/// A column of a metrics table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Column {
    Rmse,
    BoundaryRmse,
    Hausdorff,
    BorderLengthRatio,
    AreaRatio,
    NormalAngle,
    CurvatureErr,
    Flicker,
    StedSpatial,
    StedTemporal,
    /// The four [`WrinkleStats`](super::metrics::WrinkleStats) numbers ("–" where not computed).
    WrinkleRms,
    WrinkleRatio,
    WrinkleCorr,
    WrinkleChange,
}

impl Column {
    /// Every column (the `eval` table).
    pub const ALL: [Column; 14] = [
        Column::Rmse,
        Column::BoundaryRmse,
        Column::Hausdorff,
        Column::BorderLengthRatio,
        Column::AreaRatio,
        Column::NormalAngle,
        Column::CurvatureErr,
        Column::Flicker,
        Column::StedSpatial,
        Column::StedTemporal,
        Column::WrinkleRms,
        Column::WrinkleRatio,
        Column::WrinkleCorr,
        Column::WrinkleChange,
    ];

    pub fn header(self) -> &'static str {
        match self {
            Column::Rmse => "vertex RMSE (mm)",
            Column::BoundaryRmse => "boundary RMSE (mm)",
            Column::Hausdorff => "Hausdorff (mm)",
            Column::BorderLengthRatio => "border length ratio",
            Column::AreaRatio => "area ratio",
            Column::NormalAngle => "normal angle (°)",
            Column::CurvatureErr => "mean-curvature err (1/m)",
            Column::Flicker => "flicker (mm/frame)",
            Column::StedSpatial => "STED spatial (%)",
            Column::StedTemporal => "STED temporal (%)",
            Column::WrinkleRms => "wrinkle RMS (mm)",
            Column::WrinkleRatio => "wrinkle / truth",
            Column::WrinkleCorr => "wrinkle corr",
            Column::WrinkleChange => "wrinkle change / truth",
        }
    }

    /// The cell of `m`: its mean over frames (flicker: over steps; wrinkle: over the whole
    /// sequence), lengths in mm.
    pub fn cell(self, m: &SequenceMetrics) -> String {
        let f = &m.mean;
        let wrinkle = |pick: fn(&WrinkleStats) -> f32| {
            m.wrinkle.as_ref().map_or("–".into(), |w| format!("{:.3}", pick(w)))
        };
        match self {
            Column::Rmse => format!("{:.3}", 1e3 * f.rmse),
            Column::BoundaryRmse => format!("{:.3}", 1e3 * f.boundary_rmse),
            Column::Hausdorff => format!("{:.3}", 1e3 * f.hausdorff),
            Column::BorderLengthRatio => format!("{:.4}", f.boundary_length_ratio),
            Column::AreaRatio => format!("{:.4}", f.area_ratio),
            Column::NormalAngle => format!("{:.2}", f.normal_angle_deg),
            Column::CurvatureErr => format!("{:.3}", f.curvature_err),
            Column::Flicker => format!("{:.3}", 1e3 * m.flicker),
            Column::StedSpatial => format!("{:.3}", 100.0 * m.sted_spatial),
            Column::StedTemporal => format!("{:.3}", 100.0 * m.sted_temporal),
            Column::WrinkleRms => wrinkle(|w| w.rms_mm),
            Column::WrinkleRatio => wrinkle(|w| w.ratio),
            Column::WrinkleCorr => wrinkle(|w| w.corr),
            Column::WrinkleChange => wrinkle(|w| w.change_ratio),
        }
    }
}

/// A markdown table: a `method` column, then `columns`, one row per (method, metrics).
pub fn metrics_table<'a>(
    rows: impl IntoIterator<Item = (&'a str, &'a SequenceMetrics)>,
    columns: &[Column],
) -> String {
    let mut s = String::from("| method |");
    for c in columns {
        s.push_str(&format!(" {} |", c.header()));
    }
    s.push_str("\n|---|");
    s.push_str(&"---:|".repeat(columns.len()));
    s.push('\n');
    for (method, m) in rows {
        s.push_str(&format!("| {method} |"));
        for c in columns {
            s.push_str(&format!(" {} |", c.cell(m)));
        }
        s.push('\n');
    }
    s
}

/// One method's metrics on one run (`eval`).
pub struct Cell {
    pub method: String,
    /// The run's label.
    pub scenario: String,
    pub metrics: SequenceMetrics,
}

/// Rows of vertices counted as the border band of `eval`'s tables (the border and the next
/// row).
pub const BAND_ROWS: usize = 2;

/// How the wrinkle columns of `results.md` are measured (see `eval::metrics::wrinkle_detail`).
pub const WRINKLE_NOTE: &str = "Wrinkle detail D = (X − S(X))·n: X minus its Catmull-Rom round trip S(X) through the LR grid, \
along the normal of S(X), over the interior (two outer rings left out). `wrinkle RMS` = RMS(D); `/ truth` = that over the \
HR truth's RMS(D); `corr` = ΣD·D_truth / √(ΣD² ΣD_truth²); `change / truth` = RMS(D(t+1) − D(t)) over the truth's.\n";

/// `eval`'s `results.md`: a header naming the held-out `runs`, the measures, then
/// [`results_markdown`] and [`ratios_markdown`].
pub fn results_document(runs: &[String], cells: &[Cell]) -> String {
    format!(
        "# anisocb evaluation\n\nHeld-out runs: {}. Means over frames; boundary = the border band (vertices within {BAND_ROWS} rows of the grid's border).\n\n{WRINKLE_NOTE}{}",
        runs.join(", "),
        results_markdown(cells) + &ratios_markdown(cells)
    )
}

/// Markdown: one table per scenario, methods as rows (lengths in mm), under the truth's own
/// wrinkle RMS where it was computed.
pub fn results_markdown(cells: &[Cell]) -> String {
    let mut s = String::new();
    let mut scenarios: Vec<&str> = cells.iter().map(|c| c.scenario.as_str()).collect();
    scenarios.dedup();
    for sc in scenarios {
        let rows = cells.iter().filter(|c| c.scenario == sc).map(|c| (c.method.as_str(), &c.metrics));
        s.push_str(&format!("\n### {sc}\n\n"));
        let truth = cells.iter().find_map(|c| c.metrics.wrinkle.filter(|_| c.scenario == sc));
        if let Some(w) = truth {
            s.push_str(&format!("HR truth wrinkle RMS: {:.3} mm\n\n", w.truth_rms_mm));
        }
        s.push_str(&metrics_table(rows, &Column::ALL));
    }
    s
}

/// Markdown: the shipped defaults ([`default_method`]) against each interpolation, per
/// run: ratios of vertex RMSE, normal-angle error and STED temporal (< 1: anisocb is better),
/// then the RMSE ratio averaged over runs and of the summed RMSE. Empty without those rows.
pub fn ratios_markdown(cells: &[Cell]) -> String {
    let ours = default_method();
    let mut scenarios: Vec<&str> = cells.iter().map(|c| c.scenario.as_str()).collect();
    scenarios.dedup();
    let find =
        |sc: &str, m: &str| cells.iter().find(|c| c.scenario == sc && c.method == m).map(|c| &c.metrics);
    let mut s = String::new();
    for base in ["bicubic", "catmull-rom"] {
        let mut t = format!(
            "\n### {ours} vs {base} (ratios; < 1 = anisocb better)\n\n\
             | run | vertex RMSE | normal angle | STED temporal |\n|---|---:|---:|---:|\n"
        );
        let (mut ratios, mut sums, mut any) = (Vec::new(), (0.0f64, 0.0f64), false);
        for sc in &scenarios {
            let (Some(o), Some(b)) = (find(sc, &ours), find(sc, base)) else { continue };
            any = true;
            let r = o.mean.rmse / b.mean.rmse;
            ratios.push(r as f64);
            sums.0 += o.mean.rmse as f64;
            sums.1 += b.mean.rmse as f64;
            t.push_str(&format!(
                "| {sc} | {r:.3} | {:.3} | {:.3} |\n",
                o.mean.normal_angle_deg / b.mean.normal_angle_deg,
                o.sted_temporal / b.sted_temporal
            ));
        }
        if any {
            let mean = ratios.iter().sum::<f64>() / ratios.len() as f64;
            t.push_str(&format!("| mean of the ratios | {mean:.3} | | |\n"));
            t.push_str(&format!("| ratio of the summed RMSE | {:.3} | | |\n", sums.0 / sums.1));
            s.push_str(&t);
        }
    }
    s
}

/// `eval`'s `results.json`: one object per cell, `{"scenario", "method", "metrics"}` (the
/// metrics as [`SequenceMetrics::to_value`] writes them, per frame too).
pub fn cells_json(cells: &[Cell]) -> Value {
    let rows = cells
        .iter()
        .map(|c| {
            Object::new()
                .str("scenario", &c.scenario)
                .str("method", &c.method)
                .val("metrics", c.metrics.to_value())
                .into()
        })
        .collect::<Vec<Value>>();
    rows.into()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_has_one_row_per_method_in_mm() {
        let mut m = SequenceMetrics::default();
        m.mean.rmse = 0.0012345;
        m.mean.boundary_length_ratio = 1.0;
        m.flicker = 0.002;
        let t = metrics_table([("bicubic", &m)], &[Column::Rmse, Column::BorderLengthRatio, Column::Flicker]);
        assert_eq!(
            t,
            "| method | vertex RMSE (mm) | border length ratio | flicker (mm/frame) |\n|---|---:|---:|---:|\n\
             | bicubic | 1.234 | 1.0000 | 2.000 |\n"
        );
    }

    #[test]
    fn wrinkle_columns_show_a_dash_until_computed() {
        let mut m = SequenceMetrics::default();
        let cols = [Column::WrinkleRms, Column::WrinkleRatio, Column::WrinkleCorr, Column::WrinkleChange];
        assert!(metrics_table([("x", &m)], &cols).ends_with("| x | – | – | – | – |\n"));
        m.wrinkle =
            Some(WrinkleStats { rms_mm: 1.5, truth_rms_mm: 3.0, ratio: 0.5, corr: 0.25, change_ratio: 2.0 });
        let t = metrics_table([("x", &m)], &cols);
        assert!(t.starts_with(
            "| method | wrinkle RMS (mm) | wrinkle / truth | wrinkle corr | wrinkle change / truth |"
        ));
        assert!(t.ends_with("| x | 1.500 | 0.500 | 0.250 | 2.000 |\n"), "{t}");
    }
}
