//! Atomic file replacement: write to a temporary sibling, then rename.

use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::error::SimError;

/// Calls `fill` with a buffered writer on a fresh temporary file in `path`'s directory and,
/// if it succeeds, flushes, syncs and renames the file to `path`. On any failure the
/// temporary file is removed and `path` is left untouched, so no half-written file remains.
pub fn write_atomically<F>(path: &Path, fill: F) -> Result<(), SimError>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<(), SimError>,
{
    let io_err = |action: &'static str, p: &Path| {
        let p = p.to_owned();
        move |source| SimError::Io {
            action,
            path: p,
            source,
        }
    };
    let tmp = temp_path(path)?;
    let file = OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .map_err(io_err("cannot create temporary file", &tmp))?;
    let mut writer = BufWriter::new(file);
    let result = fill(&mut writer)
        .and_then(|()| writer.flush().map_err(io_err("cannot write", &tmp)))
        .and_then(|()| {
            writer
                .get_ref()
                .sync_all()
                .map_err(io_err("cannot sync", &tmp))
        });
    drop(writer);
    let result =
        result.and_then(|()| std::fs::rename(&tmp, path).map_err(io_err("cannot rename to", path)));
    if result.is_err() {
        // Best effort: the original error is what matters.
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// `dir/.name.tmp-<pid>-<n>` next to `path`.
fn temp_path(path: &Path) -> Result<PathBuf, SimError> {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = path.file_name().ok_or_else(|| SimError::Io {
        action: "cannot write",
        path: path.to_owned(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidInput, "path has no file name"),
    })?;
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp_name = format!(".{}.tmp-{}-{n}", name.to_string_lossy(), std::process::id());
    Ok(path.with_file_name(tmp_name))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch_dir(tag: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("msgp-sim-atomic-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("create scratch dir");
        dir
    }

    #[test]
    fn failed_write_leaves_nothing_behind() {
        let dir = scratch_dir("fail");
        let target = dir.join("run.csv");
        std::fs::write(&target, b"old").expect("seed file");
        let result = write_atomically(&target, |w| {
            w.write_all(b"partial").expect("buffered write");
            Err(SimError::invalid("test", 0.0, "forced failure"))
        });
        assert!(result.is_err());
        assert_eq!(std::fs::read(&target).expect("read"), b"old");
        let entries: Vec<_> = std::fs::read_dir(&dir).expect("list").collect();
        assert_eq!(entries.len(), 1, "temporary file left behind");
        write_atomically(&target, |w| {
            w.write_all(b"new").map_err(|source| SimError::Io {
                action: "cannot write",
                path: target.clone(),
                source,
            })
        })
        .expect("write succeeds");
        assert_eq!(std::fs::read(&target).expect("read"), b"new");
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }
}
