//! Histograms of the figures (SVG via plotters) and their data (JSON), written atomically.

use std::path::Path;

use plotters::prelude::*;

use super::eval::{Reconstruction, Sampled, Series};
use crate::error::{Error, Result};
use crate::io::{write_atomic, write_json_atomic};

const BINS: usize = 30;

fn draw_error(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::Write {
        path: path.to_path_buf(),
        error: std::io::Error::other(e.to_string()),
    }
}

/// One SVG with a histogram panel per series, side by side, on a shared error axis.
pub fn histograms(path: &Path, title: &str, series: &[&Series]) -> Result<()> {
    let max = series
        .iter()
        .flat_map(|s| s.errors_mm.iter().copied())
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
        .max(1e-6);
    let width = max / BINS as f64;
    let counts: Vec<Vec<u32>> = series
        .iter()
        .map(|s| {
            let mut c = vec![0u32; BINS];
            for v in s.errors_mm.iter().filter(|v| v.is_finite()) {
                c[((v / width) as usize).min(BINS - 1)] += 1;
            }
            c
        })
        .collect();
    let top = counts.iter().flatten().copied().max().unwrap_or(1).max(1);
    let mut svg = String::new();
    {
        let root =
            SVGBackend::with_string(&mut svg, (420 * series.len() as u32, 360)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_error(path, e))?;
        let root = root
            .titled(title, ("sans-serif", 18))
            .map_err(|e| draw_error(path, e))?;
        let panels = root.split_evenly((1, series.len()));
        for ((panel, s), c) in panels.iter().zip(series).zip(&counts) {
            let caption = format!(
                "{}: mean {:.3}, max {:.3} mm",
                s.name, s.stats.mean, s.stats.max
            );
            let mut chart = ChartBuilder::on(panel)
                .caption(caption, ("sans-serif", 14))
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(45)
                .build_cartesian_2d(0.0..max, 0u32..top + top / 10 + 1)
                .map_err(|e| draw_error(path, e))?;
            chart
                .configure_mesh()
                .x_desc("error (mm)")
                .y_desc("poses")
                .draw()
                .map_err(|e| draw_error(path, e))?;
            chart
                .draw_series(c.iter().enumerate().map(|(i, &n)| {
                    let x0 = i as f64 * width;
                    Rectangle::new([(x0, 0), (x0 + width, n)], BLUE.mix(0.6).filled())
                }))
                .map_err(|e| draw_error(path, e))?;
        }
        root.present().map_err(|e| draw_error(path, e))?;
    }
    write_atomic(path, svg.as_bytes())
}

/// fig12-reconstruction.svg (PCA-3, NLPCA-5, the rig), fig13-sampled.svg (with and without
/// the d1-dependent ranges) and figures.json (every series, with per-pose errors).
pub fn write_figures(dir: &Path, rec: &Reconstruction, sampled: Option<&Sampled>) -> Result<()> {
    let pick = |v: &[Series], name: &str| v.iter().find(|s| s.name == name).cloned();
    let mut panels: Vec<Series> = Vec::new();
    panels.extend(pick(&rec.pca, "PCA-3"));
    panels.extend(pick(&rec.nlpca, "NLPCA-5"));
    panels.push(rec.rig.clone());
    histograms(
        &dir.join("fig12-reconstruction.svg"),
        "Reconstruction error of the captured poses (largest vertex distance)",
        &panels.iter().collect::<Vec<_>>(),
    )?;
    if let Some(s) = sampled {
        histograms(
            &dir.join("fig13-sampled.svg"),
            "Random rig poses: distance to the nearest captured pose",
            &[&s.dynamic_ranges, &s.static_ranges],
        )?;
    }
    #[derive(serde::Serialize)]
    struct Figures<'a> {
        reconstruction: &'a Reconstruction,
        sampled: Option<&'a Sampled>,
    }
    write_json_atomic(
        &dir.join("figures.json"),
        &Figures {
            reconstruction: rec,
            sampled,
        },
    )
}
