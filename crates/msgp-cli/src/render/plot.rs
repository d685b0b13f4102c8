//! PNG plots of free simulations, like the paper's Figure 3: the measured output, the predicted
//! mean and the ±2σ band, one panel per output and trajectory (`msgp fit`/`eval --plot`), or a
//! grid of single-output panels ([`plot_grid`]: the reproductions' `--plots`).
//!
//! Drawn with plotters' bitmap backend, in the style of every msgp plot (`msgp_sim::plot`: the
//! embedded DejaVu Sans, the legend).

use std::path::{Path, PathBuf};

use anyhow::{Context, anyhow};
use msgp_sim::plot::{font, legend};
use plotters::prelude::*;

use msgp_core::data::Trajectory;
use msgp_core::data::dataset::Part;
use msgp_core::model::{Metrics, Simulated, Simulation, score_output};

/// Panels beyond this many are left out (the first trajectories are drawn).
const MAX_PANELS: usize = 6;
const WIDTH: u32 = 1200;
const PANEL_HEIGHT: u32 = 340;

/// One panel: a trajectory's output `j`, its data drawn under the legend `data`.
struct Panel<'a> {
    title: String,
    sim: &'a Simulated,
    j: usize,
    data: &'a str,
}

/// Writes the plot of `sims` (output names `outputs`) to `path`; `title` heads every panel.
pub fn plot(
    path: &Path,
    title: &str,
    outputs: &[String],
    sims: &[Simulated],
) -> anyhow::Result<()> {
    font()?;
    let mut panels = Vec::new();
    for s in sims {
        for (j, name) in outputs.iter().enumerate() {
            let mut t = format!("{title}: {name}");
            if sims.len() > 1 {
                t.push_str(&format!(" — {}", s.part.label()));
            }
            panels.push(Panel {
                title: t,
                sim: s,
                j,
                data: "measured",
            });
        }
    }
    panels.truncate(MAX_PANELS);
    if panels.is_empty() {
        return Err(anyhow!("nothing to plot"));
    }
    let height = PANEL_HEIGHT * panels.len() as u32;
    draw(path, (WIDTH, height), (panels.len(), 1), &panels)
        .with_context(|| format!("cannot write the plot {}", path.display()))
}

/// `sim`, a simulation of `traj` scored by `metrics`, as a panel's content: the part named
/// `name`, its times the row numbers.
pub fn simulated(name: &str, traj: &Trajectory, sim: Simulation, metrics: Metrics) -> Simulated {
    Simulated {
        part: Part {
            source: PathBuf::from(name),
            episode: None,
            times: (0..traj.len()).map(|t| t as f64).collect(),
            traj: traj.clone(),
        },
        sim,
        metrics,
    }
}

/// Width of one column of [`plot_grid`].
const COLUMN_WIDTH: u32 = 800;

/// Writes a grid of single-output simulations to `path`: `rows[r][c]` is the panel of row `r`,
/// column `c`, a title and the simulation of its first output (every row as long as the
/// first; at most [`MAX_PANELS`] rows), its data under the legend `data` ("measured", "true
/// output").
pub fn plot_grid(
    path: &Path,
    rows: &[Vec<(String, &Simulated)>],
    data: &str,
) -> anyhow::Result<()> {
    font()?;
    let rows = &rows[..rows.len().min(MAX_PANELS)];
    let columns = rows.first().map_or(0, Vec::len);
    if columns == 0 || rows.iter().any(|r| r.len() != columns) {
        return Err(anyhow!("nothing to plot, or rows of different lengths"));
    }
    let panels: Vec<Panel<'_>> = rows
        .iter()
        .flatten()
        .map(|(title, sim)| Panel {
            title: title.clone(),
            sim,
            j: 0,
            data,
        })
        .collect();
    // (one column as wide as `plot`'s panels)
    let width = if columns == 1 {
        WIDTH
    } else {
        COLUMN_WIDTH * columns as u32
    };
    let size = (width, PANEL_HEIGHT * rows.len() as u32);
    draw(path, size, (rows.len(), columns), &panels)
        .with_context(|| format!("cannot write the plot {}", path.display()))
}

