//! The routes and the OpenAPI document they make: every handler carries its `#[utoipa::path]`,
//! so the document cannot drift from the router (a test checks it against a snapshot).

use super::problem::Problem;
use super::routes::{
    calibrations, camera, datasets, experiments, jobs, models, perpendicularity, stage, sweeps,
    system,
};
use crate::run_event::EventKind;
use crate::service::Service;
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "ffdic",
        description = "Translation experiments, fill-factor synthesis, 2D DIC and a physical imaging model. \
                       Errors are RFC 9457 problem documents. Mutating requests need `Authorization: Bearer` \
                       when the server has a token.",
    ),
    components(schemas(Problem, EventKind)),
    tags(
        (name = "system", description = "Health and status"),
        (name = "bench", description = "Camera and stage, directly"),
        (name = "experiments", description = "Translation experiments on the bench"),
        (name = "calibrations", description = "Calibration plans on the bench and the camera cards they write; perpendicularity checks"),
        (name = "datasets", description = "Measurements in format ffdic-dataset/1"),
        (name = "jobs", description = "Any run: experiments, analyses, comparisons, diagnoses, on-bench diagnoses, sweeps, calibrations, perpendicularity checks"),
        (name = "models", description = "Analysis models: embedded and added by users"),
        (name = "sweeps", description = "Design maps: error against dot size, fill factor, noise, blur and sub-pixel motion"),
    )
)]
struct ApiDoc;

/// `max_upload_bytes` bounds dataset uploads; every other body has the app's JSON limit.
pub fn router(max_upload_bytes: usize) -> OpenApiRouter<Service> {
    // The route-level limit is the inner layer, so it wins over the app-wide JSON limit.
    let uploads = OpenApiRouter::new()
        .routes(routes!(datasets::upload))
        .layer(axum::extract::DefaultBodyLimit::max(max_upload_bytes));
    let v1 = OpenApiRouter::new()
        .merge(uploads)
        .routes(routes!(system::health))
        .routes(routes!(system::status))
        .routes(routes!(camera::get_camera, camera::patch_camera))
        .routes(routes!(camera::snapshot))
        .routes(routes!(stage::get_stage))
        .routes(routes!(stage::move_stage))
        .routes(routes!(experiments::create, experiments::list))
        .routes(routes!(experiments::get))
        .routes(routes!(experiments::cancel_experiment))
        .routes(routes!(experiments::events))
        .routes(routes!(experiments::results))
        .routes(routes!(experiments::results_csv))
        .routes(routes!(experiments::frame))
        .routes(routes!(experiments::plot))
        .routes(routes!(calibrations::create, calibrations::list))
        .routes(routes!(calibrations::get))
        .routes(routes!(calibrations::card))
        .routes(routes!(perpendicularity::create))
        .routes(routes!(perpendicularity::get))
        .routes(routes!(perpendicularity::reading))
        .routes(routes!(datasets::list))
        .routes(routes!(datasets::get, datasets::delete))
        .routes(routes!(datasets::analyse))
        .routes(routes!(datasets::compare))
        .routes(routes!(datasets::diagnose))
        .routes(routes!(datasets::on_bench))
        .routes(routes!(datasets::history))
        .routes(routes!(datasets::history_svg))
        .routes(routes!(datasets::jobs))
        .routes(routes!(datasets::details))
        .routes(routes!(models::list, models::add))
        .routes(routes!(models::get, models::delete))
        .routes(routes!(sweeps::create, sweeps::list))
        .routes(routes!(sweeps::get))
        .routes(routes!(sweeps::map))
        .routes(routes!(sweeps::map_csv))
        .routes(routes!(sweeps::map_arrow))
        .routes(routes!(sweeps::plot))
        .routes(routes!(jobs::get_job, jobs::delete_job))
        .routes(routes!(jobs::cancel_job))
        .routes(routes!(jobs::job_events))
        .routes(routes!(jobs::job_file));
    OpenApiRouter::with_openapi(ApiDoc::openapi()).nest("/api/v1", v1)
}

/// Statuses any operation can answer before its handler runs (the guard, the token check, the
/// body readers) or when the server fails or stops: documented on every operation, so a client
/// (or schemathesis) finds each status it can meet.
const MIDDLEWARE_STATUSES: [(&str, &str); 6] = [
    ("400", "Malformed request: path, query, headers or body"),
    (
        "401",
        "A token is configured and the request did not carry it",
    ),
    (
        "403",
        "A cross-site request (Origin / Sec-Fetch-Site) on a mutating route",
    ),
    ("421", "A Host header this daemon does not serve"),
    ("500", "Internal error (details in the server log)"),
    (
        "503",
        "The server is stopping, the bench is not answering, or the request took too long",
    ),
];
/// Statuses of operations that take a body.
const BODY_STATUSES: [(&str, &str); 2] = [
    ("413", "The body is larger than the configured limit"),
    (
        "415",
        "The body's Content-Type is not the one the operation takes",
    ),
];

