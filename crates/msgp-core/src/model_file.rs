//! The versioned model file: a JSON document holding everything needed to recompute a fitted
//! model's predictions, plus where it came from. The format is specified field by field in
//! `docs/model-format.md`.
//!
//! - [`ModelFile::from_fit`] describes a fitted [`Model`] with its column names, training
//!   settings and a hash of the training data; [`ModelFile::to_model`] turns a file back into a
//!   [`Model`] after checking every shape and value.
//! - [`ModelFile::write`] writes atomically (temporary file in the same folder, fsync, rename);
//!   [`ModelFile::read`] refuses files of another major format version with
//!   [`MsgpError::ModelVersion`] before looking at anything else.
//! - Floats are written as shortest round-trip decimals and parsed exactly, so a saved and
//!   reloaded model predicts bit-identical numbers.

use std::io::Write;
use std::path::{Path, PathBuf};

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::data::Normalizer;
use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::fit::{FitReport, FitSettings, RecipeOutcome};
use crate::gp::{GpConfig, GpParams, MeanFunction, PreparedGp};
use crate::model::{Method, Model};
use crate::narx::NarxSpec;
use crate::numeric::linalg::{JitterLog, JitterPolicy};

/// Value of the `format` field.
pub const FORMAT: &str = "msgp-model";
/// Major format version written and read by this build.
pub const FORMAT_MAJOR: u32 = 1;
/// Minor format version written by this build (readers accept any minor of their major).
pub const FORMAT_MINOR: u32 = 4;

/// NARX history lengths.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct History {
    /// `l_y`: past outputs in the window (≥ 1).
    pub ly: usize,
    /// `l_u`: past inputs in the window.
    pub lu: usize,
}

/// Per-column z-scoring statistics of the training data (original units).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normalization {
    /// Input means, one per input column.
    pub u_mean: Vec<f64>,
    /// Input standard deviations.
    pub u_std: Vec<f64>,
    /// Output means, one per output column.
    pub y_mean: Vec<f64>,
    /// Output standard deviations.
    pub y_std: Vec<f64>,
}

/// The jitter policy of every Cholesky factorisation.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Jitter {
    /// First relative jitter tried after a failed factorisation.
    pub initial_relative: f64,
    /// Growth factor between attempts.
    pub growth: f64,
    /// Largest relative jitter before giving up.
    pub max_relative: f64,
}

/// The sparse GP in normalised units (see `docs/model-format.md` for the equations).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GpFile {
    /// `m` pseudo-inputs, each a NARX window of length `D`.
    pub pseudo_inputs: Vec<Vec<f64>>,
    /// `m` rows of pseudo-targets, one entry per output.
    pub pseudo_targets: Vec<Vec<f64>>,
    /// `E` rows (one per output) of `D` log length-scales `log ℓ`.
    pub log_lengthscales: Vec<Vec<f64>>,
    /// `log σ_f²` per output.
    pub log_signal_var: Vec<f64>,
    /// `θ_x` per output: process noise `σ_x² = noise_floor + exp(θ_x)`.
    pub log_process_noise: Vec<f64>,
    /// `θ_y` per output: observation noise `σ_y² = noise_floor + exp(θ_y)`.
    pub log_obs_noise: Vec<f64>,
    /// Floor added to both noise variances.
    pub noise_floor: f64,
    /// Jitter policy.
    pub jitter: Jitter,
    /// `E` rows of `D` coefficients of the linear prior mean `m(x̃) = A x̃` (format 1.1);
    /// absent for the zero mean.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub linear_mean: Option<Vec<Vec<f64>>>,
    /// Per output, the variance (normalised units, ≥ 0) added to every free-simulated output
    /// variance (format 1.3; `msgp_core::fit::calibration`); absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<Vec<f64>>,
}

