//! The autoregressive (NARX) state: the window of the last `l_y` outputs and `l_u` inputs that
//! the GP maps to the next output ([`spec`]), and how a rollout of a measured trajectory starts
//! that window ([`start_window`]).

pub mod spec;
pub mod start_window;

pub use spec::NarxSpec;
pub use start_window::StartWindow;
