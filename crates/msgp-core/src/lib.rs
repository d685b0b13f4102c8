//! msgp-core: placeholder until the first slice lands.
