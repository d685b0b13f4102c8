//! Numeric CSV tables with a header; every error names the file, line and column.

use std::path::{Path, PathBuf};

use crate::error::{MsgpError, Result};

/// A numeric table: column names and row-major values.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// Where it came from (for messages).
    pub path: PathBuf,
    /// Header names.
    pub columns: Vec<String>,
    /// Rows of values, one `Vec` per data line.
    pub rows: Vec<Vec<f64>>,
}

fn file_err(path: &Path, message: String) -> MsgpError {
    MsgpError::File {
        path: path.to_path_buf(),
        message,
    }
}

impl Table {
    /// Reads a CSV file with a header line; every cell must be a finite number.
    pub fn read_csv(path: &Path) -> Result<Self> {
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(true)
            .trim(csv::Trim::All)
            .from_path(path)
            .map_err(|e| file_err(path, format!("cannot open: {e}")))?;
        let columns: Vec<String> = reader
            .headers()
            .map_err(|e| file_err(path, format!("cannot read the header: {e}")))?
            .iter()
            .map(str::to_string)
            .collect();
        if columns.is_empty() || columns.iter().all(String::is_empty) {
            return Err(file_err(path, "empty file: no header line".into()));
        }
        let mut rows = Vec::new();
        for rec in reader.records() {
            let rec = rec.map_err(|e| {
                let line = e.position().map_or(0, |p| p.line());
                file_err(path, format!("line {line}: {e}"))
            })?;
            let line = rec.position().map_or(0, |p| p.line());
            let mut row = Vec::with_capacity(columns.len());
            for (j, cell) in rec.iter().enumerate() {
                let name = columns.get(j).map_or("?", String::as_str);
                let v: f64 = cell.parse().map_err(|_| {
                    file_err(
                        path,
                        format!(
                            "line {line}, column {} (`{name}`): `{cell}` is not a number",
                            j + 1
                        ),
                    )
                })?;
                if !v.is_finite() {
                    return Err(file_err(
                        path,
                        format!(
                            "line {line}, column {} (`{name}`): non-finite value `{cell}`",
                            j + 1
                        ),
                    ));
                }
                row.push(v);
            }
            rows.push(row);
        }
        if rows.is_empty() {
            return Err(file_err(path, "no data rows after the header".into()));
        }
        Ok(Self {
            path: path.to_path_buf(),
            columns,
            rows,
        })
    }

    /// Values of the named column.
    pub fn column(&self, name: &str) -> Result<Vec<f64>> {
        let j = self.columns.iter().position(|c| c == name).ok_or_else(|| {
            file_err(
                &self.path,
                format!("no column `{name}` (columns: {})", self.columns.join(", ")),
            )
        })?;
        Ok(self.rows.iter().map(|r| r[j]).collect())
    }
}
