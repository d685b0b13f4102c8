//! Numeric tables with named columns: CSV files with a header (and, through `data::mcap`
//! with the `mcap` feature, aligned MCAP signals). Every error names the file and, for a
//! cell, its line and column.
//!
//! Rules of the CSV reader:
//! - the first line is the header; names are trimmed, must be non-empty and unique, and not
//!   all numbers (a file without a header line is refused rather than read with its first
//!   sample as names);
//! - every data cell must parse as a finite `f64` (`NaN`, `inf` and empty cells are errors);
//! - every line has as many fields as the header;
//! - blank lines are skipped; a file without data lines is an error;
//! - an optional column named [`EPISODE_COLUMN`] splits the rows into trajectories: each
//!   contiguous run of rows with the same value is one trajectory.

use std::ops::Range;
use std::path::{Path, PathBuf};

use nalgebra::DMatrix;

use crate::data::Trajectory;
use crate::error::{MsgpError, Result};

/// Name of the column whose value changes mark the start of a new trajectory.
pub const EPISODE_COLUMN: &str = "episode";

/// Relative deviation of a time step from its trajectory's median above which the data
/// loader warns ([`Table::irregular_steps`]): far above clock jitter, well below a dropped sample.
pub const IRREGULAR_STEP_TOLERANCE: f64 = 0.25;

/// Names accepted for a time column (matched case-insensitively), in order of preference.
pub const TIME_COLUMNS: [&str; 2] = ["t", "time"];

/// Where the time column of a table read from an MCAP log comes from (`data::mcap`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TimeSource {
    /// The MCAP log time (when the recorder received it).
    #[default]
    Log,
    /// The message's own `header.stamp` (`sec` + `nanosec`), as ROS messages carry it.
    Header,
}

/// A numeric table: column names and row-major values.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// Where it came from (for messages).
    pub path: PathBuf,
    /// Header names.
    pub columns: Vec<String>,
    /// Rows of values, one `Vec` per data line.
    pub rows: Vec<Vec<f64>>,
    /// For each row, the 1-based line of the file it came from (for messages; for non-text
    /// sources such as MCAP the 1-based row number).
    pub lines: Vec<u64>,
}

fn file_err(path: &Path, message: String) -> MsgpError {
    MsgpError::File {
        path: path.to_path_buf(),
        message,
    }
}

fn at(path: &Path, line: u64, column: usize, message: String) -> MsgpError {
    MsgpError::FileAt {
        path: path.to_path_buf(),
        line,
        column,
        message,
    }
}

