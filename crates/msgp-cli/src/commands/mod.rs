//! One module per `msgp` command: each takes its parsed options ([`crate::args`]), calls the
//! libraries and hands the results to [`crate::render`].

pub mod demo;
pub mod eval;
pub mod figure4;
pub mod fit;
pub mod generalisation;
pub mod learn;
pub mod sim;
pub mod table1;

use crate::args::DataArgs;
use msgp_core::data::dataset::Selection;

impl DataArgs {
    /// The columns or signals these options select.
    pub fn selection(&self) -> Selection<'_> {
        Selection {
            inputs: &self.input,
            outputs: &self.output,
            topic: self.topic.as_deref(),
        }
    }
}
