//! PNG of policy-search cost curves, like the paper's Figure 4: per iteration, the expected cost
//! predicted by the model (± 2σ bars) and the cost measured on the system; iterations whose
//! policy passed the stability test are drawn as filled markers.

use std::path::Path;

use anyhow::{Context, anyhow};
use msgp_sim::learn::IterationReport;
use plotters::prelude::*;

use crate::render::plot::{font, legend};

const WIDTH: u32 = 1000;
const HEIGHT: u32 = 560;

/// One learning run: `(iteration, predicted, predicted_std, actual, stable)` per iteration.
#[derive(Clone, Debug)]
pub struct CostCurve {
    /// Legend label.
    pub label: String,
    /// Points in iteration order.
    pub points: Vec<(usize, f64, f64, f64, bool)>,
}

const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
];

/// Writes the plot of `curves` to `path`.
pub fn plot_costs(path: &Path, title: &str, curves: &[CostCurve]) -> anyhow::Result<()> {
    font()?;
    draw(path, title, curves).with_context(|| format!("cannot write the plot {}", path.display()))
}

fn draw(path: &Path, title: &str, curves: &[CostCurve]) -> anyhow::Result<()> {
    let e = |e: DrawingAreaErrorKind<_>| anyhow!("{e}");
    let last = curves
        .iter()
        .flat_map(|c| c.points.iter().map(|p| p.0))
        .max()
        .ok_or_else(|| anyhow!("nothing to plot"))?;
    let ymax = curves
        .iter()
        .flat_map(|c| {
            c.points
                .iter()
                .flat_map(|p| [p.1 + 2.0 * p.2, p.3].into_iter())
        })
        .filter(|v| v.is_finite())
        .fold(1.0_f64, f64::max);
    let root = BitMapBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.5_f64..(last as f64 + 0.5), 0.0..(1.05 * ymax))
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("iteration")
        .y_desc("cost over the episode")
        .x_labels(last.min(20))
        .x_label_formatter(&|x| format!("{x:.0}"))
        .label_style(("sans-serif", 14))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(e)?;
    let several = curves.len() > 1;
    for (k, c) in curves.iter().enumerate() {
        let colour = PALETTE[k % PALETTE.len()];
        // a small horizontal offset per curve keeps the error bars apart
        let dx = if several {
            (k as f64 - (curves.len() as f64 - 1.0) / 2.0) * 0.04
        } else {
            0.0
        };
        let predicted: Vec<(f64, f64)> = c.points.iter().map(|p| (p.0 as f64 + dx, p.1)).collect();
        let actual: Vec<(f64, f64)> = c.points.iter().map(|p| (p.0 as f64 + dx, p.3)).collect();
        chart
            .draw_series(c.points.iter().map(|p| {
                let x = p.0 as f64 + dx;
                PathElement::new(
                    vec![(x, (p.1 - 2.0 * p.2).max(0.0)), (x, p.1 + 2.0 * p.2)],
                    colour.mix(0.6).stroke_width(1),
                )
            }))
            .map_err(e)?;
        let predicted_label = if several {
            format!("{} predicted ± 2σ", c.label)
        } else {
            "predicted (model) ± 2σ".to_string()
        };
        chart
            .draw_series(LineSeries::new(
                predicted,
                ShapeStyle::from(&colour.mix(0.6)).stroke_width(1),
            ))
            .map_err(e)?
            .label(predicted_label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], colour.mix(0.6).stroke_width(1))
            });
        let actual_label = if several {
            format!("{} actual", c.label)
        } else {
            "actual (system)".to_string()
        };
        chart
            .draw_series(LineSeries::new(actual, colour.stroke_width(2)))
            .map_err(e)?
            .label(actual_label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
            });
        chart
            .draw_series(c.points.iter().map(|p| {
                let style = if p.4 {
                    colour.filled()
                } else {
                    colour.stroke_width(2)
                };
                Circle::new((p.0 as f64 + dx, p.3), 5, style)
            }))
            .map_err(e)?;
    }
    legend(&mut chart)?;
    root.draw(&Text::new(
        "filled marker: the policy passed the stability test",
        (70, HEIGHT as i32 - 18),
        ("sans-serif", 13),
    ))
    .map_err(e)?;
    root.present().map_err(e)?;
    Ok(())
}