/// Statuses of submissions that take an `Idempotency-Key` (besides the replay's 200).
const IDEMPOTENT_STATUSES: [(&str, &str); 1] = [(
    "409",
    "The Idempotency-Key was used for a different request",
)];
const IDEMPOTENT_REPLAY: &str =
    "The same Idempotency-Key made this run before: that run, unchanged";

/// The upload's parts: `dataset.json` and the frames it names, each under its plain file name
/// (what `is_plain_file_name` and the store accept; any other part is refused).
fn upload_schema() -> serde_json::Value {
    serde_json::json!({
        "type": "object",
        "required": ["dataset.json"],
        "properties": { "dataset.json": { "type": "string", "format": "binary" } },
        "propertyNames": { "pattern": FILE_NAME_PATTERN },
        "additionalProperties": { "type": "string", "format": "binary" }
    })
}

/// A file name in a run or dataset folder, as the routes' path parameters document it.
pub const FILE_NAME_PATTERN: &str = r"^[A-Za-z0-9_][A-Za-z0-9._+\-]{0,127}$";

/// Each submission's links: (from, method, status, to, to's method). Not results: they exist
/// only once the run has succeeded.
const LINKS: [(&str, &str, &str, &str, &str); 13] = [
    (
        "/api/v1/perpendicularity-checks",
        "post",
        "202",
        "/api/v1/perpendicularity-checks/{id}",
        "get",
    ),
    (
        "/api/v1/perpendicularity-checks",
        "post",
        "202",
        "/api/v1/jobs/{id}/cancel",
        "post",
    ),
    (
        "/api/v1/calibrations",
        "post",
        "202",
        "/api/v1/calibrations/{id}",
        "get",
    ),
    (
        "/api/v1/calibrations",
        "post",
        "202",
        "/api/v1/jobs/{id}/cancel",
        "post",
    ),
    (
        "/api/v1/sweeps",
        "post",
        "202",
        "/api/v1/sweeps/{id}",
        "get",
    ),
    (
        "/api/v1/sweeps",
        "post",
        "202",
        "/api/v1/jobs/{id}/cancel",
        "post",
    ),
    (
        "/api/v1/experiments",
        "post",
        "202",
        "/api/v1/experiments/{id}",
        "get",
    ),
    (
        "/api/v1/experiments",
        "post",
        "202",
        "/api/v1/experiments/{id}/events",
        "get",
    ),
    (
        "/api/v1/experiments",
        "post",
        "202",
        "/api/v1/experiments/{id}/cancel",
        "post",
    ),
    (
        "/api/v1/datasets",
        "post",
        "201",
        "/api/v1/datasets/{id}",
        "get",
    ),
    (
        "/api/v1/datasets",
        "post",
        "201",
        "/api/v1/datasets/{id}/analyses",
        "post",
    ),
    (
        "/api/v1/datasets",
        "post",
        "201",
        "/api/v1/datasets/{id}/comparisons",
        "post",
    ),
    (
        "/api/v1/datasets/{id}/analyses",
        "post",
        "202",
        "/api/v1/jobs/{id}",
        "get",
    ),
];

/// OpenAPI links from each submission to what its answer names (the run or dataset `id` in the
/// body), so a client — and schemathesis' stateful phase — can follow them.
fn add_links(paths: &mut serde_json::Map<String, serde_json::Value>) {
    for (from, method, status, to, to_method) in LINKS {
        let operation_ref = format!(
            "#/paths/{}/{to_method}",
            to.replace('~', "~0").replace('/', "~1")
        );
        let name = operation_id(to_method, to);
        if let Some(response) = paths
            .get_mut(from)
            .and_then(|p| p.get_mut(method))
            .and_then(|op| op.get_mut("responses"))
            .and_then(|r| r.get_mut(status))
            .and_then(|r| r.as_object_mut())
        {
            let links = response
                .entry("links")
                .or_insert_with(|| serde_json::json!({}));
            links[name] = serde_json::json!({
                "operationRef": operation_ref,
                "parameters": { "id": "$response.body#/id" }
            });
        }
    }
}

