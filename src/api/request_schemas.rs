//! JSON Schemas of the request bodies' nested types, with the constraints the daemon enforces.
//!
//! The types live in the numerics and the experiment layer (`DicSettings`, `PatternSpec`,
//! `SchemeSpec`…), which know nothing of HTTP or OpenAPI, so the derive types them as bare
//! objects; their schemas are written here, beside the API, from the same constants the checks
//! use. Every constraint below is one the daemon refuses (422) when broken — schemathesis'
//! `negative_data_rejection` check holds the document to that. What depends on the bench (the
//! stage's travel, the camera's exposure range, dot sizes in pixels) or relates two fields
//! (first + active <= block, at most 200 moves counting the step series) is said in words and
//! checked by the daemon.

use crate::dic::{
    MAX_ITERATIONS, MAX_MASK_VERTICES, MAX_MOTION_PX, MAX_ROI_COORDINATE_PX, MAX_SEARCH_RADIUS_PX,
    MAX_STEP_PX, MAX_STRAIN_WINDOW, MAX_SUBSET_PX,
};
use crate::experiment::{
    MAX_FRAMES_AVERAGED, MAX_MOVES, MAX_PATTERNS, MAX_REPEATS, MAX_SCHEMES, MAX_SETTLE_MS,
    MAX_STATIC_FRAMES,
};
use crate::reduce::MAX_BLOCK_PX;
use serde_json::{json, Map, Value};

/// Ids and labels that become file names (`is_plain_id` in the experiment request).
const PLAIN_ID_PATTERN: &str = "^[A-Za-z0-9_-]{1,64}$";

/// The nested types, added to `components/schemas` under these names.
pub fn components() -> Vec<(&'static str, Value)> {
    vec![
        ("DicSettings", dic_settings()),
        ("Roi", roi()),
        ("PolygonMask", polygon_mask()),
        ("PatternSpec", pattern_spec()),
        ("MoveSpec", move_spec()),
        ("StepSeries", step_series()),
        ("SchemeSpec", scheme_spec()),
        ("SweepCamera", sweep_camera()),
    ]
}

/// What replaces (or tightens) each property the derive left loose: (schema, property,
/// refinement). A refinement holding `$ref` replaces the property's type; any other is merged
/// key by key over what utoipa wrote (its description and default stay).
pub fn refinements() -> Vec<(&'static str, &'static str, Value)> {
    let schemes = json!({
        "items": reference("SchemeSpec"),
        "minItems": 1,
        "maxItems": MAX_SCHEMES,
    });
    let mut out = Vec::new();
    for body in [
        "ExperimentRequest",
        "AnalysisRequest",
        "CompareRequest",
        "CalibrationPlan",
        "PerpendicularityCheck",
    ] {
        out.push((body, "dic", reference("DicSettings")));
    }
    for body in ["ExperimentRequest", "AnalysisRequest", "CompareRequest"] {
        out.push((body, "schemes", schemes.clone()));
    }
    for body in [
        "ExperimentRequest",
        "CompareRequest",
        "CalibrationPlan",
        "PerpendicularityCheck",
    ] {
        out.push((body, "seed", json!({ "maximum": u64::MAX })));
    }
    out.extend(calibration_refinements());
    out.extend(sweep_refinements());
    out.extend([
        ("ExperimentRequest", "name", run_name_schema()),
        (
            "ExperimentRequest",
            "patterns",
            json!({ "items": reference("PatternSpec"), "minItems": 1, "maxItems": MAX_PATTERNS }),
        ),
        (
            "ExperimentRequest",
            "moves",
            json!({ "items": reference("MoveSpec"), "maxItems": MAX_MOVES }),
        ),
        (
            "ExperimentRequest",
            "step_series",
            json!({ "items": reference("StepSeries"), "maxItems": MAX_MOVES }),
        ),
        (
            "ExperimentRequest",
            "static_frames",
            json!({ "minimum": 0, "maximum": MAX_STATIC_FRAMES }),
        ),
        (
            "ExperimentRequest",
            "repeats",
            json!({ "minimum": 1, "maximum": MAX_REPEATS }),
        ),
        (
            "ExperimentRequest",
            "frames_averaged",
            json!({ "minimum": 1, "maximum": MAX_FRAMES_AVERAGED }),
        ),
        (
            "ExperimentRequest",
            "settle_ms",
            json!({ "minimum": 0, "maximum": MAX_SETTLE_MS }),
        ),
        (
            "CameraPatch",
            "roi",
            json!({ "oneOf": [sensor_roi(), { "type": "null" }], "type": null }),
        ),
        (
            "CameraPatch",
            "binning",
            json!({ "prefixItems": [binning_factor(), binning_factor()], "minItems": 2 }),
        ),
        (
            "CameraPatch",
            "decimation",
            json!({ "prefixItems": [binning_factor(), binning_factor()], "minItems": 2 }),
        ),
        (
            "CameraPatch",
            "pixel_format",
            json!({ "enum": ["mono8", "mono10", "mono12", "mono16", null] }),
        ),
    ]);
    out
}

