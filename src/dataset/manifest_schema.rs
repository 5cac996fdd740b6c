//! `dataset.json` against its JSON Schema, `docs/dataset-format.schema.json` — the file a user
//! reads beside `docs/dataset-format.md`, compiled into ffdic so the two cannot drift: every
//! mistake the schema finds, each named by where it is (`runs[1].stage: missing field
//! `dx_mm``), instead of serde's first one (six tries for a person, issue 34).

use jsonschema::error::ValidationErrorKind;
use jsonschema::paths::LocationSegment;
use jsonschema::Validator;
use serde_json::Value;
use std::sync::LazyLock;

/// The schema as shipped in `docs/`.
pub const SCHEMA_JSON: &str = include_str!("../../docs/dataset-format.schema.json");

static VALIDATOR: LazyLock<Validator> = LazyLock::new(|| {
    let schema: Value = serde_json::from_str(SCHEMA_JSON).expect("the shipped schema is JSON");
    jsonschema::validator_for(&schema).expect("the shipped schema is a valid JSON Schema")
});

/// Every place where `manifest` breaks the schema, in the schema's order; empty when it holds.
pub fn schema_problems(manifest: &Value) -> Vec<String> {
    VALIDATOR
        .iter_errors(manifest)
        .map(|e| {
            let place = place_of(e.instance_path().iter());
            let what = match e.kind() {
                ValidationErrorKind::Required { property } => {
                    format!("missing field `{}`", property.as_str().unwrap_or("?"))
                }
                // The only patterns in the schema are file names (`$defs/file`).
                ValidationErrorKind::Pattern { .. } | ValidationErrorKind::Not { .. } => {
                    format!(
                        "{} is not a plain file name inside the dataset",
                        e.instance()
                    )
                }
                _ => e.to_string(),
            };
            match place.is_empty() {
                true => what,
                false => format!("{place}: {what}"),
            }
        })
        .collect()
}

/// `runs[1].stage` for the pointer `/runs/1/stage`.
fn place_of<'a>(segments: impl Iterator<Item = LocationSegment<'a>>) -> String {
    let mut place = String::new();
    for segment in segments {
        match segment {
            LocationSegment::Index(i) => place.push_str(&format!("[{i}]")),
            LocationSegment::Property(name) => {
                if !place.is_empty() {
                    place.push('.');
                }
                place.push_str(&name);
            }
        }
    }
    place
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The examples in docs/dataset-format.md hold, as written.
    #[test]
    fn the_documented_examples_hold() {
        let doc = include_str!("../../docs/dataset-format.md");
        let examples: Vec<&str> = doc
            .split("```json")
            .skip(1)
            .map(|rest| rest.split("```").next().unwrap())
            .collect();
        assert_eq!(examples.len(), 2);
        for example in examples {
            let value: Value = serde_json::from_str(example).unwrap();
            assert_eq!(schema_problems(&value), Vec::<String>::new(), "{example}");
        }
    }

    #[test]
    fn places_are_written_as_paths() {
        let value = serde_json::json!({ "format": "ffdic-dataset/1", "name": "n",
            "scale_px_per_mm": 26.0,
            "runs": [ { "id": "a", "reference": "r.tif", "deformed": "d.tif",
                        "stage": { "dx_mm": 1.0, "dy_mm": 0.0 } },
                      { "id": "b", "reference": "../r.tif", "deformed": ".",
                        "stage": { "dx_mm": 1.0 } } ] });
        let problems = schema_problems(&value);
        assert!(
            problems.contains(&"runs[1].stage: missing field `dy_mm`".to_string()),
            "{problems:?}"
        );
        for file in ["runs[1].reference: \"../r.tif\"", "runs[1].deformed: \".\""] {
            assert!(
                problems
                    .iter()
                    .any(|p| p.starts_with(file)
                        && p.ends_with("plain file name inside the dataset")),
                "{file}: {problems:?}"
            );
        }
    }
}
