//! Data: measured trajectories, their normalisation, the CSV and MCAP readers, the paper's
//! synthetic systems and the real benchmark series.

pub mod dataset;
#[cfg(feature = "mcap")]
pub mod mcap;
pub mod normalize;
pub mod real;
#[cfg(feature = "mcap")]
pub mod ros2;
pub mod synthetic;
pub mod table;
pub mod trajectory;

pub use normalize::Normalizer;
pub use synthetic::{NoiseScale, SyntheticSystem};
pub use trajectory::Trajectory;

/// A train/test split of one input/output series in original units.
#[derive(Clone, Debug, PartialEq)]
pub struct Benchmark {
    /// Name (e.g. "synthetic 4", "dryer").
    pub name: String,
    /// Training part.
    pub train: Trajectory,
    /// Test part (for synthetic systems: noise-free outputs).
    pub test: Trajectory,
    /// `l_y` used by the paper.
    pub ly: usize,
    /// `l_u` used by the paper.
    pub lu: usize,
}