/// An operation's id, and the name of a link to it: method and path without `/api/v1`, every
/// other character `_` (`get_experiments__id__events`).
fn operation_id(method: &str, path: &str) -> String {
    format!("{method}{}", path.trim_start_matches("/api/v1"))
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// The served document from utoipa's: every error response is `application/problem+json` (RFC
/// 9457; utoipa writes `application/json` for any body), and every operation lists the
/// middleware's statuses.
pub fn finish_document(spec: &utoipa::openapi::OpenApi) -> serde_json::Value {
    let mut doc = serde_json::to_value(spec).expect("the OpenAPI document serialises");
    // The request bodies' nested types are bare objects in the derive (they live in the
    // numerics and the experiment layer, which know no OpenAPI): spell them out.
    if let Some(schemas) = doc
        .pointer_mut("/components/schemas")
        .and_then(|s| s.as_object_mut())
    {
        super::request_schemas::apply(schemas);
    }
    let Some(paths) = doc.get_mut("paths").and_then(|p| p.as_object_mut()) else {
        return doc;
    };
    add_links(paths);
    for (path, item) in paths.iter_mut() {
        let Some(item) = item.as_object_mut() else {
            continue;
        };
        for (method, op) in item.iter_mut() {
            if ["get", "post", "patch", "put", "delete"].contains(&method.as_str()) {
                finish_operation(path, method, op);
            }
        }
    }
    doc
}

/// One operation: a unique id, the header parameters as the daemon reads them, which bodies are
/// required, problem+json for every error and the statuses the layers answer before the handler.
fn finish_operation(path: &str, method: &str, op: &mut serde_json::Value) {
    let problem_ref = serde_json::json!({ "$ref": "#/components/schemas/Problem" });
    let problem_content = serde_json::json!({
        "application/problem+json": { "schema": problem_ref.clone() }
    });
    // Unique (utoipa uses the handler's name: three `get`s).
    op["operationId"] = serde_json::Value::String(operation_id(method, path));
    let has_body = op.get("requestBody").is_some();
    let idempotent = op
        .get("parameters")
        .and_then(|p| p.as_array())
        .is_some_and(|ps| ps.iter().any(|p| p["name"] == "Idempotency-Key"));
    if let Some(params) = op.get_mut("parameters").and_then(|p| p.as_array_mut()) {
        for p in params.iter_mut().filter(|p| p["name"] == "Last-Event-ID") {
            // A header is text: "null" is not an id (utoipa writes Option as nullable);
            // ids are u64, and a larger number is refused (400).
            p["schema"] =
                serde_json::json!({ "type": "integer", "minimum": 0, "maximum": u64::MAX });
            p["required"] = serde_json::Value::Bool(false);
        }
    }
    if let Some(body) = op.get_mut("requestBody").and_then(|b| b.as_object_mut()) {
        // JSON bodies may be empty: every field then takes its default (`api::json`).
        // Other bodies (the multipart upload) are required.
        let json = body
            .get("content")
            .and_then(|c| c.as_object())
            .is_some_and(|c| c.contains_key("application/json"));
        body.insert("required".into(), serde_json::Value::Bool(!json));
        if let Some(multipart) = body
            .get_mut("content")
            .and_then(|c| c.get_mut("multipart/form-data"))
        {
            multipart["schema"] = upload_schema();
        }
    }
    let Some(responses) = op.get_mut("responses").and_then(|r| r.as_object_mut()) else {
        return;
    };
    for response in responses.values_mut() {
        let Some(content) = response.get_mut("content").and_then(|c| c.as_object_mut()) else {
            continue;
        };
        let is_problem = content
            .get("application/json")
            .and_then(|j| j.get("schema"))
            .is_some_and(|s| *s == problem_ref);
        if is_problem {
            let body = content.remove("application/json").expect("just seen");
            content.insert("application/problem+json".into(), body);
        }
    }
    // A replayed submission answers what the first one did.
    if idempotent && !responses.contains_key("200") {
        if let Some(content) = responses.get("202").and_then(|r| r.get("content")).cloned() {
            responses.insert(
                "200".into(),
                serde_json::json!({ "description": IDEMPOTENT_REPLAY, "content": content }),
            );
        }
    }
    let extra = MIDDLEWARE_STATUSES
        .iter()
        .chain(if has_body { &BODY_STATUSES[..] } else { &[] })
        .chain(if idempotent {
            &IDEMPOTENT_STATUSES[..]
        } else {
            &[]
        });
    for (status, description) in extra {
        responses.entry(status.to_string()).or_insert_with(
            || serde_json::json!({ "description": description, "content": problem_content }),
        );
    }
}
