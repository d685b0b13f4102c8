//! # msgp-reproduce — the paper's results, reproduced
//!
//! The reproductions as libraries, so that the command line (`msgp reproduce …`) and the Python
//! sweeps (`msgp.sweep`, on local processes or Ray) compute them with the same code and write
//! the same markdown. Each splits into a validated plan, independent units (one seeded fit or
//! learning run each: the same numbers on any machine and thread count) and a report.
//!
//! * [`table1`] — the paper's Table 1: free-simulation test RMSE of every column on the ten
//!   benchmarks, beside the paper's six columns.
//! * [`figure4`] — the paper's Figure 4: PILCO on the simulated pendulum with the four loop
//!   models over seeds.
//! * [`plant_task`] — the loop's named plant tasks (`Pendulum-v1`, the arm swing-up) per model.
//! * [`results`] — the sections of a results file each reproduction owns, and their provenance.
//! * [`plot`] — the plots over seeds.
//!
//! `msgp-core` is the numerics and `msgp-sim` the simulator; neither writes markdown.

pub mod error;
pub mod figure4;
pub mod plant_task;
pub mod plot;
pub mod results;
pub mod table1;

pub use error::{ReproduceError, Result};
