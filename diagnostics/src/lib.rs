//! The diagnostics behind docs/design.md and BENCHMARKS.md, one binary each (`src/bin/`).
