//! The paper's Fig. 7/8: the error over frames per subject (SVG via plotters), ours against
//! the baseline, written atomically.

use std::path::Path;

use plotters::prelude::*;

use super::eval::Evaluation;
use crate::error::{Error, Result};
use crate::io::write_atomic;

fn draw_error(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::Write {
        path: path.to_path_buf(),
        error: std::io::Error::other(e.to_string()),
    }
}

/// One panel per subject: the multi-subject mapping retargeted, the single-subject mapping on
/// its test frames and the baseline, error (mm) over frames.
pub fn error_over_frames(path: &Path, e: &Evaluation) -> Result<()> {
    let rows = e.subjects.len().max(1);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 260 * rows as u32)).into_drawing_area();
        root.fill(&WHITE).map_err(|x| draw_error(path, x))?;
        let panels = root.split_evenly((rows, 1));
        for (panel, s) in panels.iter().zip(&e.subjects) {
            let se = &s.series;
            let top = se
                .baseline
                .iter()
                .chain(&se.multi_subject)
                .chain(&se.single)
                .copied()
                .filter(|v| v.is_finite())
                .fold(0.0, f64::max)
                .max(0.1);
            let first = se.frames.first().copied().unwrap_or(0);
            let last = se.frames.last().copied().unwrap_or(1).max(first + 1);
            let caption = format!(
                "{}: multi-subject {:.2} mm, single {:.2} mm, baseline {:.2} mm",
                s.name, s.multi_subject_mm, s.single_mm, s.baseline_mm
            );
            let mut chart = ChartBuilder::on(panel)
                .caption(caption, ("sans-serif", 14))
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(45)
                .build_cartesian_2d(first..last, 0.0..top * 1.05)
                .map_err(|x| draw_error(path, x))?;
            chart
                .configure_mesh()
                .x_desc("frame")
                .y_desc("error (mm)")
                .draw()
                .map_err(|x| draw_error(path, x))?;
            let line = |v: &[f64]| -> Vec<(u32, f64)> {
                se.frames
                    .iter()
                    .zip(v)
                    .filter(|(_, e)| e.is_finite())
                    .map(|(&f, &e)| (f, e))
                    .collect()
            };
            for (values, colour, label) in [
                (&se.baseline, GREEN, "baseline (Procrustes)"),
                (&se.single, BLUE, "single subject"),
                (&se.multi_subject, RED, "multi-subject, retargeted"),
            ] {
                chart
                    .draw_series(LineSeries::new(line(values), colour))
                    .map_err(|x| draw_error(path, x))?
                    .label(label)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|x| draw_error(path, x))?;
        }
        root.present().map_err(|x| draw_error(path, x))?;
    }
    write_atomic(path, svg.as_bytes())
}
