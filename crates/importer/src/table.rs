//! Numeric CSV tables as the tools read them (measured runs, input signals): `# key=value`
//! metadata lines before one header row, then numbers; the first selected column is time and
//! must increase strictly. Every error names the file, the line and, for a cell, the column.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// `file:line:column (column "name"): message`; line and column 1-based, absent when the problem
/// is a whole line or the whole file.
#[derive(Debug, Clone, PartialEq)]
pub struct DataError {
    pub file: PathBuf,
    pub line: Option<usize>,
    pub column: Option<(usize, String)>,
    pub message: String,
}

impl std::fmt::Display for DataError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
        }
        if let Some((c, name)) = &self.column {
            write!(f, ":{c} (column {name:?})")?;
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for DataError {}

impl DataError {
    pub fn file(file: &Path, message: String) -> DataError {
        DataError { file: file.to_path_buf(), line: None, column: None, message }
    }

    pub fn line(file: &Path, line: usize, message: String) -> DataError {
        DataError { file: file.to_path_buf(), line: Some(line), column: None, message }
    }
}

/// Which columns to read; the first one is time.
pub enum Columns<'a> {
    /// Every column of the header.
    All,
    /// These, by name; `true` marks a required column. Other columns are ignored, even text.
    Named(&'a [(&'a str, bool)]),
}

pub struct Table {
    pub meta: BTreeMap<String, String>,
    /// Header names (unquoted).
    pub names: Vec<String>,
    pub header_line: usize,
    pub last_line: usize,
    /// The file's line (1-based) of each data row, so a later check can name the line of a sample.
    pub row_lines: Vec<usize>,
    /// The header position (0-based) of each selected column, `None` where the file lacks it.
    pub positions: Vec<Option<usize>>,
    /// One entry per selected column (per header column for `Columns::All`); `None` for an
    /// optional column the file does not have.
    pub columns: Vec<Option<Vec<f64>>>,
}

/// Parses `text` (`path` only names it in errors).
pub fn parse(path: &Path, text: &str, select: Columns) -> Result<Table, DataError> {
    let mut meta = BTreeMap::new();
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim_end_matches('\r')));
    let (header_line, header) = loop {
        match lines.next() {
            None => return Err(DataError::file(path, "empty file: no header row".into())),
            Some((_, l)) if l.trim().is_empty() => continue,
            Some((n, l)) if l.trim_start().starts_with('#') => {
                let body = l.trim_start().trim_start_matches('#').trim();
                if let Some((k, v)) = body.split_once('=') {
                    meta.insert(k.trim().to_string(), v.trim().to_string());
                } else if !body.is_empty() {
                    // a comment without key=value is kept as a note
                    meta.insert(format!("note_line_{n}"), body.to_string());
                }
            }
            Some((n, l)) => break (n, l),
        }
    };
    let names: Vec<String> = header.split(',').map(|s| s.trim().trim_matches('"').to_string()).collect();
    let selected: Vec<Option<usize>> = match select {
        Columns::All => (0..names.len()).map(Some).collect(),
        Columns::Named(wanted) => {
            let mut idx = Vec::with_capacity(wanted.len());
            for (name, required) in wanted {
                let i = names.iter().position(|c| c == name);
                if i.is_none() && *required {
                    return Err(DataError::line(
                        path,
                        header_line,
                        format!("missing required column {name:?} (header has: {})", names.join(", ")),
                    ));
                }
                idx.push(i);
            }
            idx
        }
    };
    let mut columns: Vec<Option<Vec<f64>>> = selected.iter().map(|i| i.map(|_| Vec::new())).collect();
    let mut last_line = header_line;
    let mut row_lines = Vec::new();
    for (n, l) in lines {
        if l.trim().is_empty() {
            continue;
        }
        if l.trim_start().starts_with('#') {
            return Err(DataError::line(path, n, "a '#' line after the header (metadata goes before it)".into()));
        }
        last_line = n;
        row_lines.push(n);
        let cells: Vec<&str> = l.split(',').collect();
        for (slot, c) in selected.iter().enumerate() {
            let Some(c) = *c else { continue };
            let col_err = |message: String| DataError {
                file: path.to_path_buf(),
                line: Some(n),
                column: Some((c + 1, names[c].clone())),
                message,
            };
            let cell = match cells.get(c) {
                None => {
                    return Err(col_err(format!(
                        "missing cell (the row has {} of {} columns)",
                        cells.len(),
                        names.len()
                    )))
                }
                Some(s) => s.trim(),
            };
            if cell.is_empty() {
                return Err(col_err("empty cell".into()));
            }
            let v: f64 = cell.parse().map_err(|_| col_err(format!("{cell:?} is not a number")))?;
            if !v.is_finite() {
                return Err(col_err(format!("{cell} is not a finite number")));
            }
            let column = columns[slot].as_mut().expect("present for a selected column");
            if slot == 0 {
                if let Some(&prev) = column.last() {
                    if v <= prev {
                        return Err(col_err(format!(
                            "time {cell} s does not increase (previous sample {} s)",
                            compact(prev)
                        )));
                    }
                }
            }
            column.push(v);
        }
    }
    Ok(Table { meta, names, header_line, last_line, row_lines, positions: selected, columns })
}

/// A number as a message shows it: Rust's `{}` never uses an exponent, so 1e300 would print 301
/// digits; beyond 1e15 or below 1e-4 (and not 0) it is written with one.
pub fn compact(x: f64) -> String {
    if x != 0.0 && !(1e-4..1e15).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn huge_and_tiny_numbers_print_with_an_exponent() {
        assert_eq!(super::compact(1e300), "1e300");
        assert_eq!(super::compact(-2.5e-7), "-2.5e-7");
        assert_eq!(super::compact(0.001), "0.001");
        assert_eq!(super::compact(12.5), "12.5");
        assert_eq!(super::compact(0.0), "0");
    }
}
