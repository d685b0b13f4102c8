//! What `msgp` shows: text and JSON lines on stdout ([`output`], [`report`]), markdown results
//! files (`msgp_reproduce::results`), PNG plots of simulations ([`plot`]; cost curves: `msgp_sim::plot`)
//! and progress bars on stderr ([`progress`]).

pub mod output;
pub mod plot;
pub mod prediction;
pub mod progress;
pub mod report;