/// Where the model came from (not needed for predictions).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Training {
    /// Seed of every random choice of the fit.
    pub seed: u64,
    /// `fnv1a64:<16 hex digits>` of the training data (see [`training_data_hash`]).
    pub data_hash: String,
    /// Number of training trajectories.
    pub trajectories: usize,
    /// Number of training samples, all trajectories together.
    pub samples: usize,
    /// Wall-clock seconds of the fit.
    pub train_seconds: f64,
    /// Adam iterations run on the MSGP loss (0 for the one-step methods).
    pub iterations_run: usize,
    /// Iteration chosen by early stopping.
    pub best_iteration: usize,
    /// Why the fitted model's free simulation over its training inputs diverges
    /// (`msgp_core::fit::check_divergence`); `null` when it does not.
    #[serde(default)]
    pub diverged: Option<String>,
    /// MSGP: each recipe the fit trained, with its start, validation NLL and why its training
    /// or final training failed (format 1.4; `msgp_core::fit::FitReport::recipes`); empty for
    /// the other methods and in older files.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub recipes: Vec<RecipeOutcome>,
    /// MSGP: the index in `recipes` of the model's recipe (format 1.4).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chosen_recipe: Option<usize>,
    /// MSGP: the iterate of the final training on all the data that the model is (format 1.4);
    /// absent where the head's model stands or there was no final training.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub full_data_iteration: Option<usize>,
    /// MSGP: why the final training on all the data failed, where it did (format 1.4).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub full_data_failed: Option<String>,
    /// The history chosen from the training data (`--history auto`): the choice and what each
    /// stage scored ([`crate::fit::history::HistoryChoice`]); absent where it was given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub history_choice: Option<crate::fit::history::HistoryChoice>,
    /// Every fit setting, as `msgp_core::fit::FitSettings` serialises it (informational).
    pub settings: Value,
}

/// A one-step prediction for checking another implementation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reference {
    /// A GP input window (normalised units, NARX layout).
    pub window: Vec<f64>,
    /// Predictive mean of the latent `f_a` at `window`, per output (normalised units).
    pub mean: Vec<f64>,
    /// Predictive variance of `f_a` (no noise), per output (normalised units).
    pub var: Vec<f64>,
}

/// The model file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelFile {
    /// Always [`FORMAT`].
    pub format: String,
    /// `MAJOR.MINOR`.
    pub format_version: String,
    /// Version of msgp-core that wrote the file.
    pub crate_version: String,
    /// `msgp`, `gp-narx` or `pilco-narx`.
    pub method: String,
    /// Input column names, in window order.
    pub inputs: Vec<String>,
    /// Output column names, in window order.
    pub outputs: Vec<String>,
    /// History lengths.
    pub history: History,
    /// Normalisation.
    pub normalization: Normalization,
    /// GP parameters.
    pub gp: GpFile,
    /// Provenance.
    pub training: Training,
    /// A one-step check value (optional).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<Reference>,
}

/// Everything about a fit that the model itself does not hold.
#[derive(Clone, Copy, Debug)]
pub struct FitRecord<'a> {
    /// Input column names.
    pub inputs: &'a [String],
    /// Output column names.
    pub outputs: &'a [String],
    /// Settings of the fit.
    pub settings: &'a FitSettings,
    /// What the fit reported.
    pub report: &'a FitReport,
    /// The training trajectories (original units), for the hash.
    pub train: &'a [Trajectory],
}

