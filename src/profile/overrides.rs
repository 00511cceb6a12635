//! Changes to single keys of a profile (`slice --set section.key=value`, `--exposure`, …)
//! without copying the profile into a file.
//!
//! An override replaces one value of the profile's TOML table; the table is then read
//! back and validated exactly as a profile file is, so an unknown key or a bad value is
//! refused with the same one-line error, naming the override that caused it.

use super::{one_line, Profile};
use crate::error::{Error, Result};
use serde::Deserialize;

/// One change to a profile key.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    /// How the change was asked for, for messages (`--set exposure.layer_s=6`,
    /// `--exposure 6`).
    pub label: String,
    /// The key's dotted path (`exposure.layer_s`; an entry of a list by its 0-based index:
    /// `projector.0.pixel_mm`).
    pub key: String,
    /// The new value.
    pub value: toml::Value,
}

impl Override {
    /// An override of `key` with `value`, asked for as `label`.
    pub fn new(label: impl Into<String>, key: impl Into<String>, value: toml::Value) -> Self {
        Override {
            label: label.into(),
            key: key.into(),
            value,
        }
    }

    /// Parses the argument of `--set`: `section.key=value`, the value read as a TOML value
    /// (a number, `true`/`false`, a quoted string, an array); anything that is not one is
    /// taken as a string, so `--set resin.name=My resin` needs no quotes.
    pub fn parse_set(arg: &str) -> Result<Override> {
        let label = format!("--set {arg}");
        let usage = || {
            let msg =
                format!("{label}: expected section.key=value (e.g. --set exposure.layer_s=6)");
            Error::Usage(msg)
        };
        let (key, text) = arg.split_once('=').ok_or_else(usage)?;
        let key = key.trim();
        if key.split('.').any(|s| s.trim().is_empty()) {
            return Err(usage());
        }
        let text = text.trim();
        let value = toml::Value::deserialize(toml::de::ValueDeserializer::new(text))
            .unwrap_or_else(|_| toml::Value::String(text.to_string()));
        Ok(Override::new(label, key, value))
    }

    /// Sets the value in `table` (a profile as TOML), creating missing sections; an error
    /// says why the key cannot be there.
    pub(crate) fn apply(&self, table: &mut toml::Table) -> std::result::Result<(), String> {
        let parts: Vec<&str> = self.key.split('.').map(str::trim).collect();
        let mut here = table
            .entry(parts[0].to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        let mut path = parts[0].to_string();
        for (k, part) in parts.iter().enumerate().skip(1) {
            here = step(here, (part, &parts[k + 1..]), &path)?;
            path = format!("{path}.{part}");
        }
        *here = self.value.clone();
        Ok(())
    }
}

/// The value at `part` inside `v` (the value at `path`; `rest` the key's parts after
/// `part`): a key of a section (created, as an empty section, if missing) or the index of
/// a list entry.
fn step<'v>(
    v: &'v mut toml::Value,
    (part, rest): (&str, &[&str]),
    path: &str,
) -> std::result::Result<&'v mut toml::Value, String> {
    match v {
        toml::Value::Table(t) => Ok(t
            .entry(part.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))),
        toml::Value::Array(a) => {
            let n = a.len();
            let index = part.parse::<usize>();
            match index {
                Ok(i) if i < n => Ok(&mut a[i]),
                _ if n == 0 => Err(format!("`{path}` is an empty list")),
                _ => {
                    // The key with its first entry's index: in place of the index given,
                    // or before the key named.
                    let mut example = vec![path, "0"];
                    example.extend(index.is_err().then_some(part));
                    example.extend_from_slice(rest);
                    Err(format!(
                        "`{path}` is a list of {}; name one by its index, 0 to {}, as in {}",
                        crate::text::count(n as u64, "entry", "entries"),
                        n - 1,
                        example.join(".")
                    ))
                }
            }
        }
        _ => Err(format!("`{path}` is a value, not a section with keys")),
    }
}

impl Profile {
    /// This profile with `overrides` applied in order, read back and validated like a
    /// profile file. An error names the override responsible: the first that is refused
    /// on its own, or, when only their combination is invalid, all of them.
    pub fn with_overrides(&self, overrides: &[Override]) -> Result<Profile> {
        if overrides.is_empty() {
            return Ok(self.clone());
        }
        let error = |labels: &str, msg: String| Error::Profile {
            origin: self.name.clone(),
            msg: format!("{labels}: {}", one_line(&msg)),
        };
        let all = self.apply_overrides(overrides);
        let Err(msg) = &all else {
            return all.map_err(|m| error("", m));
        };
        for o in overrides {
            if let Err(m) = self.apply_overrides(std::slice::from_ref(o)) {
                return Err(error(&o.label, m));
            }
        }
        let labels: Vec<&str> = overrides.iter().map(|o| o.label.as_str()).collect();
        Err(error(&labels.join(", "), msg.clone()))
    }

