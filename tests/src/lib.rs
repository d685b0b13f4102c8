//! Cross-crate tests (in `tests/`): the simulator's logs read back by the core's dataset loader
//! and modelled by its fits, the path a user takes with `msgp sim` and `msgp fit`, without the
//! command line in between.