impl Table {
    /// Reads a CSV file with a header line; every cell must be a finite number.
    pub fn read_csv(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| file_err(path, format!("cannot read: {e}")))?;
        Self::parse_csv(&bytes, path)
    }

    /// Parses CSV bytes; `path` is only used in messages.
    pub fn parse_csv(bytes: &[u8], path: &Path) -> Result<Self> {
        if bytes.iter().all(u8::is_ascii_whitespace) {
            return Err(file_err(path, "empty file: no header line".into()));
        }
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(true)
            .trim(csv::Trim::All)
            .from_reader(bytes);
        let header = reader
            .headers()
            .map_err(|e| csv_err(path, &e, "header", &mut LineCounter::new(bytes)))?;
        let columns: Vec<String> = header.iter().map(str::to_string).collect();
        if columns.iter().all(|name| name.parse::<f64>().is_ok()) {
            return Err(at(
                path,
                1,
                1,
                format!(
                    "the first line `{}` is all numbers, not a header: the file needs a first \
                     line naming its columns (e.g. `t,u,y`); otherwise its first sample would \
                     be read as column names",
                    columns.join(",")
                ),
            ));
        }
        for (j, name) in columns.iter().enumerate() {
            if name.is_empty() {
                return Err(at(path, 1, j + 1, "empty column name in the header".into()));
            }
            if let Some(k) = columns[..j].iter().position(|c| c == name) {
                return Err(at(
                    path,
                    1,
                    j + 1,
                    format!("duplicate column name `{name}` (also column {})", k + 1),
                ));
            }
        }
        let mut rows = Vec::new();
        let mut lines = Vec::new();
        // the csv crate's line counter skips blank lines; count newlines before each record
        let mut counter = LineCounter::new(bytes);
        for rec in reader.records() {
            let rec = rec.map_err(|e| csv_err(path, &e, "data", &mut counter))?;
            let line = rec.position().map_or(0, |p| counter.line_at(p.byte()));
            if rec.len() == 1 && rec.get(0).is_some_and(str::is_empty) && columns.len() > 1 {
                continue; // a blank line
            }
            let mut row = Vec::with_capacity(columns.len());
            for (j, cell) in rec.iter().enumerate() {
                let name = columns.get(j).map_or("?", String::as_str);
                if cell.is_empty() {
                    return Err(at(
                        path,
                        line,
                        j + 1,
                        format!("empty cell in column `{name}`"),
                    ));
                }
                let v: f64 = cell.parse().map_err(|_| {
                    at(
                        path,
                        line,
                        j + 1,
                        format!("`{cell}` in column `{name}` is not a number"),
                    )
                })?;
                if !v.is_finite() {
                    return Err(at(
                        path,
                        line,
                        j + 1,
                        format!("non-finite value `{cell}` in column `{name}`"),
                    ));
                }
                row.push(v);
            }
            rows.push(row);
            lines.push(line);
        }
        if rows.is_empty() {
            return Err(file_err(path, "no data rows after the header".into()));
        }
        Ok(Self {
            path: path.to_path_buf(),
            columns,
            rows,
            lines,
        })
    }

    /// Number of data rows.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True when there are no rows.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Index of the named column.
    pub fn column_index(&self, name: &str) -> Result<usize> {
        self.columns.iter().position(|c| c == name).ok_or_else(|| {
            file_err(
                &self.path,
                format!("no column `{name}` (columns: {})", self.columns.join(", ")),
            )
        })
    }

    /// Values of the named column.
    pub fn column(&self, name: &str) -> Result<Vec<f64>> {
        let j = self.column_index(name)?;
        Ok(self.rows.iter().map(|r| r[j]).collect())
    }

    /// Index of the time column (`t` or `time`, any case), if there is one.
    pub fn time_column(&self) -> Option<usize> {
        TIME_COLUMNS.iter().find_map(|want| {
            self.columns
                .iter()
                .position(|c| c.eq_ignore_ascii_case(want))
        })
    }

    /// Checks that the time column, if there is one, increases strictly within every
    /// trajectory ([`Table::episodes`]): a time that repeats or goes back is an error naming
    /// its line (data fitted as if ordered would be silently wrong).
    pub fn check_time_order(&self) -> Result<()> {
        let Some(j) = self.time_column() else {
            return Ok(());
        };
        for range in self.episodes() {
            for i in range.start + 1..range.end {
                let (before, now) = (self.rows[i - 1][j], self.rows[i][j]);
                if now <= before {
                    return Err(at(
                        &self.path,
                        self.lines[i],
                        j + 1,
                        format!(
                            "time `{}` = {now} does not increase (the sample before, line {}, \
                             is at {before}); times must increase strictly within a trajectory \
                             (an `{EPISODE_COLUMN}` column separates trajectories; the command \
                             line's --sort-time sorts rows written out of order)",
                            self.columns[j],
                            self.lines[i - 1]
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Sorts every trajectory's rows by the time column (stable: rows with equal times keep
    /// their order, and [`Table::check_time_order`] still refuses them); the rows keep their
    /// file lines, so later errors still point into the file. A note saying how many rows
    /// moved, or `None` when none did or there is no time column.
    pub fn sort_by_time(&mut self) -> Option<String> {
        let j = self.time_column()?;
        let mut moved = 0usize;
        for range in self.episodes() {
            let mut order: Vec<usize> = range.clone().collect();
            order.sort_by(|&a, &b| self.rows[a][j].total_cmp(&self.rows[b][j]));
            moved += order
                .iter()
                .zip(range.clone())
                .filter(|(from, to)| *from != to)
                .count();
            let rows: Vec<Vec<f64>> = order.iter().map(|&i| self.rows[i].clone()).collect();
            let lines: Vec<u64> = order.iter().map(|&i| self.lines[i]).collect();
            self.rows.splice(range.clone(), rows);
            self.lines.splice(range, lines);
        }
        (moved > 0).then(|| {
            format!(
                "{}: sorted the rows by `{}` within each trajectory: {moved} of {} rows moved",
                self.path.display(),
                self.columns[j],
                self.rows.len()
            )
        })
    }

    /// A warning when the time column's steps are not (nearly) equal within a trajectory: some
    /// step differs from the median step of its trajectory by more than `tolerance` (relative).
    /// The models assume equally spaced samples; a dropped sample or an irregular log breaks
    /// that silently. Says how many steps are off and where the worst one is.
    pub fn irregular_steps(&self, tolerance: f64) -> Option<String> {
        let j = self.time_column()?;
        let (mut off, mut total) = (0usize, 0usize);
        let mut worst: Option<(f64, usize, f64, f64)> = None; // (deviation, row, step, median)
        for range in self.episodes() {
            let mut steps: Vec<f64> = (range.start + 1..range.end)
                .map(|i| self.rows[i][j] - self.rows[i - 1][j])
                .collect();
            if steps.is_empty() {
                continue;
            }
            let raw = steps.clone();
            steps.sort_by(f64::total_cmp);
            let median = steps[steps.len() / 2];
            if median <= 0.0 {
                continue;
            }
            total += raw.len();
            for (k, step) in raw.into_iter().enumerate() {
                let deviation = (step - median).abs() / median;
                if deviation > tolerance {
                    off += 1;
                    if worst.is_none_or(|w| deviation > w.0) {
                        worst = Some((deviation, range.start + 1 + k, step, median));
                    }
                }
            }
        }
        let (deviation, row, step, median) = worst?;
        let short = |x: f64| {
            let t = format!("{x:.6}");
            t.trim_end_matches('0').trim_end_matches('.').to_string()
        };
        let (step, median) = (short(step), short(median));
        Some(format!(
            "{}: the time step of `{}` is irregular: {off} of {total} steps differ from their \
             trajectory's median step ({median}) by more than {:.0} %, the most at line {} \
             (a step of {step}, {:.0} % off); the models assume equally spaced samples",
            self.path.display(),
            self.columns[j],
            100.0 * tolerance,
            self.lines[row],
            100.0 * deviation
        ))
    }

    /// Row ranges of the trajectories: one per contiguous run of equal values in the
    /// [`EPISODE_COLUMN`], or the whole table when there is no such column.
    pub fn episodes(&self) -> Vec<Range<usize>> {
        let Some(e) = self.columns.iter().position(|c| c == EPISODE_COLUMN) else {
            let whole: Range<usize> = 0..self.rows.len();
            return std::iter::once(whole).collect();
        };
        let mut out = Vec::new();
        let mut start = 0;
        for i in 1..self.rows.len() {
            if self.rows[i][e] != self.rows[i - 1][e] {
                out.push(start..i);
                start = i;
            }
        }
        out.push(start..self.rows.len());
        out
    }

    /// The episode value of each trajectory of [`episodes`](Self::episodes) (`None` without an
    /// episode column).
    pub fn episode_ids(&self) -> Option<Vec<f64>> {
        let e = self.columns.iter().position(|c| c == EPISODE_COLUMN)?;
        Some(
            self.episodes()
                .iter()
                .map(|r| self.rows[r.start][e])
                .collect(),
        )
    }

    /// One trajectory per episode with the named input and output columns.
    pub fn trajectories(&self, inputs: &[&str], outputs: &[&str]) -> Result<Vec<Trajectory>> {
        if outputs.is_empty() {
            return Err(file_err(&self.path, "no output column selected".into()));
        }
        let ui: Vec<usize> = inputs
            .iter()
            .map(|n| self.column_index(n))
            .collect::<Result<_>>()?;
        let yi: Vec<usize> = outputs
            .iter()
            .map(|n| self.column_index(n))
            .collect::<Result<_>>()?;
        let mut out = Vec::new();
        for r in self.episodes() {
            let n = r.len();
            let rows = &self.rows[r];
            let u = DMatrix::from_fn(n, ui.len(), |i, j| rows[i][ui[j]]);
            let y = DMatrix::from_fn(n, yi.len(), |i, j| rows[i][yi[j]]);
            out.push(Trajectory::new(u, y).map_err(|e| file_err(&self.path, e.to_string()))?);
        }
        Ok(out)
    }

    /// Time stamps of the rows in `range`: the time column when there is one, otherwise the
    /// row index within the range.
    pub fn times(&self, range: Range<usize>) -> Vec<f64> {
        match self.time_column() {
            Some(j) => self.rows[range].iter().map(|r| r[j]).collect(),
            None => (0..range.len()).map(|i| i as f64).collect(),
        }
    }
}

/// 1-based line numbers of byte offsets, for offsets that never decrease.
struct LineCounter<'a> {
    bytes: &'a [u8],
    offset: usize,
    line: u64,
}

impl<'a> LineCounter<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Self {
            bytes,
            offset: 0,
            line: 1,
        }
    }

    /// Line of the first non-newline byte at or after `offset` (offsets before the last one
    /// asked give the last line).
    fn line_at(&mut self, offset: u64) -> u64 {
        let mut end = usize::try_from(offset)
            .unwrap_or(usize::MAX)
            .min(self.bytes.len());
        // a record's position may point at the blank lines before it
        while end < self.bytes.len() && matches!(self.bytes[end], b'\n' | b'\r') {
            end += 1;
        }
        if end > self.offset {
            let newlines = self.bytes[self.offset..end]
                .iter()
                .filter(|&&b| b == b'\n')
                .count();
            self.line += newlines as u64;
            self.offset = end;
        }
        self.line
    }
}

/// A csv-crate error as a message with the line (and field) it happened at.
fn csv_err(path: &Path, e: &csv::Error, what: &str, lines: &mut LineCounter<'_>) -> MsgpError {
    let line = e.position().map_or(0, |p| lines.line_at(p.byte()));
    match e.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => at(
            path,
            line,
            (*len as usize).min(*expected_len as usize) + 1,
            format!("{what} line has {len} fields, the header has {expected_len}"),
        ),
        csv::ErrorKind::Utf8 { err, .. } => at(
            path,
            line,
            err.field() + 1,
            format!("{what} line is not valid UTF-8"),
        ),
        csv::ErrorKind::Io(io) => file_err(path, format!("cannot read: {io}")),
        _ => file_err(path, format!("line {line}: {e}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Table> {
        Table::parse_csv(text.as_bytes(), Path::new("x.csv"))
    }

    fn message(text: &str) -> String {
        match parse(text) {
            Ok(_) => panic!("expected an error for {text:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn reads_columns_time_and_episodes() {
        let t = parse("t,u,y,episode\n0,1,2,0\n1,3,4,0\n\n2,5,6,1\n").expect("valid");
        assert_eq!(t.column("u").expect("u"), vec![1.0, 3.0, 5.0]);
        assert_eq!(t.time_column(), Some(0));
        assert_eq!(t.lines, vec![2, 3, 5]);
        assert_eq!(t.episodes(), vec![0..2, 2..3]);
        assert_eq!(t.episode_ids(), Some(vec![0.0, 1.0]));
        let trajs = t.trajectories(&["u"], &["y"]).expect("trajectories");
        assert_eq!(trajs.len(), 2);
        assert_eq!(trajs[1].y[(0, 0)], 6.0);
        assert_eq!(t.times(2..3), vec![2.0]);
    }

    #[test]
    fn errors_name_file_line_and_column() {
        assert_eq!(
            message("t,u,y\n0,1,2\n1,x,3\n"),
            "x.csv:3:2: `x` in column `u` is not a number"
        );
        assert_eq!(
            message("t,u,y\n0,NaN,2\n"),
            "x.csv:2:2: non-finite value `NaN` in column `u`"
        );
        assert!(message("t,u,y\n0,inf,2\n").contains("non-finite"));
        assert!(message("t,u,y\n0,,2\n").contains("x.csv:2:2: empty cell"));
        assert!(message("t,u,y\n0,1\n").contains("x.csv:2:"));
        assert!(message("").contains("empty file"));
        assert!(message("  \n").contains("empty file"));
        assert!(message("t,u,y\n").contains("no data rows"));
        assert!(message("t,u,u\n1,2,3\n").contains("duplicate column name `u`"));
        assert!(message("t,,y\n1,2,3\n").contains("empty column name"));
        assert_eq!(
            message("0,6.41,4.7660989\n0.08,6.2,4.8\n"),
            "x.csv:1:1: the first line `0,6.41,4.7660989` is all numbers, not a header: the \
             file needs a first line naming its columns (e.g. `t,u,y`); otherwise its first \
             sample would be read as column names"
        );
        assert!(
            parse("t,1,y\n0,1,2\n").is_ok(),
            "a name that is a number among names"
        );
        let t = parse("t,u\n0,1\n").expect("valid");
        let e = t.column("y").expect_err("missing").to_string();
        assert!(e.contains("no column `y` (columns: t, u)"), "{e}");
    }

    /// The time column must increase strictly within a trajectory: a step back or a repeat is
    /// an error at its line; a new episode may start over; no time column, no check.
    #[test]
    fn the_time_column_must_increase_within_a_trajectory() {
        let check = |csv: &str| parse(csv).expect("parses").check_time_order();
        let back = check("t,u,y\n0,1,2\n2,1,2\n1,1,2\n3,1,2\n")
            .expect_err("goes back")
            .to_string();
        assert!(
            back.starts_with("x.csv:4:1: time `t` = 1 does not increase"),
            "{back}"
        );
        assert!(back.contains("line 3, is at 2"), "{back}");
        let repeat = check("time,u,y\n0,1,2\n0.5,1,2\n0.5,1,2\n")
            .expect_err("repeats")
            .to_string();
        assert!(
            repeat.starts_with("x.csv:4:1: time `time` = 0.5"),
            "{repeat}"
        );
        check("t,u,y,episode\n0,1,2,0\n1,1,2,0\n0,1,2,1\n1,1,2,1\n").expect("per episode");
        check("u,y\n1,2\n1,2\n").expect("no time column");
        let in_episode = check("t,u,y,episode\n0,1,2,0\n1,1,2,0\n0,1,2,1\n0,1,2,1\n")
            .expect_err("repeat inside episode 1")
            .to_string();
        assert!(in_episode.starts_with("x.csv:5:1:"), "{in_episode}");
    }

    /// Sorting by time orders each trajectory on its own, keeps the file lines of the rows
    /// (a repeat found afterwards names the lines it has in the file) and says how many moved.
    #[test]
    fn rows_sort_by_time_within_each_trajectory() {
        let mut t = parse("t,u,y,episode\n0,1,10,0\n2,3,12,0\n1,2,11,0\n1,5,15,1\n0,4,14,1\n")
            .expect("parses");
        let note = t.sort_by_time().expect("rows moved");
        assert_eq!(
            note,
            "x.csv: sorted the rows by `t` within each trajectory: 4 of 5 rows moved"
        );
        assert_eq!(t.column("y").expect("y"), [10.0, 11.0, 12.0, 14.0, 15.0]);
        t.check_time_order().expect("ordered now");
        assert_eq!(t.sort_by_time(), None, "nothing moves the second time");
        let mut repeat = parse("t,u,y\n1,1,2\n0,1,2\n1,1,3\n").expect("parses");
        repeat.sort_by_time().expect("moved");
        let e = repeat.check_time_order().expect_err("repeat").to_string();
        assert!(e.starts_with("x.csv:4:1: time `t` = 1"), "{e}");
        assert!(e.contains("line 2, is at 1"), "{e}");
        let mut untimed = parse("u,y\n2,1\n1,2\n").expect("parses");
        assert_eq!(untimed.sort_by_time(), None);
    }

    #[test]
    fn an_irregular_time_step_is_a_warning_naming_the_line() {
        let steps = |csv: &str| parse(csv).expect("parses").irregular_steps(0.25);
        // 1 % jitter is not irregular; a dropped sample (a double step) is, at its line
        let even = "t,u\n0,1\n1.01,1\n2,1\n3.01,1\n4,1\n";
        assert_eq!(steps(even), None);
        let gap = steps("t,u\n0,1\n1,1\n2,1\n4,1\n5,1\n").expect("gap");
        assert!(
            gap.starts_with("x.csv: the time step of `t` is irregular: 1 of 4 steps"),
            "{gap}"
        );
        assert!(
            gap.contains("median step (1)") && gap.contains("line 5 (a step of 2, 100 % off)"),
            "{gap}"
        );
        // the median is per trajectory: two episodes at different rates are regular
        let two = "t,u,episode\n0,1,0\n1,1,0\n2,1,0\n0,1,1\n0.5,1,1\n1,1,1\n";
        assert_eq!(steps(two), None);
        assert_eq!(steps("u,y\n1,2\n3,4\n"), None, "no time column");
    }
}