/// Which cost of an iteration a panel shows.
type Pick = fn(&IterationReport) -> f64;

/// Mean and standard deviation across runs of `f` at each iteration (runs may differ in length).
fn band(
    runs: &[Vec<IterationReport>],
    f: impl Fn(&IterationReport) -> f64,
) -> Vec<(f64, f64, f64)> {
    let last = runs.iter().map(Vec::len).max().unwrap_or(0);
    (0..last)
        .filter_map(|i| {
            let v: Vec<f64> = runs.iter().filter_map(|r| r.get(i)).map(&f).collect();
            if v.is_empty() {
                return None;
            }
            let n = v.len() as f64;
            let mean = v.iter().sum::<f64>() / n;
            let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
            Some(((i + 1) as f64, mean, var.sqrt()))
        })
        .collect()
}

/// Figure 4 of the paper: per model, the mean ± 1 standard deviation over seeds of the predicted
/// (left panel) and the actual (right panel) cost per iteration.
pub fn plot_cost_bands(
    path: &Path,
    models: &[(String, Vec<Vec<IterationReport>>)],
) -> anyhow::Result<()> {
    font()?;
    draw_bands(path, models).with_context(|| format!("cannot write the plot {}", path.display()))
}

fn draw_bands(path: &Path, models: &[(String, Vec<Vec<IterationReport>>)]) -> anyhow::Result<()> {
    let e = |e: DrawingAreaErrorKind<_>| anyhow!("{e}");
    let root = BitMapBackend::new(path, (WIDTH + 200, HEIGHT)).into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    let panels = root.split_evenly((1, 2));
    let pick: [(&str, Pick); 2] = [
        ("predicted cost (model)", |r| r.predicted_cost),
        ("actual cost (system)", |r| r.actual_cost),
    ];
    let bands: Vec<[Vec<(f64, f64, f64)>; 2]> = models
        .iter()
        .map(|(_, runs)| [band(runs, pick[0].1), band(runs, pick[1].1)])
        .collect();
    let last = bands
        .iter()
        .flat_map(|b| b[0].iter().map(|p| p.0))
        .fold(1.0_f64, f64::max);
    let ymax = bands
        .iter()
        .flat_map(|b| b.iter().flat_map(|s| s.iter().map(|p| p.1 + p.2)))
        .filter(|v| v.is_finite())
        .fold(1.0_f64, f64::max);
    for (k, area) in panels.iter().enumerate() {
        let mut chart = ChartBuilder::on(area)
            .caption(pick[k].0, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(0.8_f64..(last + 0.2), 0.0..(1.05 * ymax))
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("iteration")
            .y_desc("cost per episode")
            .x_labels(last as usize)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .label_style(("sans-serif", 13))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(e)?;
        for (j, ((label, runs), b)) in models.iter().zip(&bands).enumerate() {
            let colour = PALETTE[j % PALETTE.len()];
            let s = &b[k];
            let mut poly: Vec<(f64, f64)> = s.iter().map(|p| (p.0, p.1 + p.2)).collect();
            poly.extend(s.iter().rev().map(|p| (p.0, (p.1 - p.2).max(0.0))));
            chart
                .draw_series(std::iter::once(Polygon::new(
                    poly,
                    colour.mix(0.18).filled(),
                )))
                .map_err(e)?;
            chart
                .draw_series(LineSeries::new(
                    s.iter().map(|p| (p.0, p.1)),
                    colour.stroke_width(2),
                ))
                .map_err(e)?
                .label(format!("{label} ({} runs)", runs.len()))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                });
        }
        legend(&mut chart)?;
    }
    root.present().map_err(e)?;
    Ok(())
}
