//! Results files: `RESULTS.md` holds several reproductions; each command owns one section between
//! `<!-- msgp:NAME:begin -->` and `<!-- msgp:NAME:end -->` and replaces only that.

use std::path::Path;

use msgp_core::MsgpError;
use msgp_core::model_file::write_atomically;

use crate::error::Result;

fn markers(name: &str) -> (String, String) {
    (
        format!("<!-- msgp:{name}:begin -->"),
        format!("<!-- msgp:{name}:end -->"),
    )
}

/// `text` with section `name` set to `body` (appended when absent).
pub fn with_section(text: &str, name: &str, body: &str) -> String {
    let (begin, end) = markers(name);
    let block = format!("{begin}\n{}\n{end}", body.trim_end());
    if let Some(b) = text.find(&begin)
        && let Some(e) = text[b..].find(&end)
    {
        let after = b + e + end.len();
        return format!("{}{block}{}", &text[..b], &text[after..]);
    }
    if text.trim().is_empty() {
        format!("{block}\n")
    } else {
        format!("{}\n\n{block}\n", text.trim_end())
    }
}

/// Replaces section `name` of the markdown file at `path` (created when missing), atomically.
pub fn update_section(path: &Path, name: &str, body: &str) -> Result<()> {
    let old = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
        Err(e) => {
            return Err(MsgpError::File {
                path: path.to_path_buf(),
                message: format!("cannot read: {e}"),
            }
            .into());
        }
    };
    Ok(write_atomically(
        path,
        with_section(&old, name, body).as_bytes(),
    )?)
}

/// "2 CPUs (AMD EPYC …)" from the OS, best effort.
pub fn machine() -> String {
    let cpus = std::thread::available_parallelism().map_or(0, |n| n.get());
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".to_string());
    format!("{cpus} CPUs ({model})")
}

/// Today's date `YYYY-MM-DD` (UTC) from the system clock.
pub fn today() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (y, m, d) = civil_from_days((secs / 86_400) as i64);
    format!("{y:04}-{m:02}-{d:02}")
}

/// Days since 1970-01-01 → (year, month, day), proleptic Gregorian (H. Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (if m <= 2 { y + 1 } else { y }, m, d)
}

/// Where the markdown says the numbers came from.
#[derive(Clone, Debug)]
pub struct Provenance {
    /// The command that produced them, as a user would type it (markdown: in code spans).
    pub command: String,
    /// Total wall time \[s\].
    pub seconds: f64,
    /// Where it ran (`2 CPUs (…)`, or a Ray cluster).
    pub machine: String,
    /// Date (UTC), `YYYY-MM-DD`.
    pub date: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(19_723), (2024, 1, 1));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
    }

    #[test]
    fn sections_are_replaced_in_place_and_appended_when_new() {
        let a = with_section("", "one", "first\n");
        assert_eq!(a, "<!-- msgp:one:begin -->\nfirst\n<!-- msgp:one:end -->\n");
        let b = with_section(&a, "two", "second");
        assert!(b.contains("first") && b.contains("second"));
        let c = with_section(&b, "one", "FIRST");
        assert!(!c.contains("first") && c.contains("FIRST") && c.contains("second"));
        assert!(c.find("FIRST") < c.find("second"), "order kept");
        assert_eq!(with_section(&c, "one", "FIRST"), c, "idempotent");
    }
}