/// Applies [`components`] and [`refinements`] to a document's `components/schemas`. A
/// refinement's `null` removes that key (utoipa's `type` where a `oneOf` takes its place).
pub fn apply(schemas: &mut Map<String, Value>) {
    for (name, schema) in components() {
        schemas.insert(name.to_string(), schema);
    }
    for (schema, property, refinement) in refinements() {
        let Some(slot) = schemas
            .get_mut(schema)
            .and_then(|s| s.pointer_mut(&format!("/properties/{property}")))
            .and_then(Value::as_object_mut)
        else {
            // The snapshot test fails on a refinement that found nothing to refine.
            continue;
        };
        let Value::Object(refinement) = refinement else {
            continue;
        };
        if refinement.contains_key("$ref") {
            slot.retain(|k, _| k == "description" || k == "default");
        }
        for (k, v) in refinement {
            if v.is_null() {
                slot.remove(&k);
            } else {
                slot.insert(k, v);
            }
        }
    }
}

/// `POST /calibrations` and `POST /perpendicularity-checks`: `crate::experiment::CalibrationPlan`
/// and `PerpendicularityCheck`, which become experiment requests (their checks then apply: the
/// travel, the counts).
fn calibration_refinements() -> Vec<(&'static str, &'static str, Value)> {
    vec![
        ("CalibrationPlan", "name", run_name_schema()),
        ("CalibrationPlan", "pattern", reference("PatternSpec")),
        ("PerpendicularityCheck", "pattern", reference("PatternSpec")),
        // 0 is the default move; a negative one is a 422 naming `move_mm`.
        ("PerpendicularityCheck", "move_mm", json!({ "minimum": 0 })),
        (
            "CalibrationPlan",
            "move_sizes_mm",
            json!({ "items": { "type": "number", "exclusiveMinimum": 0 }, "maxItems": MAX_MOVES / 4 }),
        ),
        (
            "CalibrationPlan",
            "phase_scan_step_px",
            json!({ "minimum": 0 }),
        ),
        (
            "CalibrationPlan",
            "phase_scan_count",
            json!({ "minimum": 0, "maximum": MAX_MOVES / 2 }),
        ),
        (
            "CalibrationPlan",
            "static_frames",
            json!({ "minimum": 0, "maximum": MAX_STATIC_FRAMES }),
        ),
    ]
}

/// `POST /sweeps`: `crate::sweep::SweepSpec`, checked by `SweepSpec::validate` and the daemon's
/// A run's name as `check_run_name` takes it: no control character (Unicode Cc, as
/// `char::is_control`), 1 to `MAX_RUN_NAME_CHARS` characters. "Not only white space" is said by
/// the 422, not by the schema.
fn run_name_schema() -> Value {
    json!({
        "minLength": 1,
        "maxLength": crate::experiment::MAX_RUN_NAME_CHARS,
        "pattern": "^[^\\u0000-\\u001F\\u007F-\\u009F]*$",
    })
}

