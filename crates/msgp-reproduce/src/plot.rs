//! PNG plots of the reproductions over seeds: Figure 4's cost bands (per model, the mean ± 1
//! standard deviation over seeds of the predicted and the measured cost per iteration,
//! [`plot_cost_bands`]), a task's score bands ([`plot_score_bands`]) and panels of signals over
//! time ([`plot_signals`]), in the style of every msgp plot (`msgp_sim::plot`'s font, legend and
//! palette).

use std::path::Path;

use msgp_sim::plot::{CostPoint, HEIGHT, PALETTE, WIDTH, font, legend};
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::error::{ReproduceError, Result};

/// Which cost of an iteration a panel shows.
type Pick = fn(&CostPoint) -> f64;

/// A plot's error, named by the file it was drawn into.
fn failed(path: &Path, message: impl std::fmt::Display) -> ReproduceError {
    ReproduceError::Plot {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// Mean and standard deviation across runs of `f` at each iteration (runs may differ in length).
fn band(runs: &[Vec<CostPoint>], f: impl Fn(&CostPoint) -> f64) -> Vec<(f64, f64, f64)> {
    let values: Vec<Vec<f64>> = runs.iter().map(|r| r.iter().map(&f).collect()).collect();
    band_of(&values)
}

/// Mean and standard deviation across runs at each iteration (runs may differ in length).
fn band_of(runs: &[Vec<f64>]) -> Vec<(f64, f64, f64)> {
    let last = runs.iter().map(Vec::len).max().unwrap_or(0);
    (0..last)
        .filter_map(|i| {
            let v: Vec<f64> = runs.iter().filter_map(|r| r.get(i)).copied().collect();
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

/// A captioned panel of `area` with iterations 1 to `last` along x and `y` up, its mesh drawn
/// in the style of the band plots.
fn iteration_chart<'a, DB: DrawingBackend + 'a>(
    area: &DrawingArea<DB, Shift>,
    caption: &str,
    last: f64,
    y: std::ops::Range<f64>,
    y_desc: &str,
) -> Result<ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>, String> {
    let e = |e: DrawingAreaErrorKind<_>| e.to_string();
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(64)
        .build_cartesian_2d(0.8_f64..(last + 0.2), y)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("iteration")
        .y_desc(y_desc)
        .x_labels(last as usize)
        .x_label_formatter(&|x| format!("{x:.0}"))
        .label_style(("sans-serif", 13))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(e)?;
    Ok(chart)
}

/// One model's band on `chart`: the mean ± 1 standard deviation per iteration (`band`, from
/// [`band_of`]) shaded, its lower edge cut at `floor` when given, the mean as a line labelled
/// `label`.
fn draw_band<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    colour: RGBColor,
    band: &[(f64, f64, f64)],
    label: &str,
    floor: Option<f64>,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<_>| e.to_string();
    let low = |v: f64| floor.map_or(v, |f| v.max(f));
    let mut poly: Vec<(f64, f64)> = band.iter().map(|p| (p.0, p.1 + p.2)).collect();
    poly.extend(band.iter().rev().map(|p| (p.0, low(p.1 - p.2))));
    chart
        .draw_series(std::iter::once(Polygon::new(
            poly,
            colour.mix(0.18).filled(),
        )))
        .map_err(e)?;
    chart
        .draw_series(LineSeries::new(
            band.iter().map(|p| (p.0, p.1)),
            colour.stroke_width(2),
        ))
        .map_err(e)?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2)));
    Ok(())
}

/// Figure 4 of the paper: per model, the mean ± 1 standard deviation over seeds of the predicted
/// (left panel) and the actual (right panel) cost per iteration.
pub fn plot_cost_bands(path: &Path, models: &[(String, Vec<Vec<CostPoint>>)]) -> Result<()> {
    font()?;
    draw_bands(path, models).map_err(|m| failed(path, m))
}

fn draw_bands(path: &Path, models: &[(String, Vec<Vec<CostPoint>>)]) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<_>| e.to_string();
    let root = BitMapBackend::new(path, (WIDTH + 200, HEIGHT)).into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    let panels = root.split_evenly((1, 2));
    let pick: [(&str, Pick); 2] = [
        ("predicted cost (model)", |r| r.predicted),
        ("actual cost (system)", |r| r.actual),
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
        let mut chart = iteration_chart(
            area,
            pick[k].0,
            last,
            0.0..(1.05 * ymax),
            "cost per episode",
        )?;
        for (j, ((label, runs), b)) in models.iter().zip(&bands).enumerate() {
            let name = format!("{label} ({} runs)", runs.len());
            draw_band(
                &mut chart,
                PALETTE[j % PALETTE.len()],
                &b[k],
                &name,
                Some(0.0),
            )?;
        }
        legend(&mut chart)?;
    }
    root.present().map_err(e)?;
    Ok(())
}

/// A task's score per iteration: per model, the mean ± 1 standard deviation over seeds (the
/// y axis spans the data, negative returns included), the mean as a line.
pub fn plot_score_bands(
    path: &Path,
    score: &str,
    models: &[(String, Vec<Vec<f64>>)],
) -> Result<()> {
    font()?;
    draw_score_bands(path, score, models).map_err(|m| failed(path, m))
}

