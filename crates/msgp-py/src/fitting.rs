//! The fit behind `Msgp.fit`, run without the GIL: the history chosen from the data first
//! where asked, then the fit, its progress relayed to a Python callable, and the model as
//! saved (what `msgp fit` writes).

use msgp_core::data::Trajectory;
use msgp_core::fit::history::{HistoryEvent, HistorySearch, with_chosen_history};
use msgp_core::fit::{FitOptions, FitReport, fit_observed};
use msgp_core::model::Model;
use msgp_core::model_file::{FitRecord, ModelFile};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::{Result, with_python};
use crate::options;

/// A fitted or loaded model: the file as `msgp fit` writes it and the model it describes.
#[derive(Debug)]
pub struct Fitted {
    pub file: ModelFile,
    pub model: Model,
    pub report: Option<FitReport>,
}

/// The fit behind `Msgp.fit`, without the GIL: the history chosen first where asked
/// (each judged candidate a progress event of stage 0), then the fit, its model as saved.
/// The outer error is the fit's; the inner one an exception `progress` raised (or Ctrl-C).
pub fn fit_detached(
    (options, auto_history): (FitOptions, bool),
    train: &[Trajectory],
    (inputs, outputs): &(Vec<String>, Vec<String>),
    progress: Option<Py<PyAny>>,
) -> Result<std::result::Result<Fitted, PyErr>> {
    let mut raised = None;
    // `history="auto"`: each judged candidate is a progress event of stage 0
    let (options, choice) = match auto_history {
        false => (options, None),
        true => {
            let chosen =
                with_chosen_history(&options, train, &HistorySearch::default(), &mut |event| {
                    match event {
                        // (Ctrl-C stops the candidate's fit)
                        HistoryEvent::Fit(_) => with_python(&mut raised, |_| Ok(())),
                        HistoryEvent::Judged(p) => with_python(&mut raised, |py| {
                            let Some(f) = &progress else {
                                return Ok(());
                            };
                            let d = PyDict::new(py);
                            d.set_item("stage", 0)?;
                            d.set_item("iteration", p.done)?;
                            d.set_item("iterations", p.of)?;
                            d.set_item("loss", p.scored.score)?;
                            d.set_item("validation", None::<f64>)?;
                            d.set_item("elapsed", p.elapsed)?;
                            d.set_item("history", (p.scored.ly, p.scored.lu))?;
                            f.call1(py, (d,))?;
                            Ok(())
                        }),
                    }
                });
            if let Some(err) = raised.take() {
                return Ok(Err(err));
            }
            let (options, choice) = chosen?;
            (options, Some(choice))
        }
    };
    let settings = options::settings(&options, train)?;
    let fitted = fit_observed(train, &settings, &mut |p| {
        with_python(&mut raised, |py| {
            let Some(f) = &progress else {
                return Ok(());
            };
            let d = PyDict::new(py);
            d.set_item("stage", p.stage)?;
            d.set_item("iteration", p.iteration)?;
            d.set_item("iterations", p.iterations)?;
            d.set_item("loss", p.loss)?;
            d.set_item("validation", p.validation)?;
            d.set_item("elapsed", p.elapsed)?;
            f.call1(py, (d,))?;
            Ok(())
        })
    });
    if let Some(err) = raised {
        return Ok(Err(err));
    }
    let (model, mut report) = fitted?;
    report.history_choice = choice;
    let file = ModelFile::from_fit(
        &model,
        &FitRecord {
            inputs,
            outputs,
            settings: &settings,
            report: &report,
            train,
        },
    )?;
    // predict with the model as saved, like `msgp fit`
    let model = file.to_model()?;
    Ok(Ok(Fitted {
        file,
        model,
        report: Some(report),
    }))
}