/// `[sweeps]` limits (the task count, a product of the axes' lengths, is said in words).
fn sweep_refinements() -> Vec<(&'static str, &'static str, Value)> {
    let numbers = |lo: f64, hi: f64| json!({ "items": { "type": "number", "minimum": lo, "maximum": hi }, "minItems": 1 });
    vec![
        ("SweepSpec", "name", run_name_schema()),
        (
            "SweepSpec",
            "seed",
            json!({ "minimum": 0, "maximum": u64::MAX }),
        ),
        (
            "SweepSpec",
            "seeds",
            json!({ "minimum": 1, "maximum": crate::sweep::MAX_SEEDS }),
        ),
        ("SweepSpec", "camera", reference("SweepCamera")),
        ("SweepSpec", "dic", reference("DicSettings")),
        (
            "SweepSpec",
            "move_mm",
            json!({ "items": { "type": "number", "minimum": -crate::sweep::MAX_MOVE_MM, "maximum": crate::sweep::MAX_MOVE_MM },
                    "minItems": 2, "maxItems": 2 }),
        ),
        (
            "SweepSpec",
            "axes",
            json!({ "description": format!(
                "The axes; their lengths multiplied by `seeds` give the task count, at most {} (or the daemon's `[sweeps] max_tasks`). Give `dot_diameter_px` or `patterns` (or both).",
                crate::service::job::MAX_DAEMON_SWEEP_TASKS) }),
        ),
        (
            "SweepAxes",
            "dot_diameter_px",
            json!({ "items": { "type": "number", "minimum": 0.5, "maximum": 100 } }),
        ),
        (
            "SweepAxes",
            "patterns",
            json!({ "items": { "type": "string", "enum": ["a", "b", "c"] } }),
        ),
        (
            "SweepAxes",
            "schemes",
            json!({ "items": reference("SchemeSpec"), "minItems": 1, "maxItems": MAX_SCHEMES }),
        ),
        ("SweepAxes", "psf_sigma_px", numbers(0.0, 20.0)),
        (
            "SweepAxes",
            "pixel_aperture",
            json!({ "items": { "type": "array", "minItems": 2, "maxItems": 2,
                               "items": { "type": "number", "exclusiveMinimum": 0, "maximum": 1 } } }),
        ),
        ("SweepAxes", "subpixel_x", numbers(-1.0, 1.0)),
        ("SweepAxes", "subpixel_y", numbers(-1.0, 1.0)),
        (
            "NoiseLevel",
            "full_well_e",
            json!({ "exclusiveMinimum": 0 }),
        ),
        ("NoiseLevel", "read_noise_e", json!({ "minimum": 0 })),
        ("NoiseLevel", "gain", json!({ "exclusiveMinimum": 0 })),
    ]
}

/// `crate::model::Camera` as a sweep's full-resolution sensor.
fn sweep_camera() -> Value {
    let side = crate::service::job::MAX_DAEMON_SENSOR_SIDE_PX;
    let offset = json!({ "type": "number", "minimum": -(side as f64), "maximum": side,
                         "description": "Principal point relative to the image centre, px; within the sensor." });
    json!({
        "type": "object",
        "additionalProperties": false,
        "required": ["width", "height", "scale_px_per_mm"],
        "description": format!("The full-resolution sensor; at most {side} px a side (or the daemon's `[sweeps] max_sensor_side_px`)."),
        "properties": {
            "width": { "type": "integer", "minimum": crate::sweep::MIN_SENSOR_SIDE_PX, "maximum": side },
            "height": { "type": "integer", "minimum": crate::sweep::MIN_SENSOR_SIDE_PX, "maximum": side },
            "scale_px_per_mm": { "type": "number", "minimum": 0.01, "maximum": 10000 },
            "exposure_level": { "type": "number", "exclusiveMinimum": 0, "maximum": 1,
                                "description": "White-background level as a fraction of full scale (default 0.5)." },
            "principal_dx_px": offset.clone(),
            "principal_dy_px": offset
        }
    })
}

fn reference(name: &str) -> Value {
    json!({ "$ref": format!("#/components/schemas/{name}") })
}

/// An odd integer in `[lo, hi]`.
fn odd(lo: usize, hi: usize, description: &str) -> Value {
    json!({ "type": "integer", "minimum": lo, "maximum": hi, "not": { "multipleOf": 2 },
            "description": description })
}

/// A number that may be null (the test is then off), in `[lo, hi]` or `(lo, hi]`.
fn optional_number(lo: f64, exclusive: bool, hi: f64, description: &str) -> Value {
    let bound = if exclusive {
        json!({ "type": "number", "exclusiveMinimum": lo, "maximum": hi })
    } else {
        json!({ "type": "number", "minimum": lo, "maximum": hi })
    };
    json!({ "oneOf": [bound, { "type": "null" }], "description": description })
}

