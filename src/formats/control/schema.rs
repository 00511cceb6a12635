//! The control file's settings against the standard's own JSON Schema (draft 7,
//! `fixtures/sla_control/schema_v5.json`, vendored unchanged), with the `jsonschema`
//! crate: the whole settings object, after named layer groups and `${...}` are expanded,
//! as the standard's validator (`print_file_validator.py`) checks it.

use serde_json::Value;
use std::sync::OnceLock;

/// The vendored schema.
const SCHEMA: &str = include_str!("../../../fixtures/sla_control/schema_v5.json");

/// Longest value a message quotes, characters.
const SHOWN: usize = 80;

/// A validator of the whole schema, and one of its layer definition (`LAYER_BASE`) that
/// says what is wrong inside a layer the `oneOf` of `Layers` refuses as a whole.
fn validators() -> &'static (jsonschema::Validator, jsonschema::Validator) {
    static V: OnceLock<(jsonschema::Validator, jsonschema::Validator)> = OnceLock::new();
    V.get_or_init(|| {
        let schema: Value = serde_json::from_str(SCHEMA).expect("the vendored schema is JSON");
        let layer = serde_json::json!({
            "$ref": "#/$defs/LAYER_BASE",
            "$defs": schema["$defs"].clone(),
        });
        let new = |s: &Value| jsonschema::draft7::new(s).expect("the vendored schema compiles");
        (new(&schema), new(&layer))
    })
}

/// A location in the settings as the reader names it: `Layers[0].Image settings
/// list[1].Layer exposure time (ms)`.
fn place(location: &jsonschema::paths::Location) -> String {
    let mut out = String::new();
    for seg in location.iter() {
        match seg {
            jsonschema::paths::LocationSegment::Index(i) => out.push_str(&format!("[{i}]")),
            jsonschema::paths::LocationSegment::Property(p) if out.is_empty() => out.push_str(&p),
            jsonschema::paths::LocationSegment::Property(p) => {
                out.push('.');
                out.push_str(&p);
            }
        }
    }
    out
}

/// What the schema refuses in `settings`, as one line: the first problem (where and
/// what, the value cut to 80 characters) and how many more there are; `None` when valid.
pub(super) fn check(settings: &Value) -> Option<String> {
    let (whole, layer) = validators();
    let mut errors = whole.iter_errors(settings);
    let first = errors.next()?;
    let more = errors.count();
    let mut at = place(first.instance_path());
    let mut what = first.to_string();
    // `Layers` items are a layer or a group call (`oneOf`): say what the layer lacks.
    if at.starts_with("Layers[") && !at.contains('.') {
        if let Some(e) = layer.iter_errors(first.instance()).next() {
            let inner = place(e.instance_path());
            if !inner.is_empty() {
                at = format!("{at}.{inner}");
            }
            what = e.to_string();
        }
    }
    if what.chars().count() > SHOWN {
        what = what.chars().take(SHOWN).collect::<String>() + "…";
    }
    let at = if at.is_empty() {
        "the settings".into()
    } else {
        at
    };
    let more = match more {
        0 => String::new(),
        k => format!(
            " (and {})",
            crate::text::count(k as u64, "more problem", "more problems")
        ),
    };
    Some(format!(
        "{at}: {what}, against the standard's schema v5{more}"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn settings(image: Value) -> Value {
        super::super::test_settings(json!([{"Image settings list": [image]}]))
    }

    #[test]
    fn the_schema_names_the_place_and_the_problem() {
        assert_eq!(check(&settings(json!({"Image file": "b.png"}))), None);
        let cases = [
            (
                json!({"Layer exposure time (ms)": "abc"}),
                "\"abc\" is not of type \"number\"",
            ),
            (
                json!({"Layer exposure time (ms)": -1}),
                "-1 is less than the minimum of 0",
            ),
            (
                json!({"Layer exposure time (ms)": 1e308}),
                "is greater than the maximum of 10000",
            ),
            (
                json!({"Layer exposure time (ms)": null}),
                "null is not of type \"number\"",
            ),
            (
                json!({"Light engine power setting": -1}),
                "-1 is less than the minimum of 0",
            ),
            (
                json!({"Light engine power setting": 2.5}),
                "is not of type \"integer\"",
            ),
            (
                json!({"Shutter": 1}),
                "Additional properties are not allowed",
            ),
        ];
        for (image, what) in cases {
            let key = image.as_object().unwrap().keys().next().unwrap().clone();
            let e = check(&settings(image)).unwrap();
            assert!(e.starts_with("Layers[0].Image settings list[0]"), "{e}");
            assert!(e.contains(what), "{e}");
            assert!(key == "Shutter" || e.contains(&key), "{e}");
        }
        let mut s = settings(json!({}));
        s["Header"]["Schema version"] = json!("4.0.0");
        s["Layers"] = json!([[]]);
        let e = check(&s).unwrap();
        assert!(
            e.starts_with("Header.Schema version: \"4.0.0\" does not match"),
            "{e}"
        );
        assert!(e.ends_with("(and 1 more problem)"), "{e}");
    }
}