/// FNV-1a (64 bit) of the training data, as `fnv1a64:<16 lowercase hex digits>`.
///
/// Bytes hashed, in order: for each trajectory, its number of samples `T`, inputs `d_u` and
/// outputs `d_y` as little-endian `u64`, then for each sample `t` the inputs `u[t, 0..d_u]`
/// followed by the outputs `y[t, 0..d_y]`, each as the little-endian IEEE-754 bits of the `f64`.
pub fn training_data_hash(train: &[Trajectory]) -> String {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let mut h = OFFSET;
    let mut eat = |bytes: [u8; 8]| {
        for b in bytes {
            h ^= u64::from(b);
            h = h.wrapping_mul(PRIME);
        }
    };
    for t in train {
        eat((t.len() as u64).to_le_bytes());
        eat((t.u.ncols() as u64).to_le_bytes());
        eat((t.y.ncols() as u64).to_le_bytes());
        for i in 0..t.len() {
            for j in 0..t.u.ncols() {
                eat(t.u[(i, j)].to_bits().to_le_bytes());
            }
            for j in 0..t.y.ncols() {
                eat(t.y[(i, j)].to_bits().to_le_bytes());
            }
        }
    }
    format!("fnv1a64:{h:016x}")
}

pub(crate) fn rows_of(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| m.row(i).iter().copied().collect())
        .collect()
}

fn shape_err(path: &Path, message: String) -> MsgpError {
    MsgpError::File {
        path: path.to_path_buf(),
        message: format!("invalid model file: {message}"),
    }
}

/// `rows` as an `nrows × ncols` matrix, or a message naming `what`.
fn matrix(
    path: &Path,
    what: &str,
    rows: &[Vec<f64>],
    nrows: usize,
    ncols: usize,
) -> Result<DMatrix<f64>> {
    if rows.len() != nrows {
        return Err(shape_err(
            path,
            format!("`{what}` has {} rows, expected {nrows}", rows.len()),
        ));
    }
    for (i, r) in rows.iter().enumerate() {
        if r.len() != ncols {
            return Err(shape_err(
                path,
                format!(
                    "row {i} of `{what}` has {} entries, expected {ncols}",
                    r.len()
                ),
            ));
        }
    }
    Ok(DMatrix::from_fn(nrows, ncols, |i, j| rows[i][j]))
}

fn vector(path: &Path, what: &str, v: &[f64], n: usize) -> Result<DVector<f64>> {
    if v.len() != n {
        return Err(shape_err(
            path,
            format!("`{what}` has {} entries, expected {n}", v.len()),
        ));
    }
    Ok(DVector::from_column_slice(v))
}

fn check_finite(path: &Path, what: &str, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(shape_err(path, format!("`{what}` entry {i} is not finite"))),
        None => Ok(()),
    }
}

/// Parses `MAJOR.MINOR`.
pub(crate) fn parse_version(s: &str) -> Option<(u32, u32)> {
    let (major, minor) = s.split_once('.')?;
    Some((major.parse().ok()?, minor.parse().ok()?))
}

