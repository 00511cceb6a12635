//! Reading measurement tables: small CSV files of numbers with named columns (the light
//! calibration's readings, the lens distortion table).
//!
//! Accepted: a UTF-8 byte order mark, `#` comments (whole lines or after the data), blank
//! lines, CRLF line ends, spaces around fields, quoted fields. The header row names the
//! columns in any order, or, where [`Columns::header_optional`], may be left out (the
//! columns then in the canonical order). Rows are deserialized with serde into the caller's
//! row type; a cell that is a number must be a finite one. Every error is one line naming
//! the file, the line and, for a bad value, the column:
//! `meas.csv: line 14, column irradiance_mw_cm2: "abc" is not a number`.

use crate::error::{Error, Result};
use serde::de::DeserializeOwned;
use std::path::Path;

/// The columns of a table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Columns {
    /// Column names, in the canonical order.
    pub names: &'static [&'static str],
    /// Whether the header row may be left out (then the columns are in the canonical order).
    pub header_optional: bool,
}

impl Columns {
    /// The canonical header, `a,b,c`.
    pub fn header(&self) -> String {
        self.names.join(",")
    }
}

/// One data row and the line it was read from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row<T> {
    /// Line in the file (1-based).
    pub line: u64,
    /// The row's values.
    pub value: T,
}

/// The error of a bad value at `line` in `column` of the table at `path`.
pub fn cell_error(path: &Path, line: u64, column: &str, msg: impl std::fmt::Display) -> Error {
    Error::input(path, format!("line {line}, column {column}: {msg}"))
}

/// Reads the table at `path`: the file's bytes (for hashing) and its rows.
pub fn read<T: DeserializeOwned>(path: &Path, columns: &Columns) -> Result<(Vec<u8>, Vec<Row<T>>)> {
    let bytes = crate::input::read_file(path, "table", crate::input::TEXT_MAX_BYTES)?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|_| Error::input(path, "not UTF-8 text (expected a CSV table)"))?;
    let rows = parse(path, text, columns)?;
    Ok((bytes, rows))
}

/// Parses table text; `path` names the file in errors.
pub fn parse<T: DeserializeOwned>(
    path: &Path,
    text: &str,
    columns: &Columns,
) -> Result<Vec<Row<T>>> {
    let (text, lines) = strip_comments(text.strip_prefix('\u{feff}').unwrap_or(text));
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let mut records = reader.records();
    let line_of = |r: &csv::StringRecord| {
        let k = r.position().map_or(1, |p| p.line()).max(1) as usize - 1;
        lines.get(k).or(lines.last()).copied().unwrap_or(0)
    };
    let read_err = |e: csv::Error| Error::input(path, format!("not a CSV table: {e}"));
    let Some(first) = records.next().transpose().map_err(read_err)? else {
        if columns.header_optional {
            return Ok(Vec::new());
        }
        return Err(Error::input(
            path,
            format!("empty file; expected the header {}", columns.header()),
        ));
    };
    let is_number = |f: &str| f.parse::<f64>().is_ok();
    let (header, first_row) = if columns.header_optional && first.iter().any(is_number) {
        (csv::StringRecord::from(columns.names.to_vec()), Some(first))
    } else {
        check_header(path, line_of(&first), &first, columns)?;
        (first, None)
    };
    let mut rows = Vec::new();
    for record in first_row.into_iter().map(Ok).chain(records) {
        let record = record.map_err(read_err)?;
        let line = line_of(&record);
        if record.len() != header.len() {
            return Err(Error::input(
                path,
                format!(
                    "line {line}: expected {} columns ({}), found {}",
                    header.len(),
                    columns.header(),
                    record.len()
                ),
            ));
        }
        // Every cell that is a number must be a finite one.
        if let Some(k) = record
            .iter()
            .position(|c| c.parse::<f64>().is_ok_and(|v| !v.is_finite()))
        {
            return Err(cell_error(
                path,
                line,
                &header[k],
                format!("{:?} is not a finite number", &record[k]),
            ));
        }
        let value = record
            .deserialize(Some(&header))
            .map_err(|e| value_error(path, line, &header, &record, &e))?;
        rows.push(Row { line, value });
    }
    Ok(rows)
}

/// The text's lines with `#` comments cut off and without blank lines, and the file's line
/// number of each (the CSV reader counts only the lines it is given).
fn strip_comments(text: &str) -> (String, Vec<u64>) {
    let mut out = String::with_capacity(text.len());
    let mut lines = Vec::new();
    for (i, line) in text.split('\n').enumerate() {
        let data = line.split('#').next().unwrap_or("").trim_end();
        if !data.trim_start().is_empty() {
            out.push_str(data);
            out.push('\n');
            lines.push(i as u64 + 1);
        }
    }
    (out, lines)
}

/// Checks a header row: every column named once, none unknown.
fn check_header(
    path: &Path,
    line: u64,
    header: &csv::StringRecord,
    columns: &Columns,
) -> Result<()> {
    let err = |msg: String| {
        Error::input(
            path,
            format!(
                "line {line}: {msg} (expected the header {})",
                columns.header()
            ),
        )
    };
    for (i, name) in header.iter().enumerate() {
        if !columns.names.contains(&name) {
            return Err(err(format!("unknown column {name:?}")));
        }
        if header.iter().take(i).any(|n| n == name) {
            return Err(err(format!("column {name:?} appears twice")));
        }
    }
    match columns
        .names
        .iter()
        .find(|n| !header.iter().any(|h| h == **n))
    {
        Some(missing) => Err(err(format!("missing column {missing:?}"))),
        None => Ok(()),
    }
}