/// Draws `panels` row by row on a `grid` of (rows, columns) in an image of `size`.
fn draw(
    path: &Path,
    size: (u32, u32),
    grid: (usize, usize),
    panels: &[Panel<'_>],
) -> anyhow::Result<()> {
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let areas = root.split_evenly(grid);
    for (area, panel) in areas.iter().zip(panels) {
        draw_panel(area, panel)?;
    }
    root.present().map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

fn draw_panel(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    panel: &Panel<'_>,
) -> anyhow::Result<()> {
    let s = panel.sim;
    let j = panel.j;
    let start = s.sim.start;
    let n = s.sim.mean.nrows();
    let t: Vec<f64> = s.part.times[start..start + n].to_vec();
    let mean: Vec<f64> = (0..n).map(|i| s.sim.mean[(i, j)]).collect();
    let sd: Vec<f64> = (0..n).map(|i| s.sim.var[(i, j)].max(0.0).sqrt()).collect();
    let measured: Vec<f64> = (0..n).map(|i| s.part.traj.y[(start + i, j)]).collect();
    let lo: Vec<f64> = mean.iter().zip(&sd).map(|(m, d)| m - 2.0 * d).collect();
    let hi: Vec<f64> = mean.iter().zip(&sd).map(|(m, d)| m + 2.0 * d).collect();
    let (x0, x1) = bounds(&t);
    let (y0, y1) = bounds(
        lo.iter()
            .chain(&hi)
            .chain(&measured)
            .copied()
            .collect::<Vec<_>>()
            .as_slice(),
    );
    let pad = 0.05 * (y1 - y0).max(1e-12);
    let scores = score_output(&s.sim, &s.part.traj, j)?;
    let caption = format!(
        "{} (RMSE {:.4}, 2σ coverage {:.2})",
        panel.title, scores.rmse, scores.coverage_2sigma
    );
    let e = |e: DrawingAreaErrorKind<_>| anyhow!("{e}");
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("t")
        .x_label_formatter(&|x| tick(*x))
        .y_label_formatter(&|y| tick(*y))
        .label_style(("sans-serif", 13))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(e)?;
    let band = RGBColor(220, 60, 60);
    let mut poly: Vec<(f64, f64)> = t.iter().copied().zip(hi.iter().copied()).collect();
    poly.extend(t.iter().copied().zip(lo.iter().copied()).rev());
    chart
        .draw_series(std::iter::once(Polygon::new(poly, band.mix(0.2).filled())))
        .map_err(e)?
        .label("mean ± 2σ")
        .legend(move |(x, y)| {
            Rectangle::new([(x, y - 5), (x + 18, y + 5)], band.mix(0.2).filled())
        });
    chart
        .draw_series(LineSeries::new(
            t.iter().copied().zip(measured.iter().copied()),
            BLACK.stroke_width(1),
        ))
        .map_err(e)?
        .label(panel.data)
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK));
    chart
        .draw_series(LineSeries::new(
            t.iter().copied().zip(mean.iter().copied()),
            band.stroke_width(2),
        ))
        .map_err(e)?
        .label("predicted mean")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], band.stroke_width(2)));
    legend(&mut chart).map_err(anyhow::Error::msg)?;
    Ok(())
}

/// (min, max) of finite values, widened when degenerate.
fn bounds(v: &[f64]) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &x in v.iter().filter(|x| x.is_finite()) {
        lo = lo.min(x);
        hi = hi.max(x);
    }
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-12 {
        return (lo - 0.5, hi + 0.5);
    }
    (lo, hi)
}

/// A tick label: up to 6 significant decimals, trailing zeros dropped, no `-0`.
fn tick(x: f64) -> String {
    let s = format!("{x:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".to_string()
    } else {
        s.to_string()
    }
}