impl ModelFile {
    /// Describes a fitted model.
    pub fn from_fit(model: &Model, record: &FitRecord<'_>) -> Result<Self> {
        let spec = model.spec;
        if record.inputs.len() != spec.du || record.outputs.len() != spec.dy {
            return Err(MsgpError::Shape(format!(
                "{} input and {} output names for a model with {} inputs and {} outputs",
                record.inputs.len(),
                record.outputs.len(),
                spec.du,
                spec.dy
            )));
        }
        let p = &model.params;
        let n = &model.normalizer;
        let reference = match record.train.first() {
            Some(t) if t.len() > spec.warmup() => {
                let norm = n.apply(t);
                let window = spec.window(&norm.y, &norm.u, spec.warmup() - 1);
                let mut log = JitterLog::default();
                let gp = PreparedGp::new(p, &model.config, &mut log)?;
                let pred = gp.predict(&window);
                Some(Reference {
                    window,
                    mean: pred.iter().map(|(m, _)| *m).collect(),
                    var: pred.iter().map(|(_, v)| *v).collect(),
                })
            }
            _ => None,
        };
        Ok(Self {
            format: FORMAT.to_string(),
            format_version: format!("{FORMAT_MAJOR}.{FORMAT_MINOR}"),
            crate_version: env!("CARGO_PKG_VERSION").to_string(),
            method: model.method.name().to_string(),
            inputs: record.inputs.to_vec(),
            outputs: record.outputs.to_vec(),
            history: History {
                ly: spec.ly,
                lu: spec.lu,
            },
            normalization: Normalization {
                u_mean: n.u_mean.clone(),
                u_std: n.u_std.clone(),
                y_mean: n.y_mean.clone(),
                y_std: n.y_std.clone(),
            },
            gp: GpFile {
                pseudo_inputs: rows_of(&p.pseudo_inputs),
                pseudo_targets: rows_of(&p.pseudo_targets),
                log_lengthscales: rows_of(&p.log_lengthscales),
                log_signal_var: p.log_signal_var.iter().copied().collect(),
                log_process_noise: p.log_process_noise.iter().copied().collect(),
                log_obs_noise: p.log_obs_noise.iter().copied().collect(),
                noise_floor: model.config.noise_floor,
                jitter: Jitter {
                    initial_relative: model.config.jitter.initial_relative,
                    growth: model.config.jitter.growth,
                    max_relative: model.config.jitter.max_relative,
                },
                linear_mean: (model.config.mean == MeanFunction::Linear)
                    .then(|| rows_of(&p.linear_mean)),
                calibration: (!model.calibration.is_empty()).then(|| model.calibration.clone()),
            },
            training: Training {
                seed: record.settings.seed,
                data_hash: training_data_hash(record.train),
                trajectories: record.train.len(),
                samples: record.train.iter().map(Trajectory::len).sum(),
                train_seconds: record.report.train_seconds,
                iterations_run: record.report.iterations_run,
                best_iteration: record.report.best_iteration,
                diverged: record.report.diverged.clone(),
                recipes: record.report.recipes.clone(),
                chosen_recipe: (!record.report.recipes.is_empty())
                    .then_some(record.report.chosen_recipe),
                full_data_iteration: record.report.full_data_iteration,
                full_data_failed: record.report.full_data_failed.clone(),
                history_choice: record.report.history_choice.clone(),
                settings: serde_json::to_value(record.settings)
                    .map_err(|e| MsgpError::Data(format!("cannot serialise the settings: {e}")))?,
            },
            reference,
        })
    }

    /// The training method.
    pub fn method(&self) -> Option<Method> {
        Method::from_name(&self.method)
    }

    /// Checks every shape and value and builds the [`Model`]; `path` is used in messages.
    pub fn to_model_at(&self, path: &Path) -> Result<Model> {
        let method = self.method().ok_or_else(|| {
            shape_err(
                path,
                format!(
                    "unknown method `{}` (expected msgp, gp-narx, pilco-narx or linear-kf)",
                    self.method
                ),
            )
        })?;
        let (du, dy) = (self.inputs.len(), self.outputs.len());
        let spec = NarxSpec {
            ly: self.history.ly,
            lu: self.history.lu,
            dy,
            du,
        };
        spec.validate()
            .map_err(|e| shape_err(path, e.to_string()))?;
        if self.gp.pseudo_inputs.is_empty() {
            return Err(shape_err(path, "`gp.pseudo_inputs` is empty".into()));
        }
        let normalizer = self.normalizer_at(path, du, dy)?;
        let params = self.params_at(path, &spec)?;
        let calibration = self.calibration_at(path, dy)?;
        let config = self.config_at(path)?;
        Ok(Model {
            method,
            spec,
            params,
            config,
            normalizer,
            calibration,
        })
    }

