//! Prediction files of `msgp simulate --out`: the free simulation's mean and standard
//! deviation beside the measured outputs, per simulated step, as CSV or as an MCAP log that
//! Foxglove plots (the extension chooses).
//!
//! **CSV:** `t, <output>_mean, <output>_std, <output>` per step (`episode` first with several
//! trajectories; with `--filtered` also `<output>_filtered_mean, <output>_filtered_std`).
//!
//! **MCAP:** JSON messages on `/msgp/prediction` (one trajectory) or
//! `/msgp/prediction/<episode>` (several; the `episode` value or the trajectory's index), schema
//! `msgp.Prediction` (`jsonschema`), one message per step with `log_time = publish_time =` the
//! step's time (time column or MCAP time; negative times are shifted to start at 0):
//! `{"t", "outputs": [{"name", "measured", "mean", "std", "lower", "upper"[, "filtered_mean",
//! "filtered_std"]}, …]}`, `lower`/`upper` = mean ∓ 2 std. In Foxglove's plot panel the series
//! `/msgp/prediction.outputs[0].measured`, `.mean`, `.lower` and `.upper` overlay.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;
use msgp_core::model::Simulated;
use serde_json::json;

/// The format of a prediction file: the run logs' choice by extension (`.csv` or `.mcap`).
pub use msgp_sim::log::LogFormat as Format;

/// The format `path`'s extension names, or an error saying which ones there are.
pub fn format_of(path: &Path) -> anyhow::Result<Format> {
    Format::from_path(path).map_err(|_| {
        anyhow::anyhow!(
            "--out {}: the prediction file's extension must be .csv or .mcap",
            path.display()
        )
    })
}

/// The file's bytes in `format`.
pub fn encode(
    format: Format,
    outputs: &[String],
    sims: &[Simulated],
    filtered: Option<&[Simulated]>,
) -> anyhow::Result<Vec<u8>> {
    match format {
        Format::Csv => Ok(csv(outputs, sims, filtered).into_bytes()),
        Format::Mcap => mcap_log(outputs, sims, filtered),
    }
}

/// The prediction CSV; with `filtered` (one per simulation, the same steps) two more columns
/// per output.
fn csv(outputs: &[String], sims: &[Simulated], filtered: Option<&[Simulated]>) -> String {
    let several = sims.len() > 1;
    let mut s = String::new();
    if several {
        s.push_str("episode,");
    }
    s.push('t');
    for name in outputs {
        // writing to a String cannot fail
        let _ = write!(s, ",{name}_mean,{name}_std,{name}");
        if filtered.is_some() {
            let _ = write!(s, ",{name}_filtered_mean,{name}_filtered_std");
        }
    }
    s.push('\n');
    for (k, sim) in sims.iter().enumerate() {
        let start = sim.sim.start;
        for i in 0..sim.sim.mean.nrows() {
            if several {
                let _ = match sim.part.episode {
                    Some(e) => write!(s, "{e},"),
                    None => write!(s, "{k},"),
                };
            }
            let _ = write!(s, "{}", sim.part.times[start + i]);
            for j in 0..outputs.len() {
                let _ = write!(
                    s,
                    ",{},{},{}",
                    sim.sim.mean[(i, j)],
                    sim.sim.var[(i, j)].max(0.0).sqrt(),
                    sim.part.traj.y[(start + i, j)]
                );
                if let Some(f) = filtered.map(|f| &f[k].sim) {
                    let _ = write!(s, ",{},{}", f.mean[(i, j)], f.var[(i, j)].max(0.0).sqrt());
                }
            }
            s.push('\n');
        }
    }
    s
}

const SCHEMA: &str = r#"{"title":"msgp.Prediction","description":"Free simulation of a fitted model beside the measured outputs","type":"object","properties":{"t":{"type":"number","description":"time of the step (data time column or MCAP time) [s]"},"outputs":{"type":"array","items":{"type":"object","properties":{"name":{"type":"string"},"measured":{"type":"number"},"mean":{"type":"number","description":"predicted mean"},"std":{"type":"number","description":"predicted standard deviation"},"lower":{"type":"number","description":"mean - 2 std"},"upper":{"type":"number","description":"mean + 2 std"},"filtered_mean":{"type":"number","description":"one-step-ahead filtered mean (--filtered)"},"filtered_std":{"type":"number","description":"one-step-ahead filtered standard deviation (--filtered)"}},"required":["name","measured","mean","std","lower","upper"]}}},"required":["t","outputs"]}"#;

/// The MCAP prediction log (see the module docs).
fn mcap_log(
    outputs: &[String],
    sims: &[Simulated],
    filtered: Option<&[Simulated]>,
) -> anyhow::Result<Vec<u8>> {
    let mut buf = std::io::Cursor::new(Vec::new());
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_threads(0)
        .create(&mut buf)
        .context("cannot start the MCAP log")?;
    let schema = w
        .add_schema("msgp.Prediction", "jsonschema", SCHEMA.as_bytes())
        .context("cannot add the MCAP schema")?;
    // times below zero are shifted so that the log starts at 0 (MCAP times are unsigned)
    let t0 = sims
        .iter()
        .flat_map(|s| s.part.times[s.sim.start..].iter().copied())
        .fold(0.0f64, f64::min);
    for (k, sim) in sims.iter().enumerate() {
        let topic = if sims.len() == 1 {
            "/msgp/prediction".to_string()
        } else {
            match sim.part.episode {
                Some(e) => format!("/msgp/prediction/{e}"),
                None => format!("/msgp/prediction/{k}"),
            }
        };
        let channel = w
            .add_channel(schema, &topic, "json", &BTreeMap::new())
            .with_context(|| format!("cannot add the MCAP channel {topic}"))?;
        let start = sim.sim.start;
        for i in 0..sim.sim.mean.nrows() {
            let t = sim.part.times[start + i];
            let mut items = Vec::with_capacity(outputs.len());
            for (j, name) in outputs.iter().enumerate() {
                let (mean, std) = (sim.sim.mean[(i, j)], sim.sim.var[(i, j)].max(0.0).sqrt());
                let mut item = json!({
                    "name": name,
                    "measured": sim.part.traj.y[(start + i, j)],
                    "mean": mean,
                    "std": std,
                    "lower": mean - 2.0 * std,
                    "upper": mean + 2.0 * std,
                });
                if let Some(f) = filtered.map(|f| &f[k].sim) {
                    item["filtered_mean"] = json!(f.mean[(i, j)]);
                    item["filtered_std"] = json!(f.var[(i, j)].max(0.0).sqrt());
                }
                items.push(item);
            }
            let body = serde_json::to_vec(&json!({ "t": t, "outputs": items }))
                .context("cannot encode a prediction message")?;
            let time = ((t - t0) * 1e9).round().max(0.0) as u64;
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: u32::try_from(i).unwrap_or(u32::MAX),
                log_time: time,
                publish_time: time,
            };
            w.write_to_known_channel(&header, &body)
                .context("cannot write a prediction message")?;
        }
    }
    w.finish().context("cannot finish the MCAP log")?;
    drop(w);
    Ok(buf.into_inner())
}
