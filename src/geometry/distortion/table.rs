//! The measured correction table: pairs of where the uncorrected projector was aimed and
//! where its light landed, from a CSV file (read by [`crate::table`]) or a profile's
//! inline points.

use crate::digest::sha256_hex;
use crate::error::{Error, Result};
use crate::table::{self, Columns, Row};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The table's columns: `x_mm,y_mm,seen_x_mm,seen_y_mm` (the header row is optional).
pub const COLUMNS: Columns = Columns {
    names: &["x_mm", "y_mm", "seen_x_mm", "seen_y_mm"],
    header_optional: true,
};

/// One measured pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    /// Where the uncorrected projector was aimed, mm.
    pub aim: [f64; 2],
    /// Where the light landed, mm.
    pub seen: [f64; 2],
    /// 1-based line in the file (or index in the inline list).
    pub line: usize,
}

/// A row of the CSV table, as read.
#[derive(Debug, Deserialize)]
struct TableRow {
    x_mm: f64,
    y_mm: f64,
    seen_x_mm: f64,
    seen_y_mm: f64,
}

impl From<Row<TableRow>> for Pair {
    fn from(Row { line, value: r }: Row<TableRow>) -> Pair {
        Pair {
            aim: [r.x_mm, r.y_mm],
            seen: [r.seen_x_mm, r.seen_y_mm],
            line: line as usize,
        }
    }
}

/// A parsed correction table and where it came from.
#[derive(Debug, Clone)]
pub struct Table {
    /// The file (or a label for inline points) named in errors.
    pub origin: PathBuf,
    /// "line" for files, "point" for inline profile points.
    pub unit: &'static str,
    /// Short source name for the manifest (file name, or "profile `<name>`").
    pub source: String,
    /// SHA-256 of the file bytes (or of the inline points as CSV text).
    pub sha256: String,
    /// The measured pairs.
    pub pairs: Vec<Pair>,
}

impl Table {
    /// Reads and parses a CSV table.
    pub fn read(path: &Path) -> Result<Table> {
        let (bytes, rows) = table::read::<TableRow>(path, &COLUMNS)?;
        Ok(Table {
            origin: path.to_path_buf(),
            unit: "line",
            source: path
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            sha256: sha256_hex(&bytes),
            pairs: rows.into_iter().map(Pair::from).collect(),
        })
    }

    /// Parses CSV text; `path` names the file in errors.
    #[cfg(any(test, feature = "internals"))]
    pub fn parse(path: &Path, text: &str) -> Result<Vec<Pair>> {
        let rows = table::parse::<TableRow>(path, text, &COLUMNS)?;
        Ok(rows.into_iter().map(Pair::from).collect())
    }

    /// Table from a profile's inline points; `profile` names it in errors.
    pub fn inline(profile: &str, points: &[[f64; 4]]) -> Table {
        let mut csv = COLUMNS.header();
        csv.push('\n');
        let pairs = points
            .iter()
            .enumerate()
            .map(|(i, r)| {
                csv.push_str(&format!("{},{},{},{}\n", r[0], r[1], r[2], r[3]));
                Pair {
                    aim: [r[0], r[1]],
                    seen: [r[2], r[3]],
                    line: i + 1,
                }
            })
            .collect();
        Table {
            origin: PathBuf::from(format!("profile {profile} [distortion].points")),
            unit: "point",
            source: format!("profile {profile}"),
            sha256: sha256_hex(csv.as_bytes()),
            pairs,
        }
    }

    /// The pairs as inline profile points.
    pub fn points(&self) -> Vec<[f64; 4]> {
        self.pairs
            .iter()
            .map(|p| [p.aim[0], p.aim[1], p.seen[0], p.seen[1]])
            .collect()
    }

    /// An error at `line` of the table (or inline point `line`).
    pub(super) fn err(&self, line: usize, msg: impl std::fmt::Display) -> Error {
        Error::input(&self.origin, format!("{} {line}: {msg}", self.unit))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_optional_comments_and_errors() {
        let p = Path::new("t.csv");
        let ok = Table::parse(
            p,
            "\u{feff}x_mm,y_mm,seen_x_mm,seen_y_mm\n# c\n1,2,3,4 # x\n\n5, 6 ,7,8\r\n",
        )
        .unwrap();
        assert_eq!(ok.len(), 2);
        assert_eq!(
            (ok[0].aim, ok[0].seen, ok[0].line),
            ([1.0, 2.0], [3.0, 4.0], 3)
        );
        assert_eq!((ok[1].aim, ok[1].line), ([5.0, 6.0], 5));
        let no_header = Table::parse(p, "1,2,3,4\n").unwrap();
        assert_eq!(no_header[0].seen, [3.0, 4.0]);
        let err = |text| Table::parse(p, text).unwrap_err().to_string();
        assert_eq!(
            err("1,2,3,4\n1,2,3\n"),
            "t.csv: line 2: expected 4 columns (x_mm,y_mm,seen_x_mm,seen_y_mm), found 3"
        );
        let e = err("1,2,3,4\n1,2,x,4\n");
        assert_eq!(e, "t.csv: line 2, column seen_x_mm: \"x\" is not a number");
        let e = err("a,b,c,d\n");
        assert!(e.starts_with("t.csv: line 1: unknown column \"a\""), "{e}");
        let e = err("1,2,3,4\n1,2,inf,4\n");
        assert!(
            e.contains("line 2, column seen_x_mm: \"inf\" is not a finite"),
            "{e}"
        );
    }

    #[test]
    fn inline_points_hash_as_their_csv_text() {
        let t = Table::inline("p", &[[1.0, 2.0, 3.0, 4.5]]);
        assert_eq!(
            t.sha256,
            sha256_hex(b"x_mm,y_mm,seen_x_mm,seen_y_mm\n1,2,3,4.5\n")
        );
        assert_eq!(t.points(), vec![[1.0, 2.0, 3.0, 4.5]]);
        let e = t.err(1, "bad").to_string();
        assert_eq!(e, "profile p [distortion].points: point 1: bad");
    }
}