    /// The normalisation, each vector of its length, finite, the scales positive.
    fn normalizer_at(&self, path: &Path, du: usize, dy: usize) -> Result<Normalizer> {
        let n = &self.normalization;
        for (what, v, len) in [
            ("normalization.u_mean", &n.u_mean, du),
            ("normalization.u_std", &n.u_std, du),
            ("normalization.y_mean", &n.y_mean, dy),
            ("normalization.y_std", &n.y_std, dy),
        ] {
            vector(path, what, v, len)?;
            check_finite(path, what, v)?;
        }
        for (what, v) in [
            ("normalization.u_std", &n.u_std),
            ("normalization.y_std", &n.y_std),
        ] {
            if let Some(i) = v.iter().position(|s| *s <= 0.0) {
                return Err(shape_err(
                    path,
                    format!("`{what}` entry {i} is not positive"),
                ));
            }
        }
        Ok(Normalizer {
            u_mean: n.u_mean.clone(),
            u_std: n.u_std.clone(),
            y_mean: n.y_mean.clone(),
            y_std: n.y_std.clone(),
        })
    }

    /// The GP's parameters, each of the window's shape and finite.
    fn params_at(&self, path: &Path, spec: &NarxSpec) -> Result<GpParams<f64>> {
        let (g, d, dy) = (&self.gp, spec.input_dim(), spec.dy);
        let m = g.pseudo_inputs.len();
        let params = GpParams {
            pseudo_inputs: matrix(path, "gp.pseudo_inputs", &g.pseudo_inputs, m, d)?,
            pseudo_targets: matrix(path, "gp.pseudo_targets", &g.pseudo_targets, m, dy)?,
            log_lengthscales: matrix(path, "gp.log_lengthscales", &g.log_lengthscales, dy, d)?,
            log_signal_var: vector(path, "gp.log_signal_var", &g.log_signal_var, dy)?,
            log_process_noise: vector(path, "gp.log_process_noise", &g.log_process_noise, dy)?,
            log_obs_noise: vector(path, "gp.log_obs_noise", &g.log_obs_noise, dy)?,
            linear_mean: match &g.linear_mean {
                Some(rows) => matrix(path, "gp.linear_mean", rows, dy, d)?,
                None => DMatrix::zeros(dy, d),
            },
        };
        for (what, values) in [
            ("gp.pseudo_inputs", params.pseudo_inputs.as_slice()),
            ("gp.pseudo_targets", params.pseudo_targets.as_slice()),
            ("gp.log_lengthscales", params.log_lengthscales.as_slice()),
            ("gp.log_signal_var", params.log_signal_var.as_slice()),
            ("gp.log_process_noise", params.log_process_noise.as_slice()),
            ("gp.log_obs_noise", params.log_obs_noise.as_slice()),
            ("gp.linear_mean", params.linear_mean.as_slice()),
        ] {
            check_finite(path, what, values)?;
        }
        Ok(params)
    }

    /// The calibration's added variances (none in files before it), each finite and ≥ 0.
    fn calibration_at(&self, path: &Path, dy: usize) -> Result<Vec<f64>> {
        let Some(c) = &self.gp.calibration else {
            return Ok(Vec::new());
        };
        vector(path, "gp.calibration", c, dy)?;
        check_finite(path, "gp.calibration", c)?;
        if let Some(i) = c.iter().position(|v| *v < 0.0) {
            return Err(shape_err(
                path,
                format!("`gp.calibration` entry {i} is negative"),
            ));
        }
        Ok(c.clone())
    }

    /// The GP's configuration: its noise floor, jitter policy and prior mean.
    fn config_at(&self, path: &Path) -> Result<GpConfig> {
        let g = &self.gp;
        let j = g.jitter;
        let valid = g.noise_floor.is_finite()
            && g.noise_floor >= 0.0
            && j.initial_relative.is_finite()
            && j.initial_relative > 0.0
            && j.growth.is_finite()
            && j.growth > 1.0
            && j.max_relative.is_finite()
            && j.max_relative >= j.initial_relative;
        if !valid {
            return Err(shape_err(
                path,
                "`gp.noise_floor` must be ≥ 0 and `gp.jitter` needs 0 < initial_relative ≤ max_relative and growth > 1".into(),
            ));
        }
        Ok(GpConfig {
            noise_floor: g.noise_floor,
            jitter: JitterPolicy {
                initial_relative: j.initial_relative,
                growth: j.growth,
                max_relative: j.max_relative,
            },
            mean: if g.linear_mean.is_some() {
                MeanFunction::Linear
            } else {
                MeanFunction::Zero
            },
            ..GpConfig::default()
        })
    }