/// `crate::dic::DicSettings`, checked by `DicSettings::validate`.
fn dic_settings() -> Value {
    json!({
        "type": "object",
        "additionalProperties": false,
        "description": "2D DIC settings; every field has a default (the paper's analysis).",
        "properties": {
            "subset_px": odd(5, MAX_SUBSET_PX, "Subset side, px; odd."),
            "step_px": { "type": "integer", "minimum": 1, "maximum": MAX_STEP_PX,
                         "description": "Distance between neighbouring points of interest, px." },
            "roi": { "oneOf": [reference("Roi"), { "type": "null" }],
                     "description": "Rectangle holding the POI centres; null is the centred 800x800, clipped to the image." },
            "strain_window": odd(3, MAX_STRAIN_WINDOW, "Strain window side in POIs; odd."),
            "interpolation": { "type": "string", "enum": ["bspline3", "bspline5"] },
            "shape": { "type": "string", "enum": ["affine", "quadratic"],
                       "description": "Subset shape function: first order (affine) or second order." },
            "prefilter_sigma_px": { "type": "number", "minimum": 0, "maximum": 5,
                                    "description": "Gaussian pre-filter σ, px (0 turns it off)." },
            "convergence_px": { "type": "number", "exclusiveMinimum": 0, "maximum": 1,
                                "description": "IC-GN stops when the update moves the subset less than this, px." },
            "max_iterations": { "type": "integer", "minimum": 1, "maximum": MAX_ITERATIONS },
            "min_zncc": { "type": "number", "minimum": -1, "maximum": 1,
                          "description": "Points whose final ZNCC is below this get status low_correlation." },
            "max_znssd_ratio": optional_number(1.0, false, 1e6,
                "Points whose ZNSSD exceeds this many times the field's median get status low_correlation; null turns the test off."),
            "max_displacement_std_px": { "type": "number", "exclusiveMinimum": 0, "maximum": 100,
                                         "description": "Points whose predicted displacement std exceeds this get status no_texture, px." },
            "outlier_threshold": optional_number(0.0, true, 100.0,
                "Normalised median test threshold (Westerweel & Scarano 2005); null turns the test off."),
            "mask": { "oneOf": [reference("PolygonMask"), { "type": "null" }] },
            "max_motion_px": { "type": "integer", "minimum": 0, "maximum": MAX_MOTION_PX,
                               "description": "Largest rigid motion the global FFT cross-correlation looks for, px." },
            "search_radius_px": { "type": "integer", "minimum": 0, "maximum": MAX_SEARCH_RADIUS_PX,
                                  "description": "Integer search radius where no converged neighbour helps, px." }
        }
    })
}

/// `crate::image::Roi`.
fn roi() -> Value {
    json!({
        "type": "object",
        "additionalProperties": false,
        "required": ["x", "y", "width", "height"],
        "description": "Pixel rectangle: columns x..x+width, rows y..y+height.",
        "properties": {
            "x": { "type": "integer", "minimum": 0, "maximum": MAX_ROI_COORDINATE_PX },
            "y": { "type": "integer", "minimum": 0, "maximum": MAX_ROI_COORDINATE_PX },
            "width": { "type": "integer", "minimum": 1, "maximum": MAX_ROI_COORDINATE_PX },
            "height": { "type": "integer", "minimum": 1, "maximum": MAX_ROI_COORDINATE_PX }
        }
    })
}

/// `ffdic_hw::SensorRoi`: sensor pixels, whatever the camera's size (the camera checks that).
fn sensor_roi() -> Value {
    let side = |lo: u32| json!({ "type": "integer", "minimum": lo, "maximum": u32::MAX });
    json!({
        "type": "object",
        "additionalProperties": false,
        "required": ["x", "y", "width", "height"],
        "properties": { "x": side(0), "y": side(0), "width": side(1), "height": side(1) }
    })
}

fn binning_factor() -> Value {
    json!({ "type": "integer", "minimum": 1, "maximum": crate::api::routes::camera::MAX_BINNING })
}

/// `crate::dic::PolygonMask`, checked by `PolygonMask::validate`.
fn polygon_mask() -> Value {
    let polygon = json!({
        "type": "array",
        "minItems": 3,
        "maxItems": MAX_MASK_VERTICES,
        "items": { "type": "array", "items": { "type": "number" }, "minItems": 2, "maxItems": 2 },
        "description": "Vertices [x, y] in px, at least 3."
    });
    json!({
        "type": "object",
        "additionalProperties": false,
        "description": format!("Polygons bounding the analysed region (at most {MAX_MASK_VERTICES} vertices in all); points outside an include polygon or inside an exclude polygon get status masked."),
        "properties": {
            "include": { "type": "array", "items": polygon.clone() },
            "exclude": { "type": "array", "items": polygon }
        }
    })
}

