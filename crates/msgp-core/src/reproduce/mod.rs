//! Reproductions of the paper's results as libraries, so that the command line (`msgp
//! reproduce …`) and the Python sweeps (`msgp.sweep`, on local processes or Ray) compute them
//! with the same code and write the same markdown.

pub mod results;
pub mod table1;
