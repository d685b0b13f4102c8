//! Shared text and JSON rendering of free-simulation metrics.

use msgp_core::model::Metrics;
use serde_json::{Value, json};

/// Adds `rmse`, `nll`, `coverage_2sigma` and `test_steps` to a JSON object (`null` without a
/// test part).
pub fn metrics_json(v: &mut Value, m: Option<&Metrics>) {
    let fields = match m {
        Some(m) => json!({
            "rmse": m.rmse,
            "nll": m.nll,
            "coverage_2sigma": m.coverage_2sigma,
            "test_steps": m.steps,
        }),
        None => json!({
            "rmse": null,
            "nll": null,
            "coverage_2sigma": null,
            "test_steps": 0,
        }),
    };
    if let (Value::Object(dst), Value::Object(src)) = (v, fields) {
        dst.extend(src);
    }
}

/// `label (N steps): RMSE …, NLL/step …, 2σ coverage …` (original units).
pub fn metrics_line(label: &str, m: Option<&Metrics>) -> String {
    match m {
        Some(m) => format!(
            "{label} ({} steps): RMSE {:.6}, mean NLL/step {:.4}, 2σ coverage {:.3}",
            m.steps, m.rmse, m.nll, m.coverage_2sigma
        ),
        None => format!("{label}: no test part (all samples trained)"),
    }
}

/// `1 trajectory`, `3 trajectories`.
pub fn trajectories(n: usize) -> String {
    if n == 1 {
        "1 trajectory".to_string()
    } else {
        format!("{n} trajectories")
    }
}
