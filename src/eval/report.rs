//! The markdown metric tables of the reports (`demo`'s `metrics.md`, `eval`'s `results.md`):
//! one row per method, the chosen columns, lengths in mm.

use super::metrics::{SequenceMetrics, WrinkleStats};

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