    /// [`to_model_at`](Self::to_model_at) without a file name.
    pub fn to_model(&self) -> Result<Model> {
        self.to_model_at(Path::new("<model>"))
    }

    /// Parses and checks a model file's bytes; `path` is used in messages.
    pub fn from_json(bytes: &[u8], path: &Path) -> Result<Self> {
        let value: Value = serde_json::from_slice(bytes)
            .map_err(|e| shape_err(path, format!("not valid JSON: {e}")))?;
        let Value::Object(obj) = &value else {
            return Err(shape_err(path, "not a JSON object".into()));
        };
        match obj.get("format") {
            Some(Value::String(f)) if f == FORMAT => {}
            _ => {
                return Err(shape_err(
                    path,
                    format!("not an msgp model file (no \"format\": \"{FORMAT}\")"),
                ));
            }
        }
        let version = match obj.get("format_version") {
            Some(Value::String(v)) => v.clone(),
            _ => {
                return Err(shape_err(path, "no \"format_version\" string".into()));
            }
        };
        match parse_version(&version) {
            Some((major, _)) if major == FORMAT_MAJOR => {}
            _ => {
                return Err(MsgpError::ModelVersion {
                    path: path.to_path_buf(),
                    found: version,
                    supported: format!("{FORMAT_MAJOR}.x"),
                });
            }
        }
        let file: Self =
            serde_json::from_value(value).map_err(|e| shape_err(path, e.to_string()))?;
        file.to_model_at(path)?;
        Ok(file)
    }

    /// Reads and checks a model file.
    pub fn read(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| MsgpError::File {
            path: path.to_path_buf(),
            message: format!("cannot read the model: {e}"),
        })?;
        Self::from_json(&bytes, path)
    }

    /// Pretty-printed JSON text.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self)
            .map_err(|e| MsgpError::Data(format!("cannot serialise the model: {e}")))
    }

    /// Writes the file atomically: a temporary file in the same folder, fsync, rename. On
    /// failure `path` is left as it was and the temporary file is removed.
    pub fn write(&self, path: &Path) -> Result<()> {
        let mut text = self.to_json()?;
        text.push('\n');
        write_atomically(path, text.as_bytes())
    }
}