/// The one-line error of a row the row type refused, naming the column and its text.
fn value_error(
    path: &Path,
    line: u64,
    header: &csv::StringRecord,
    record: &csv::StringRecord,
    e: &csv::Error,
) -> Error {
    let csv::ErrorKind::Deserialize { err, .. } = e.kind() else {
        return Error::input(path, format!("line {line}: {e}"));
    };
    let Some(k) = err.field().map(|k| k as usize) else {
        return Error::input(path, format!("line {line}: {err}"));
    };
    let (column, text) = (header.get(k).unwrap_or("?"), record.get(k).unwrap_or(""));
    let what = match err.kind() {
        csv::DeserializeErrorKind::ParseFloat(_) | csv::DeserializeErrorKind::ParseInt(_) => {
            "is not a number".to_string()
        }
        other => format!("cannot be read ({other})"),
    };
    cell_error(path, line, column, format!("{text:?} {what}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize, PartialEq)]
    struct Xy {
        x_mm: f64,
        y_mm: f64,
    }

    const REQUIRED: Columns = Columns {
        names: &["x_mm", "y_mm"],
        header_optional: false,
    };
    const OPTIONAL: Columns = Columns {
        names: &["x_mm", "y_mm"],
        header_optional: true,
    };

    fn rows(text: &str, c: &Columns) -> Result<Vec<(u64, f64, f64)>> {
        let r: Vec<Row<Xy>> = parse(Path::new("t.csv"), text, c)?;
        Ok(r.iter()
            .map(|r| (r.line, r.value.x_mm, r.value.y_mm))
            .collect())
    }

    fn err(text: &str, c: &Columns) -> String {
        rows(text, c).unwrap_err().to_string()
    }

    #[test]
    fn accepts_comments_blanks_bom_crlf_spaces_quotes_and_any_column_order() {
        let text = "\u{feff}# made by hand\r\ny_mm , x_mm # swapped\r\n\r\n  \r\n1, 2\r\n  # note\r\n\"3\",4.5e0 # tail\r\n";
        assert_eq!(
            rows(text, &REQUIRED).unwrap(),
            vec![(5, 2.0, 1.0), (7, 4.5, 3.0)]
        );
        // An optional header may be left out: the columns are then in canonical order.
        assert_eq!(
            rows("1,2\n\n3,4\n", &OPTIONAL).unwrap(),
            vec![(1, 1.0, 2.0), (3, 3.0, 4.0)]
        );
        assert_eq!(
            rows("x_mm,y_mm\n1,2\n", &OPTIONAL).unwrap(),
            vec![(2, 1.0, 2.0)]
        );
        assert_eq!(rows("", &OPTIONAL).unwrap(), vec![]);
    }

    #[test]
    fn errors_name_file_line_and_column() {
        assert_eq!(
            err("x_mm,y_mm\n1,2\n# c\n3,abc\n", &REQUIRED),
            "t.csv: line 4, column y_mm: \"abc\" is not a number"
        );
        assert_eq!(
            err("y_mm,x_mm\n1,inf\n", &REQUIRED),
            "t.csv: line 2, column x_mm: \"inf\" is not a finite number"
        );
        assert_eq!(
            err("1,2\n1,NaN\n", &OPTIONAL),
            "t.csv: line 2, column y_mm: \"NaN\" is not a finite number"
        );
        assert_eq!(
            err("x_mm,y_mm\n1,2,3\n", &REQUIRED),
            "t.csv: line 2: expected 2 columns (x_mm,y_mm), found 3"
        );
        assert_eq!(
            err("1,2\n\n7\n", &OPTIONAL),
            "t.csv: line 3: expected 2 columns (x_mm,y_mm), found 1"
        );
        // A first row with a number in it is data, not a misspelt header.
        assert_eq!(
            err("1,x\n", &OPTIONAL),
            "t.csv: line 1, column y_mm: \"x\" is not a number"
        );
        assert_eq!(
            err("x_mm,z\n", &REQUIRED),
            "t.csv: line 1: unknown column \"z\" (expected the header x_mm,y_mm)"
        );
        assert_eq!(
            err("a,b\n1,2\n", &OPTIONAL),
            "t.csv: line 1: unknown column \"a\" (expected the header x_mm,y_mm)"
        );
        assert_eq!(
            err("# c\nx_mm,x_mm\n", &REQUIRED),
            "t.csv: line 2: column \"x_mm\" appears twice (expected the header x_mm,y_mm)"
        );
        assert_eq!(
            err("x_mm\n1\n", &REQUIRED),
            "t.csv: line 1: missing column \"y_mm\" (expected the header x_mm,y_mm)"
        );
        assert_eq!(
            err("\n# nothing\n", &REQUIRED),
            "t.csv: empty file; expected the header x_mm,y_mm"
        );
    }

    #[test]
    fn reads_files_and_refuses_non_utf8() {
        let dir = std::env::temp_dir().join(format!("dmdsl-table-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let good = dir.join("good.csv");
        std::fs::write(&good, "x_mm,y_mm\n1,2\n").unwrap();
        let (bytes, r) = read::<Xy>(&good, &REQUIRED).unwrap();
        assert_eq!(bytes, b"x_mm,y_mm\n1,2\n");
        assert_eq!(r[0].value.y_mm, 2.0);
        let bad = dir.join("bad.csv");
        std::fs::write(&bad, b"x_mm,y_mm\n1,\xff\n").unwrap();
        let e = read::<Xy>(&bad, &REQUIRED).unwrap_err().to_string();
        assert!(
            e.ends_with("bad.csv: not UTF-8 text (expected a CSV table)"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