/// `crate::experiment::PatternSpec`: a preset or a print described in full.
fn pattern_spec() -> Value {
    json!({
        "description": "A preset of the paper (a: 0.5 mm dots at 0.75 mm, b: 0.24 mm at 0.36 mm, c: a defocused, low-contrast a) or a print described in full. Dot diameter and spacing must be at least 0.1 px and 1 px at the bench's scale.",
        "oneOf": [
            { "type": "string", "enum": ["a", "b", "c"] },
            {
                "type": "object",
                "additionalProperties": false,
                "required": ["label", "dot_diameter_mm", "dot_spacing_mm", "contrast"],
                "properties": {
                    "label": { "type": "string", "pattern": PLAIN_ID_PATTERN },
                    "dot_diameter_mm": { "type": "number", "exclusiveMinimum": 0 },
                    "dot_spacing_mm": { "type": "number", "exclusiveMinimum": 0,
                                        "description": "Mean distance between dot centres." },
                    "contrast": { "type": "number", "minimum": 0, "maximum": 1,
                                  "description": "Darkening at a dot centre as a fraction of the background (1 = black dots)." },
                    "edge_softness_mm": { "type": "number", "minimum": 0, "maximum": 10, "default": 0,
                                          "description": "Standard deviation of the print's blur, mm." }
                }
            }
        ]
    })
}

/// `crate::experiment::MoveSpec`.
fn move_spec() -> Value {
    json!({
        "type": "object",
        "additionalProperties": false,
        "required": ["id", "dx_mm"],
        "description": "A stage move from the reference position; within the stage's travel (`GET /stage`). Ids are unique in the request.",
        "properties": {
            "id": { "type": "string", "pattern": PLAIN_ID_PATTERN },
            "dx_mm": { "type": "number" },
            "dy_mm": { "type": "number", "default": 0 }
        }
    })
}

/// `crate::experiment::StepSeries`.
fn step_series() -> Value {
    json!({
        "type": "object",
        "additionalProperties": false,
        "required": ["id", "count"],
        "description": format!("`count` moves of k·step for k = 1..=count, named {{id}}-{{k}}; at most {MAX_MOVES} moves in all, counting `moves`."),
        "properties": {
            "id": { "type": "string", "pattern": PLAIN_ID_PATTERN },
            "dx_step_mm": { "type": "number", "default": 0 },
            "dy_step_mm": { "type": "number", "default": 0 },
            "count": { "type": "integer", "minimum": 0, "maximum": MAX_MOVES }
        }
    })
}

/// `crate::experiment::SchemeSpec`: a reduction scheme by preset name or per axis.
fn scheme_spec() -> Value {
    let axis = json!({
        "type": "object",
        "required": ["block", "first", "active"],
        "additionalProperties": false,
        "properties": {
            "block": { "type": "integer", "minimum": 1, "maximum": MAX_BLOCK_PX },
            "first": { "type": "integer", "minimum": 0, "maximum": MAX_BLOCK_PX - 1 },
            "active": { "type": "integer", "minimum": 1, "maximum": MAX_BLOCK_PX }
        }
    });
    json!({
        "description": "A preset (ff100, ff50, ff25, any case) or per axis: `active` pixels from `first` in every `block`, first + active <= block",
        "oneOf": [
            { "type": "string", "pattern": "^(?i:ff100|ff50|ff25)$" },
            {
                "type": "object",
                "required": ["name", "x", "y"],
                "additionalProperties": false,
                "properties": {
                    "name": { "type": "string", "pattern": r"^[A-Za-z0-9_+\-][A-Za-z0-9_.+\-]{0,63}$" },
                    "x": axis,
                    "y": axis
                }
            }
        ]
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every refinement names a property the derive wrote: a renamed field would otherwise
    /// leave its constraints silently behind.
    #[test]
    fn every_refinement_finds_its_property() {
        let (_, spec) = super::super::openapi::router(1 << 20).split_for_parts();
        let doc = serde_json::to_value(&spec).unwrap();
        for (schema, property, _) in refinements() {
            assert!(
                doc.pointer(&format!(
                    "/components/schemas/{schema}/properties/{property}"
                ))
                .is_some(),
                "{schema}.{property} is not in the document"
            );
        }
    }
}
