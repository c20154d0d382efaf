//! Building blocks of the JSON Schemas the codecs write.

use serde_json::{Value, json};

/// JSON Schema of [`ipc_types::Stamps`].
pub(super) fn stamps_schema() -> Value {
    let stamp = |what: &str| {
        uint(
            &format!("{what}, ns CLOCK_MONOTONIC; 0 if not yet."),
            u64::MAX,
        )
    };
    object(
        "mems.Stamps",
        "Per-stage timestamps.",
        &[
            ("sample_ns", stamp("When the sensor sampled")),
            ("acquired_ns", stamp("When acquisition published")),
            ("calibrated_ns", stamp("When calibration published")),
            ("odometry_ns", stamp("When odometry published")),
        ],
    )
}

/// A JSON Schema object whose properties are all required.
pub(super) fn object(title: &str, description: &str, properties: &[(&str, Value)]) -> Value {
    let required: Vec<&str> = properties.iter().map(|(name, _)| *name).collect();
    let properties: serde_json::Map<String, Value> = properties
        .iter()
        .map(|(name, schema)| ((*name).to_owned(), schema.clone()))
        .collect();
    json!({
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": required,
    })
}

/// A JSON Schema number (an `f64`).
pub(super) fn number(description: &str) -> Value {
    json!({"type": "number", "description": description})
}

/// A JSON Schema unsigned integer up to `max`.
pub(super) fn uint(description: &str, max: u64) -> Value {
    json!({"type": "integer", "minimum": 0, "maximum": max, "description": description})
}

/// A JSON Schema `i16`.
pub(super) fn int16(description: &str) -> Value {
    json!({"type": "integer", "minimum": i16::MIN, "maximum": i16::MAX, "description": description})
}

/// A JSON Schema array of exactly `n` items.
pub(super) fn vector(n: usize, item: Value) -> Value {
    json!({"type": "array", "items": item, "minItems": n, "maxItems": n})
}
