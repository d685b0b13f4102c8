//! msgp-sim
