//! Warnings a script can act on: each has a stable code, a severity and its figures as
//! fields, beside the one-line message people read.
//!
//! Codes are `area.kebab-name` (e.g. `mesh.degenerate-facets`, `plan.wait-capped`) and never
//! change meaning once released; the message may be reworded. The figures a message quotes
//! are also in `fields`, so a script never parses the message.

use serde::{Deserialize, Serialize};

/// How much a warning matters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Severity {
    /// Worth knowing; the job is as asked.
    Note,
    /// The job may not print as the user expects.
    Warning,
    /// Treated as a failure (a warning raised by `--deny-warnings` or `-W CODE=error`).
    Error,
}

/// One warning.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Warning {
    /// Stable code, `area.kebab-name`.
    pub code: String,
    /// How much it matters.
    pub severity: Severity,
    /// One line for people.
    pub message: String,
    /// The figures the message quotes, by name (with their unit in the name, e.g.
    /// `wait_s`).
    #[serde(default, skip_serializing_if = "serde_json::Map::is_empty")]
    pub fields: serde_json::Map<String, serde_json::Value>,
}

impl Warning {
    /// A warning of severity [`Severity::Warning`].
    pub fn new(code: &str, message: impl Into<String>) -> Warning {
        Warning {
            code: code.into(),
            severity: Severity::Warning,
            message: message.into(),
            fields: serde_json::Map::new(),
        }
    }

    /// A warning of severity [`Severity::Note`].
    pub fn note(code: &str, message: impl Into<String>) -> Warning {
        Warning {
            severity: Severity::Note,
            ..Warning::new(code, message)
        }
    }

    /// The same warning with the figure `name` = `value`.
    pub fn with(mut self, name: &str, value: impl Into<serde_json::Value>) -> Warning {
        self.fields.insert(name.into(), value.into());
        self
    }
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} [{}]", self.message, self.code)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_shape_keeps_code_severity_and_fields() {
        let w = Warning::new("plan.wait-capped", "leveling wait capped on 3 layers")
            .with("layers", 3)
            .with("wait_max_s", 60.0);
        let v = serde_json::to_value(&w).unwrap();
        assert_eq!(v["code"], "plan.wait-capped");
        assert_eq!(v["severity"], "warning");
        assert_eq!(v["fields"]["layers"], 3);
        assert_eq!(v["fields"]["wait_max_s"], 60.0);
        let back: Warning = serde_json::from_value(v).unwrap();
        assert_eq!(back, w);
        let n = serde_json::to_value(Warning::note("mesh.repaired", "x")).unwrap();
        assert_eq!(n["severity"], "note");
        assert!(n.get("fields").is_none());
        assert_eq!(
            Warning::new("a.b", "m").to_string(),
            "m [a.b]",
            "people see the code to allow or deny it"
        );
    }
}
