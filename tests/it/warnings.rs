//! Warning codes: the table in `docs/WARNINGS.md` lists exactly the codes the library can
//! raise (`dmdsl::warning::CODES`), with their severity, figures and meaning.

use crate::common::root;
use dmdsl::warning::{Severity, CODES};

/// The table's row for each code, as `docs/WARNINGS.md` must have it.
fn expected_rows() -> Vec<String> {
    CODES
        .iter()
        .map(|c| {
            let severity = match c.severity {
                Severity::Note => "note",
                Severity::Warning => "warning",
                Severity::Error => "error",
            };
            let fields = if c.fields.is_empty() {
                String::from("–")
            } else {
                c.fields
                    .split(", ")
                    .map(|f| format!("`{f}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            format!("| `{}` | {severity} | {fields} | {} |", c.code, c.meaning)
        })
        .collect()
}

#[test]
fn docs_table_lists_every_code() {
    let doc = std::fs::read_to_string(root().join("docs/WARNINGS.md")).unwrap();
    let rows: Vec<&str> = doc.lines().filter(|l| l.starts_with("| `")).collect();
    let want = expected_rows();
    assert_eq!(
        rows,
        want,
        "docs/WARNINGS.md's table must be:\n{}",
        want.join("\n")
    );
}
