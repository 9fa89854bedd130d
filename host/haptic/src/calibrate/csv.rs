//! Bench CSV files: a header row naming the columns, then one record per line. Lines starting
//! with `#` are comments (data files cite their source there). Columns are picked by name;
//! every error names the file and, where there is one, the line and the column.

use std::path::Path;

/// A bench-file error.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CsvError {
    /// The file cannot be opened or is not valid CSV.
    #[error("{file}: {message}")]
    File {
        /// The file.
        file: String,
        /// What went wrong.
        message: String,
    },
    /// A column the command needs is not in the header.
    #[error("{file}:{line}: missing column {column:?} (the header has: {header})")]
    MissingColumn {
        /// The file.
        file: String,
        /// The header's line.
        line: u64,
        /// The missing name.
        column: String,
        /// The header, comma separated.
        header: String,
    },
    /// A bad value or record.
    #[error("{file}:{line}: {message}")]
    At {
        /// The file.
        file: String,
        /// 1-based line.
        line: u64,
        /// What is wrong, naming the column.
        message: String,
    },
    /// Not enough data rows.
    #[error("{file}: {got} data rows, need at least {need}{why}")]
    TooFew {
        /// The file.
        file: String,
        /// Rows found.
        got: usize,
        /// Rows needed.
        need: usize,
        /// Why that many (may be empty).
        why: String,
    },
}

/// The selected columns of a bench file, as text, with the line of each record.
#[derive(Debug, Clone)]
pub struct Table {
    /// The file, as named in errors.
    pub file: String,
    /// The selected column names, in the order asked for.
    pub columns: Vec<String>,
    /// 1-based line of each record.
    pub lines: Vec<u64>,
    cells: Vec<Vec<String>>,
}

/// Reads `path` and keeps the named columns (header names are matched after trimming).
pub fn read(path: &Path, columns: &[&str]) -> Result<Table, CsvError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| CsvError::File {
        file: file.clone(),
        message: format!("cannot read: {e}"),
    })?;
    parse(&file, &text, columns)
}

/// Parses CSV text; `file` names it in errors.
pub fn parse(file: &str, text: &str, columns: &[&str]) -> Result<Table, CsvError> {
    // Comment lines are blanked rather than left to the reader, whose line and byte counts
    // skip them; blank lines are skipped by the reader but counted.
    let blanked: String = text
        .split_inclusive('\n')
        .map(|l| {
            if l.trim_start().starts_with('#') {
                if l.ends_with('\n') { "\n" } else { "" }
            } else {
                l
            }
        })
        .collect();
    let text = blanked.as_str();
    let lines_of = LineIndex::new(text);
    let mut reader = ::csv::ReaderBuilder::new()
        .trim(::csv::Trim::All)
        .from_reader(text.as_bytes());
    let at = |line: u64, message: String| CsvError::At {
        file: file.to_string(),
        line,
        message,
    };
    let header = reader
        .headers()
        .map_err(|e| at(lines_of.error_line(&e), format!("bad header: {e}")))?
        .clone();
    let header_line = header.position().map_or(1, |p| lines_of.line_at(p.byte()));
    if header.is_empty() || header.iter().all(str::is_empty) {
        return Err(CsvError::File {
            file: file.to_string(),
            message: "empty file: expected a header row naming the columns".into(),
        });
    }
    let index: Vec<usize> = columns
        .iter()
        .map(|name| {
            header
                .iter()
                .position(|h| h == *name)
                .ok_or_else(|| CsvError::MissingColumn {
                    file: file.to_string(),
                    line: header_line,
                    column: (*name).to_string(),
                    header: header.iter().collect::<Vec<_>>().join(","),
                })
        })
        .collect::<Result<_, _>>()?;
    let mut lines = Vec::new();
    let mut cells = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| at(lines_of.error_line(&e), format!("bad record: {e}")))?;
        let line = record.position().map_or(0, |p| lines_of.line_at(p.byte()));
        cells.push(
            index
                .iter()
                .map(|&i| record.get(i).unwrap_or("").to_string())
                .collect(),
        );
        lines.push(line);
    }
    Ok(Table {
        file: file.to_string(),
        columns: columns.iter().map(|c| (*c).to_string()).collect(),
        lines,
        cells,
    })
}

/// Byte offsets of the line starts of a text, for line numbers in O(log n) per lookup (a
/// bench log may have millions of records).
struct LineIndex<'t> {
    text: &'t [u8],
    /// Offset of every `\n`, ascending.
    newlines: Vec<usize>,
}

