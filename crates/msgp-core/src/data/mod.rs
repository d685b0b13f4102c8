//! Data: the paper's synthetic systems, the real benchmark series, normalisation.

#[cfg(feature = "mcap")]
pub mod mcap;
pub mod normalize;
pub mod real;
pub mod synthetic;
pub mod table;

pub use normalize::Normalizer;
pub use synthetic::{NoiseScale, SyntheticSystem};

/// A train/test split of one input/output series in original units.
#[derive(Clone, Debug, PartialEq)]
pub struct Benchmark {
    /// Name (e.g. "synthetic 4", "dryer").
    pub name: String,
    /// Training part.
    pub train: crate::trajectory::Trajectory,
    /// Test part (for synthetic systems: noise-free outputs).
    pub test: crate::trajectory::Trajectory,
    /// `l_y` used by the paper.
    pub ly: usize,
    /// `l_u` used by the paper.
    pub lu: usize,
}