    /// `overrides` applied to this profile's table, which is then read and validated; an
    /// error is the message without the profile's name.
    fn apply_overrides(&self, overrides: &[Override]) -> std::result::Result<Profile, String> {
        let mut table = toml::Table::try_from(self).map_err(|e| e.to_string())?;
        for o in overrides {
            o.apply(&mut table)?;
        }
        let profile = Profile::deserialize(toml::Value::Table(table)).map_err(|e| e.to_string())?;
        profile.validate()?;
        Ok(profile)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(args: &[&str]) -> Result<Profile> {
        let o: Vec<Override> = args
            .iter()
            .map(|a| Override::parse_set(a).unwrap())
            .collect();
        Profile::default_profile().with_overrides(&o)
    }

    #[test]
    fn values_reach_their_keys() {
        let base = Profile::default_profile();
        let p = set(&[
            "exposure.layer_s=6",
            "exposure.bottom_layers=5",
            "slicing.binary=true",
            "resin.name=My resin",
            "projector.0.mirror_x=true",
        ])
        .unwrap();
        assert_eq!(p.exposure.layer_s.get(), 6.0);
        assert_eq!(p.exposure.bottom_layers, 5);
        assert!(p.slicing.binary);
        assert_eq!(p.resin.name, "My resin");
        assert!(p.projector[0].mirror_x);
        // Nothing else changes, and no override gives the profile itself.
        let mut back = p.clone();
        back.exposure = base.exposure.clone();
        back.slicing.binary = false;
        back.resin.name = base.resin.name.clone();
        back.projector[0].mirror_x = false;
        assert_eq!(back, base);
        assert_eq!(base.with_overrides(&[]).unwrap(), base);
        // A quoted string stays a string.
        let p = set(&["resin.name=\"42\""]).unwrap();
        assert_eq!(p.resin.name, "42");
    }

    #[test]
    fn every_built_in_profile_survives_the_table_unchanged() {
        for name in crate::profile::builtin_names() {
            let p = Profile::resolve(name).unwrap();
            let same = Override::parse_set(&format!("name={name}")).unwrap();
            assert_eq!(p.with_overrides(&[same]).unwrap(), p, "{name}");
        }
    }

    #[test]
    fn refusals_name_the_override() {
        let cases = [
            (
                "exposure.layr_s=6",
                "profile xu2010-topdown: --set exposure.layr_s=6: unknown field `layr_s`",
            ),
            (
                "exposure.layer_s=-1",
                "profile xu2010-topdown: --set exposure.layer_s=-1: must be a finite number > 0, got -1",
            ),
            (
                "exposure.layer_s=fast",
                "profile xu2010-topdown: --set exposure.layer_s=fast: invalid type: string \"fast\"",
            ),
            (
                "exposure.layer_s=2e7",
                "profile xu2010-topdown: --set exposure.layer_s=2e7: exposure.layer_s = 20000000.0 is not a duration",
            ),
            ("nosuch.key=1", "--set nosuch.key=1: unknown field `nosuch`"),
            (
                "projector.pixel_mm=0.05",
                "--set projector.pixel_mm=0.05: `projector` is a list of 1 entry; name one by its index, 0 to 0, as in projector.0.pixel_mm",
            ),
            (
                "projector.3.width_px=10",
                "--set projector.3.width_px=10: `projector` is a list of 1 entry; name one by its index, 0 to 0, as in projector.0.width_px",
            ),
            (
                "name.x=1",
                "--set name.x=1: `name` is a value, not a section with keys",
            ),
        ];
        for (arg, want) in cases {
            let e = set(&[arg]).unwrap_err().to_string();
            assert!(e.contains(want), "{arg}: {e}");
            assert!(!e.contains('\n'), "{e}");
            assert_eq!(set(&[arg]).unwrap_err().code(), "profile.invalid");
        }
        // The override that fails on its own is named among several.
        let e = set(&["exposure.layer_s=6", "exposure.bottom_s=0"])
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("profile xu2010-topdown: --set exposure.bottom_s=0: "),
            "{e}"
        );
        for bad in ["exposure.layer_s", "=3", "exposure.=3", ".x=1"] {
            let e = Override::parse_set(bad).unwrap_err();
            assert_eq!(e.code(), "usage", "{bad}");
            assert!(e.to_string().contains("expected section.key=value"), "{e}");
        }
    }

    #[test]
    fn a_combination_only_invalid_together_names_all() {
        // Steps of 0.02 mm are fine for 0.05 mm layers, and 0.01 mm layers are fine with
        // the profile's steps; together the steps are coarser than a layer.
        let e = set(&["stage.steps_per_mm=50", "slicing.layer_height_mm=0.01"])
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with(
                "profile xu2010-topdown: --set stage.steps_per_mm=50, --set slicing.layer_height_mm=0.01: stage.steps_per_mm"
            ),
            "{e}"
        );
    }
}