/// Writes `bytes` to `path` through a temporary sibling file and a rename.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let io = |action: &str, p: &Path, e: std::io::Error| MsgpError::File {
        path: p.to_path_buf(),
        message: format!("{action}: {e}"),
    };
    let tmp = temp_path(path)?;
    let result = (|| {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(|e| io("cannot create a temporary file", &tmp, e))?;
        f.write_all(bytes)
            .map_err(|e| io("cannot write", &tmp, e))?;
        f.sync_all().map_err(|e| io("cannot sync", &tmp, e))?;
        drop(f);
        std::fs::rename(&tmp, path).map_err(|e| io("cannot rename the temporary file to", path, e))
    })();
    if result.is_err() {
        // best effort: the original error is what matters
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// `dir/.name.tmp-<pid>-<n>` next to `path`.
fn temp_path(path: &Path) -> Result<PathBuf> {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = path.file_name().ok_or_else(|| MsgpError::File {
        path: path.to_path_buf(),
        message: "cannot write: the path has no file name".into(),
    })?;
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    Ok(path.with_file_name(format!(
        ".{}.tmp-{}-{n}",
        name.to_string_lossy(),
        std::process::id()
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{NoiseScale, SyntheticSystem};
    use crate::fit::{MsgpSettings, fit};

    fn fitted() -> (Model, ModelFile, Trajectory) {
        let bench = SyntheticSystem::new(4)
            .expect("system")
            .generate(0, NoiseScale::StdDev)
            .expect("data");
        let train = bench.train.slice(0, 120);
        let settings = FitSettings {
            ly: 2,
            lu: 1,
            method: MsgpSettings {
                inducing: 10,
                iterations: 3,
                one_step_iterations: 20,
                ..MsgpSettings::default()
            }
            .into(),
            ..FitSettings::default()
        };
        let (model, report) =
            fit(std::slice::from_ref(&train), &settings, &mut |_| {}).expect("fit");
        let names = |s: &str| vec![s.to_string()];
        let file = ModelFile::from_fit(
            &model,
            &FitRecord {
                inputs: &names("u"),
                outputs: &names("y"),
                settings: &settings,
                report: &report,
                train: std::slice::from_ref(&train),
            },
        )
        .expect("describe");
        (model, file, bench.test)
    }

    #[test]
    fn json_round_trip_is_exact() {
        let (model, file, test) = fitted();
        let text = file.to_json().expect("json");
        let back = ModelFile::from_json(text.as_bytes(), Path::new("m.json")).expect("parse");
        assert_eq!(back, file);
        let m2 = back.to_model().expect("model");
        assert_eq!(m2.params, model.params);
        assert_eq!(m2.normalizer, model.normalizer);
        assert_eq!(
            m2.simulate(&test).expect("sim"),
            model.simulate(&test).expect("sim")
        );
        assert!(file.training.data_hash.starts_with("fnv1a64:"));
        assert_eq!(file.training.data_hash.len(), 8 + 16);
    }

    #[test]
    fn fnv_known_value() {
        // FNV-1a 64 of the empty input is the offset basis
        assert_eq!(training_data_hash(&[]), "fnv1a64:cbf29ce484222325");
    }

    #[test]
    fn bad_files_are_refused_clearly() {
        let (_, file, _) = fitted();
        let p = Path::new("m.json");
        let mut v: Value = serde_json::to_value(&file).expect("value");
        v["format_version"] = Value::from("2.0");
        let e = ModelFile::from_json(v.to_string().as_bytes(), p).expect_err("v2");
        assert!(matches!(e, MsgpError::ModelVersion { .. }), "{e}");
        assert!(
            e.to_string().contains("version 2.0 is not supported"),
            "{e}"
        );
        let mut v: Value = serde_json::to_value(&file).expect("value");
        v["gp"]["log_signal_var"] = serde_json::json!([1.0, 2.0]);
        let e = ModelFile::from_json(v.to_string().as_bytes(), p).expect_err("shape");
        assert!(
            e.to_string()
                .contains("`gp.log_signal_var` has 2 entries, expected 1"),
            "{e}"
        );
        let mut v: Value = serde_json::to_value(&file).expect("value");
        v["gp"]["pseudo_inputs"][0] = serde_json::json!([1.0]);
        let e = ModelFile::from_json(v.to_string().as_bytes(), p).expect_err("row");
        assert!(e.to_string().contains("row 0 of `gp.pseudo_inputs`"), "{e}");
        let e = ModelFile::from_json(b"{}", p).expect_err("not a model");
        assert!(e.to_string().contains("not an msgp model file"), "{e}");
        let e = ModelFile::from_json(b"\xff", p).expect_err("not json");
        assert!(e.to_string().contains("not valid JSON"), "{e}");
    }

    #[test]
    fn write_is_atomic_and_readable() {
        let (_, file, _) = fitted();
        let dir = std::env::temp_dir().join(format!("msgp-model-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("m.json");
        file.write(&path).expect("write");
        assert_eq!(ModelFile::read(&path).expect("read"), file);
        let names: Vec<_> = std::fs::read_dir(&dir).expect("list").collect();
        assert_eq!(names.len(), 1, "no temporary file left");
        assert!(file.write(&dir.join("missing/m.json")).is_err());
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }
}