fn draw_score_bands(
    path: &Path,
    score: &str,
    models: &[(String, Vec<Vec<f64>>)],
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<_>| e.to_string();
    let bands: Vec<Vec<(f64, f64, f64)>> = models.iter().map(|(_, runs)| band_of(runs)).collect();
    let points = || {
        bands
            .iter()
            .flatten()
            .filter(|p| p.1.is_finite() && p.2.is_finite())
    };
    if points().next().is_none() {
        return Err("nothing to plot".to_string());
    }
    let last = points().map(|p| p.0).fold(1.0_f64, f64::max);
    let lo = points().map(|p| p.1 - p.2).fold(f64::INFINITY, f64::min);
    let hi = points()
        .map(|p| p.1 + p.2)
        .fold(f64::NEG_INFINITY, f64::max);
    let pad = 0.05 * (hi - lo).max(1.0);
    let root = BitMapBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    let mut chart = iteration_chart(
        &root,
        score,
        last,
        (lo - pad)..(hi + pad),
        "score of the iteration's policy",
    )?;
    for (j, ((label, runs), b)) in models.iter().zip(&bands).enumerate() {
        let name = format!("{label} ({} runs)", runs.len());
        draw_band(&mut chart, PALETTE[j % PALETTE.len()], b, &name, None)?;
    }
    legend(&mut chart)?;
    root.present().map_err(e)?;
    Ok(())
}

/// One panel of [`plot_signals`]: a signal of several episodes over time.
#[derive(Clone, Debug)]
pub struct SignalPanel {
    /// The y axis' label.
    pub label: String,
    /// Per episode: legend label and `(t, value)` points.
    pub lines: Vec<(String, Vec<(f64, f64)>)>,
    /// A band drawn behind the lines (`t₀, t₁, low, high`): what success asks of the signal.
    pub band: Option<(f64, f64, f64, f64)>,
}

/// Episodes over time, one panel per signal stacked vertically (a learned swing-up: the pole's
/// angle from upright and the end effector's position).
pub fn plot_signals(path: &Path, title: &str, panels: &[SignalPanel]) -> Result<()> {
    font()?;
    draw_signals(path, title, panels).map_err(|m| failed(path, m))
}

fn draw_signals(path: &Path, title: &str, panels: &[SignalPanel]) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<_>| e.to_string();
    let points = || {
        panels
            .iter()
            .flat_map(|p| p.lines.iter().flat_map(|l| &l.1))
    };
    if points().next().is_none() {
        return Err("nothing to plot".to_string());
    }
    let t_end = points().map(|p| p.0).fold(0.0_f64, f64::max).max(1e-9);
    let root =
        BitMapBackend::new(path, (WIDTH, 300 * panels.len() as u32 + 40)).into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    let (top, rest) = root.split_vertically(40);
    top.titled(title, ("sans-serif", 20)).map_err(e)?;
    for (panel, area) in panels.iter().zip(rest.split_evenly((panels.len(), 1))) {
        let values = panel.lines.iter().flat_map(|l| l.1.iter().map(|p| p.1));
        let (lo, hi) = values
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
        let pad = 0.05 * (hi - lo).max(0.1);
        let mut chart = ChartBuilder::on(&area)
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t_end, (lo - pad)..(hi + pad))
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("time [s]")
            .y_desc(panel.label.as_str())
            .label_style(("sans-serif", 13))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(e)?;
        if let Some((t0, t1, low, high)) = panel.band {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(t0, low), (t1, high)],
                    RGBColor(44, 160, 44).mix(0.15).filled(),
                )))
                .map_err(e)?;
        }
        for (k, (label, line)) in panel.lines.iter().enumerate() {
            let colour = PALETTE[k % PALETTE.len()];
            chart
                .draw_series(LineSeries::new(
                    line.iter().copied(),
                    colour.stroke_width(2),
                ))
                .map_err(e)?
                .label(label.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                });
        }
        legend(&mut chart)?;
    }
    root.present().map_err(e)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(offset: f64) -> Vec<CostPoint> {
        (1..=4)
            .map(|iteration| CostPoint {
                iteration,
                predicted: 10.0 / iteration as f64 + offset,
                predicted_std: 0.5,
                actual: 12.0 / iteration as f64,
                stable: iteration > 2,
            })
            .collect()
    }

    #[test]
    fn band_and_signal_plots_are_pngs_and_say_what_failed() {
        let dir = std::env::temp_dir().join(format!("msgp-reproduce-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let bands = dir.join("bands.png");
        plot_cost_bands(&bands, &[("msgp".to_string(), vec![run(0.0), run(1.0)])]).expect("bands");
        let scores = dir.join("scores.png");
        let returns = vec![vec![-900.0, -400.0, -180.0], vec![-1100.0, -300.0]];
        plot_score_bands(&scores, "mean return", &[("msgp".to_string(), returns)]).expect("scores");
        let none = plot_score_bands(&dir.join("none.png"), "x", &[("m".to_string(), vec![])])
            .expect_err("no scores");
        assert!(none.to_string().contains("nothing to plot"), "{none}");
        let signals = dir.join("signals.png");
        let panel = SignalPanel {
            label: "angle".to_string(),
            lines: vec![(
                "start 0".to_string(),
                (0..50)
                    .map(|k| (0.1 * k as f64, (0.1 * k as f64).cos()))
                    .collect(),
            )],
            band: Some((3.0, 5.0, -0.1, 0.1)),
        };
        plot_signals(&signals, "a swing", &[panel.clone(), panel]).expect("signals");
        let empty_panel = SignalPanel {
            label: "x".to_string(),
            lines: vec![],
            band: None,
        };
        let e = plot_signals(&dir.join("s.png"), "none", &[empty_panel]).expect_err("empty");
        assert!(e.to_string().contains("nothing to plot"), "{e}");
        for path in [&bands, &scores, &signals] {
            let bytes = std::fs::read(path).expect("written");
            assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}", path.display());
            assert!(bytes.len() > 10_000, "{} is nearly empty", path.display());
        }
        let nowhere = dir.join("missing-folder").join("x.png");
        let e =
            plot_cost_bands(&nowhere, &[("m".to_string(), vec![run(0.0)])]).expect_err("no folder");
        assert!(e.to_string().contains("x.png"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