impl<'t> LineIndex<'t> {
    fn new(text: &'t str) -> LineIndex<'t> {
        let text = text.as_bytes();
        let newlines = text
            .iter()
            .enumerate()
            .filter_map(|(i, &b)| (b == b'\n').then_some(i))
            .collect();
        LineIndex { text, newlines }
    }

    fn error_line(&self, e: &::csv::Error) -> u64 {
        e.position().map_or(1, |p| self.line_at(p.byte()))
    }

    /// 1-based line of the first non-blank byte at or after `offset` (the reader reports a
    /// record's position before the blank lines it skips).
    fn line_at(&self, offset: u64) -> u64 {
        let mut end = usize::try_from(offset)
            .unwrap_or(usize::MAX)
            .min(self.text.len());
        while end < self.text.len() && matches!(self.text[end], b'\n' | b'\r') {
            end += 1;
        }
        self.newlines.partition_point(|&n| n < end) as u64 + 1
    }
}

impl Table {
    /// Number of data rows.
    pub fn len(&self) -> usize {
        self.lines.len()
    }

    /// True when there are no data rows.
    pub fn is_empty(&self) -> bool {
        self.lines.is_empty()
    }

    /// The text of selected column `col`, one entry per row.
    pub fn text(&self, col: usize) -> impl Iterator<Item = &str> {
        self.cells
            .iter()
            .map(move |r| r.get(col).map_or("", String::as_str))
    }

    /// Selected column `col` as finite numbers; a bad cell names its line and column.
    pub fn numbers(&self, col: usize) -> Result<Vec<f64>, CsvError> {
        let name = self.columns.get(col).map_or("?", String::as_str);
        self.text(col)
            .zip(&self.lines)
            .map(|(cell, &line)| match cell.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                Ok(v) => Err(self.at(line, format!("column {name:?}: {v} is not finite"))),
                Err(_) if cell.is_empty() => {
                    Err(self.at(line, format!("column {name:?}: empty value")))
                }
                Err(_) => Err(self.at(line, format!("column {name:?}: {cell:?} is not a number"))),
            })
            .collect()
    }

    /// Fails unless there are at least `need` rows.
    pub fn require_rows(&self, need: usize, why: &str) -> Result<(), CsvError> {
        if self.len() < need {
            return Err(CsvError::TooFew {
                file: self.file.clone(),
                got: self.len(),
                need,
                why: if why.is_empty() {
                    String::new()
                } else {
                    format!(" ({why})")
                },
            });
        }
        Ok(())
    }

    /// Fails at the first row whose value of column `col` (given as `values`) is not larger
    /// than the previous row's.
    pub fn require_increasing(&self, col: usize, values: &[f64]) -> Result<(), CsvError> {
        let name = self.columns.get(col).map_or("?", String::as_str);
        for (i, w) in values.windows(2).enumerate() {
            if w[1] <= w[0] {
                let line = self.lines.get(i + 1).copied().unwrap_or(0);
                return Err(self.at(
                    line,
                    format!(
                        "column {name:?} must increase from row to row: {} after {}",
                        w[1], w[0]
                    ),
                ));
            }
        }
        Ok(())
    }

    /// An error at `line`.
    pub fn at(&self, line: u64, message: String) -> CsvError {
        CsvError::At {
            file: self.file.clone(),
            line,
            message,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A million-row bench log (with comments and blank lines in it) keeps exact line
    /// numbers; the line lookup is logarithmic, so this reads in about a second (recounting
    /// newlines per record took an hour at this size).
    #[test]
    fn a_million_rows_keep_their_line_numbers() {
        let mut text = String::from("# bench log\nx,y\n");
        for i in 0..1_000_000u32 {
            if i == 500_000 {
                text.push_str("# operator swapped the sample\n\n");
            }
            text.push_str(&format!("{i},{}\n", 2 * i));
        }
        let t = parse("log.csv", &text, &["y", "x"]).unwrap();
        assert_eq!(t.len(), 1_000_000);
        assert_eq!(t.lines[0], 3);
        assert_eq!(t.lines[499_999], 500_002);
        assert_eq!(t.lines[500_000], 500_005);
        assert_eq!(t.lines[999_999], 1_000_004);
        let x = t.numbers(1).unwrap();
        assert_eq!(x[999_999], 999_999.0);
    }

    #[test]
    fn lines_count_comments_and_header() {
        let t = parse("b.csv", "# source\nx,y\n1,2\n# note\n3,oops\n", &["y"]).unwrap();
        assert_eq!(t.lines, vec![3, 5]);
        let e = t.numbers(0).unwrap_err();
        assert_eq!(
            e.to_string(),
            "b.csv:5: column \"y\": \"oops\" is not a number"
        );
    }

    #[test]
    fn missing_column_names_header_line() {
        let e = parse("b.csv", "# c\nx,z\n1,2\n", &["x", "y"]).unwrap_err();
        assert!(
            e.to_string().starts_with("b.csv:2: missing column \"y\""),
            "{e}"
        );
    }

    #[test]
    fn non_increasing_names_the_line() {
        let t = parse("b.csv", "x\n1\n2\n2\n", &["x"]).unwrap();
        let v = t.numbers(0).unwrap();
        let e = t.require_increasing(0, &v).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("b.csv:4: column \"x\" must increase"),
            "{e}"
        );
    }
}
