//! What `msgp` shows: text and JSON lines on stdout ([`output`], [`report`]), markdown results
//! files (`msgp_core::reproduce::results`), PNG plots of simulations and cost curves ([`plot`], [`cost_plot`])
//! and progress bars on stderr ([`progress`]).

pub mod cost_plot;
pub mod output;
pub mod plot;
pub mod prediction;
pub mod progress;
pub mod report;
