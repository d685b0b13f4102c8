//! Writing to stdout without panicking when the reader goes away (`msgp … | head`).
//!
//! `println!` panics on a closed pipe because Rust ignores SIGPIPE. Commands print through
//! [`out`] instead: a closed pipe ends the output quietly, any other write error is returned.

use std::io::Write;

/// Writes `text` and a newline to stdout; a closed pipe (`EPIPE`) is not an error.
pub fn out(text: &str) -> anyhow::Result<()> {
    let mut stdout = std::io::stdout().lock();
    let result = stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.write_all(b"\n"))
        .and_then(|()| stdout.flush());
    match result {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        Err(e) => Err(anyhow::Error::new(e).context("cannot write to stdout")),
        Ok(()) => Ok(()),
    }
}

/// Writes one JSON value as a single line.
pub fn out_json(value: &serde_json::Value) -> anyhow::Result<()> {
    out(&value.to_string())
}
