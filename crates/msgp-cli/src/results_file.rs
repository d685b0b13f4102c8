//! `RESULTS.md` holds several reproductions; each command owns one section between
//! `<!-- msgp:NAME:begin -->` and `<!-- msgp:NAME:end -->` and replaces only that.

use std::path::Path;

use anyhow::Context;
use msgp_core::model_file::write_atomically;

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
pub fn update_section(path: &Path, name: &str, body: &str) -> anyhow::Result<()> {
    let old = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
        Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
    };
    write_atomically(path, with_section(&old, name, body).as_bytes())
        .with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

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
