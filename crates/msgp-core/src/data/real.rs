//! The five real benchmark series of the paper (Table 3), read in place.
//!
//! The files are not shipped (their licence is not ours to relicense); they are found in the
//! folder named by `MSGP_DATA_DIR` (default `../shared/data/real`). Splits are contiguous: the
//! first `n_train` samples train, the rest test.

use std::path::{Path, PathBuf};

use super::Benchmark;
use super::table::Table;
use crate::data::Trajectory;
use crate::error::{MsgpError, Result};

/// Environment variable naming the folder with the real series.
pub const DATA_DIR_VAR: &str = "MSGP_DATA_DIR";

/// One of the five real series.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RealSeries {
    /// Hydraulic actuator (1024 samples).
    Actuator,
    /// Ball and beam (1000).
    Ballbeam,
    /// Coupled electric drives (500).
    Drives,
    /// Gas furnace (296).
    Furnace,
    /// Hair dryer (1000).
    Dryer,
}

impl RealSeries {
    /// All five, in the paper's order.
    pub const ALL: [RealSeries; 5] = [
        RealSeries::Actuator,
        RealSeries::Ballbeam,
        RealSeries::Drives,
        RealSeries::Furnace,
        RealSeries::Dryer,
    ];

    /// File stem.
    pub fn name(&self) -> &'static str {
        match self {
            RealSeries::Actuator => "actuator",
            RealSeries::Ballbeam => "ballbeam",
            RealSeries::Drives => "drives",
            RealSeries::Furnace => "furnace",
            RealSeries::Dryer => "dryer",
        }
    }

    /// (training samples, l_y = l_u) from Table 3.
    pub fn split(&self) -> (usize, usize) {
        match self {
            RealSeries::Actuator => (512, 10),
            RealSeries::Ballbeam => (500, 10),
            RealSeries::Drives => (250, 10),
            RealSeries::Furnace => (148, 3),
            RealSeries::Dryer => (500, 2),
        }
    }

    /// The series split the other way round: the *last* `n_train` samples of Table 3's split
    /// train and the samples before them test, for judging a model on a stretch of the plant's
    /// behaviour it was not trained on (the same amount of training data).
    pub fn load_swapped(&self, dir: &Path) -> Result<Benchmark> {
        let b = self.load(dir)?;
        let (n_train, _) = self.split();
        let u: Vec<f64> = b.train.u.iter().chain(b.test.u.iter()).copied().collect();
        let y: Vec<f64> = b.train.y.iter().chain(b.test.y.iter()).copied().collect();
        let cut = u.len() - n_train;
        Ok(Benchmark {
            name: format!("{} (swapped)", self.name()),
            train: Trajectory::siso(&u[cut..], &y[cut..])?,
            test: Trajectory::siso(&u[..cut], &y[..cut])?,
            ly: b.ly,
            lu: b.lu,
        })
    }

    /// Loads `<dir>/<name>.csv` (columns `t,u,y`) and splits it.
    pub fn load(&self, dir: &Path) -> Result<Benchmark> {
        let path = dir.join(format!("{}.csv", self.name()));
        let table = Table::read_csv(&path)?;
        let u = table.column("u")?;
        let y = table.column("y")?;
        let (n_train, l) = self.split();
        if u.len() <= n_train {
            return Err(MsgpError::File {
                path,
                message: format!("{} samples, the split needs more than {n_train}", u.len()),
            });
        }
        Ok(Benchmark {
            name: self.name().to_string(),
            train: Trajectory::siso(&u[..n_train], &y[..n_train])?,
            test: Trajectory::siso(&u[n_train..], &y[n_train..])?,
            ly: l,
            lu: l,
        })
    }
}

/// The data folder: `$MSGP_DATA_DIR`, else `../shared/data/real` relative to `base`.
pub fn data_dir(base: &Path) -> PathBuf {
    match std::env::var_os(DATA_DIR_VAR) {
        Some(v) if !v.is_empty() => PathBuf::from(v),
        _ => base.join("../shared/data/real"),
    }
}
