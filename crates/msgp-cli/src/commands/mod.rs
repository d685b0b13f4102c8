//! One module per `msgp` command: each takes its parsed options ([`crate::args`]), calls the
//! libraries and hands the results to [`crate::render`].

pub mod demo;
pub mod eval;
pub mod figure4;
pub mod fit;
pub mod generalisation;
pub mod learn;
pub mod plant_task;
pub mod policy;
pub mod side_by_side;
pub mod sim;
pub mod table1;

use std::path::{Path, PathBuf};

use crate::args::{BenchmarkArgs, DataArgs};
use msgp_core::data::dataset::Selection;
use msgp_core::data::real::data_dir;

impl BenchmarkArgs {
    /// The folder with the real series: `--data-dir`, else `$MSGP_DATA_DIR`, else
    /// `../shared/data/real`.
    pub fn data_dir(&self) -> PathBuf {
        self.data_dir
            .clone()
            .unwrap_or_else(|| data_dir(Path::new(".")))
    }

    /// At least one seed was given.
    pub fn check_seeds(&self) -> anyhow::Result<()> {
        if self.seeds.is_empty() {
            anyhow::bail!("--seeds: give at least one seed");
        }
        Ok(())
    }
}

impl DataArgs {
    /// The columns or signals these options select.
    pub fn selection(&self) -> Selection<'_> {
        Selection {
            inputs: &self.input,
            outputs: &self.output,
            topic: self.topic.as_deref(),
            time: self.time.into(),
            sort_time: self.sort_time,
        }
    }
}
