//! The PNG plot of one learning run (`msgp learn-policy --out`): per iteration, the expected
//! cost predicted by the model (± 2σ bars) and the cost measured on the system; iterations whose
//! policy passed the stability test are drawn as filled markers ([`plot_costs`]). Plots over
//! seeds (Figure 4's bands) are the reproductions' (crate `msgp-reproduce`).
//!
//! Drawn with plotters' bitmap backend; text uses DejaVu Sans embedded in the library (crate
//! `dejavu`), so no system font library is needed. [`font`] and [`legend`] are the style every
//! msgp plot shares (the command line's simulation plots use them too).

use std::path::Path;
use std::sync::OnceLock;

use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::error::SimError;

/// A plot's error, named by the file it was drawn into.
fn failed(path: &Path, message: impl std::fmt::Display) -> SimError {
    SimError::Plot {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// Registers the embedded font (once per process); every plot calls it first.
pub fn font() -> Result<(), SimError> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = DONE.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .is_ok()
    });
    if *ok {
        Ok(())
    } else {
        Err(failed(
            Path::new("dejavu::sans::regular"),
            "cannot load the embedded font",
        ))
    }
}

/// The series legend in the upper right corner, as every msgp plot draws it.
pub fn legend<'a, DB, CT>(chart: &mut ChartContext<'a, DB, CT>) -> Result<(), String>
where
    DB: DrawingBackend + 'a,
    CT: plotters::coord::CoordTranslate,
{
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 13))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| e.to_string())
}

/// Width of every msgp plot, in pixels.
pub const WIDTH: u32 = 1000;
/// Height of a one-panel plot, in pixels.
pub const HEIGHT: u32 = 560;

/// One policy iteration as the plots show it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CostPoint {
    /// The iteration (from 1).
    pub iteration: usize,
    /// The expected episode cost the model predicted.
    pub predicted: f64,
    /// Its standard deviation.
    pub predicted_std: f64,
    /// The cost measured on the system.
    pub actual: f64,
    /// Whether the iteration's policy passed the stability test.
    pub stable: bool,
}

/// One learning run.
#[derive(Clone, Debug)]
pub struct CostCurve {
    /// Legend label.
    pub label: String,
    /// Points in iteration order.
    pub points: Vec<CostPoint>,
}

/// The colours of series, in order.
pub const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
];

/// Writes the plot of `curves` to `path`.
pub fn plot_costs(path: &Path, title: &str, curves: &[CostCurve]) -> Result<(), SimError> {
    font()?;
    draw(path, title, curves).map_err(|m| failed(path, m))
}

fn draw(path: &Path, title: &str, curves: &[CostCurve]) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<_>| e.to_string();
    let last = curves
        .iter()
        .flat_map(|c| c.points.iter().map(|p| p.iteration))
        .max()
        .ok_or_else(|| "nothing to plot".to_string())?;
    let ymax = curves
        .iter()
        .flat_map(|c| {
            c.points
                .iter()
                .flat_map(|p| [p.predicted + 2.0 * p.predicted_std, p.actual].into_iter())
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
        let predicted: Vec<(f64, f64)> = c
            .points
            .iter()
            .map(|p| (p.iteration as f64 + dx, p.predicted))
            .collect();
        let actual: Vec<(f64, f64)> = c
            .points
            .iter()
            .map(|p| (p.iteration as f64 + dx, p.actual))
            .collect();
        chart
            .draw_series(c.points.iter().map(|p| {
                let x = p.iteration as f64 + dx;
                PathElement::new(
                    vec![
                        (x, (p.predicted - 2.0 * p.predicted_std).max(0.0)),
                        (x, p.predicted + 2.0 * p.predicted_std),
                    ],
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
                let style = if p.stable {
                    colour.filled()
                } else {
                    colour.stroke_width(2)
                };
                Circle::new((p.iteration as f64 + dx, p.actual), 5, style)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_plot_is_a_png_and_says_what_failed() {
        let dir = std::env::temp_dir().join(format!("msgp-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let one = dir.join("one.png");
        let points = (1..=4)
            .map(|iteration| CostPoint {
                iteration,
                predicted: 10.0 / iteration as f64,
                predicted_std: 0.5,
                actual: 12.0 / iteration as f64,
                stable: iteration > 2,
            })
            .collect();
        let curve = CostCurve {
            label: "msgp".to_string(),
            points,
        };
        plot_costs(&one, "a run", &[curve]).expect("plot");
        let bytes = std::fs::read(&one).expect("written");
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        assert!(bytes.len() > 10_000, "nearly empty");
        let empty = plot_costs(&dir.join("empty.png"), "nothing", &[]).expect_err("no points");
        assert!(
            empty.to_string().contains("empty.png: nothing to plot"),
            "{empty}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
