//! Experiments: start one (`{}` runs the paper's study), follow it, cancel it, fetch what it made.

use super::jobs::{cancel, file, load, run_id};
use crate::api::json::ApiJson;
use crate::api::problem::{ApiError, ApiResult, Problem};
use crate::api::sse::{self, SseResponse};
use crate::experiment::ExperimentRequest;
use crate::service::{Service, SubmitError};
use crate::store::{RunKind, RunRecord, RunStatus, MAX_IDEMPOTENCY_KEY_LEN};
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::Deserialize;

pub fn idempotency_key(headers: &HeaderMap) -> ApiResult<Option<String>> {
    match headers.get("idempotency-key") {
        None => Ok(None),
        Some(v) => {
            let key = v
                .to_str()
                .ok()
                .filter(|k| !k.is_empty() && k.len() <= MAX_IDEMPOTENCY_KEY_LEN)
                .ok_or_else(|| {
                    ApiError::invalid(
                        "Idempotency-Key",
                        format!("1 to {MAX_IDEMPOTENCY_KEY_LEN} visible ASCII characters"),
                    )
                })?;
            Ok(Some(key.to_string()))
        }
    }
}

/// What a 429 asks a client to wait before submitting again: about one queued job's time.
const RETRY_AFTER_S: u64 = 30;

impl From<SubmitError> for ApiError {
    fn from(e: SubmitError) -> Self {
        match e {
            SubmitError::Field(f) => f.into(),
            SubmitError::NoStage => ApiError::unavailable(e.to_string()),
            SubmitError::Store(s) => s.into(),
            SubmitError::QueueFull { .. } => ApiError::too_many(e.to_string(), RETRY_AFTER_S),
        }
    }
}

/// 202 with `Location` for a new run; 200 with the same run for a repeated Idempotency-Key.
pub fn accepted(record: RunRecord, created: bool, location: String) -> Response {
    let status = if created {
        StatusCode::ACCEPTED
    } else {
        StatusCode::OK
    };
    (status, [(header::LOCATION, location)], Json(record)).into_response()
}

#[utoipa::path(post, path = "/experiments", tag = "experiments", request_body = ExperimentRequest,
    params(("Idempotency-Key" = Option<String>, Header, description = "Repeat-safe submission")),
    responses((status = 202, description = "Queued; Location names it", body = Object),
              (status = 429, description = "The lane already has jobs.max_queued_per_lane jobs waiting; Retry-After says when to try again", body = Problem),
              (status = 200, description = "Same Idempotency-Key: the run made before", body = Object),
              (status = 400, body = Problem), (status = 401, body = Problem),
              (status = 413, body = Problem), (status = 422, body = Problem),
              (status = 503, body = Problem)))]
pub async fn create(
    State(svc): State<Service>,
    headers: HeaderMap,
    ApiJson(request): ApiJson<ExperimentRequest>,
) -> ApiResult<Response> {
    let key = idempotency_key(&headers)?;
    let s = svc.clone();
    let (record, created) =
        super::blocking(move || s.submit_experiment(&request, key.as_deref())).await??;
    let location = format!("/api/v1/experiments/{}", record.id);
    Ok(accepted(record, created, location))
}

#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
pub struct ListQuery {
    /// queued, running, succeeded, failed or cancelled
    #[param(pattern = "^(queued|running|succeeded|failed|cancelled)$")]
    pub status: Option<String>,
    /// At most this many, newest first (default 50, at most 1000).
    #[param(minimum = 1, maximum = 1000)]
    pub limit: Option<u32>,
}

#[utoipa::path(get, path = "/experiments", tag = "experiments", params(ListQuery),
    responses((status = 200, body = Vec<Object>), (status = 422, body = Problem)))]
pub async fn list(
    State(svc): State<Service>,
    Query(q): Query<ListQuery>,
) -> ApiResult<Json<Vec<RunRecord>>> {
    list_runs(&svc, RunKind::Experiment, &q).await
}

/// The runs of `kind`, newest first, filtered and limited as `q` asks.
pub async fn list_runs(
    svc: &Service,
    kind: RunKind,
    q: &ListQuery,
) -> ApiResult<Json<Vec<RunRecord>>> {
    let status = match q.status.as_deref() {
        None => None,
        Some(s) => Some(
            serde_json::from_value::<RunStatus>(serde_json::json!(s)).map_err(|_| {
                ApiError::invalid("status", "queued, running, succeeded, failed or cancelled")
            })?,
        ),
    };
    let limit = q.limit.unwrap_or(50) as usize;
    if !(1..=1000).contains(&limit) {
        return Err(ApiError::invalid("limit", "1 to 1000"));
    }
    let store = svc.store.clone();
    let runs = super::blocking(move || store.list(status, Some(kind), limit)).await??;
    Ok(Json(runs))
}

#[utoipa::path(get, path = "/experiments/{id}", tag = "experiments",
    params(("id" = String, Path, description = "Experiment id")),
    responses((status = 200, body = Object), (status = 404, body = Problem)))]
pub async fn get(State(svc): State<Service>, Path(id): Path<String>) -> ApiResult<Json<RunRecord>> {
    Ok(Json(
        load(&svc, &run_id(&id)?, Some(RunKind::Experiment)).await?,
    ))
}

#[utoipa::path(post, path = "/experiments/{id}/cancel", tag = "experiments",
    params(("id" = String, Path, description = "Experiment id")),
    responses((status = 200, body = Object), (status = 404, body = Problem),
              (status = 409, description = "Already ended", body = Problem)))]
pub async fn cancel_experiment(
    State(svc): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<Json<RunRecord>> {
    cancel(&svc, &run_id(&id)?, Some(RunKind::Experiment)).await
}

#[utoipa::path(get, path = "/experiments/{id}/events", tag = "experiments",
    params(("id" = String, Path, description = "Experiment id"),
           ("Last-Event-ID" = Option<u64>, Header, description = "Resume after this event")),
    responses((status = 200, description = "Server-sent events: each named by its kind (the `EventKind` schema), its data the stored event as JSON (id, run_id, kind, progress, message, at, data); the stream ends after succeeded, failed or cancelled",
               content_type = "text/event-stream"),
              (status = 404, body = Problem)))]
pub async fn events(
    State(svc): State<Service>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult<SseResponse> {
    let id = run_id(&id)?;
    load(&svc, &id, Some(RunKind::Experiment)).await?;
    Ok(sse::stream(svc, id, sse::last_event_id(&headers)?))
}

#[utoipa::path(get, path = "/experiments/{id}/results", tag = "experiments",
    params(("id" = String, Path, description = "Experiment id")),
    responses((status = 200, description = "The study: one row per pattern, move and scheme", body = Object),
              (status = 404, description = "No such experiment, or no results yet", body = Problem)))]
pub async fn results(State(svc): State<Service>, Path(id): Path<String>) -> ApiResult<Response> {
    let id = run_id(&id)?;
    file(
        &svc,
        &id,
        Some(RunKind::Experiment),
        "results",
        "study.json",
    )
    .await
}

#[utoipa::path(get, path = "/experiments/{id}/results.csv", tag = "experiments",
    params(("id" = String, Path, description = "Experiment id")),
    responses((status = 200, description = "The study as CSV", content_type = "text/csv"),
              (status = 404, body = Problem)))]
pub async fn results_csv(
    State(svc): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<Response> {
    let id = run_id(&id)?;
    file(&svc, &id, Some(RunKind::Experiment), "results", "study.csv").await
}

#[utoipa::path(get, path = "/experiments/{id}/frames/{name}", tag = "experiments",
    params(("id" = String, Path, description = "Experiment id"),
           ("name" = String, Path, description = "Frame file, e.g. b_ref.tif, or dataset.json", pattern = r"^[A-Za-z0-9_][A-Za-z0-9._+\-]{0,127}$")),
    responses((status = 200, description = "16-bit TIFF", content_type = "image/tiff"),
              (status = 404, body = Problem)))]
pub async fn frame(
    State(svc): State<Service>,
    Path((id, name)): Path<(String, String)>,
) -> ApiResult<Response> {
    let id = run_id(&id)?;
    file(&svc, &id, Some(RunKind::Experiment), "frames", &name).await
}

#[utoipa::path(get, path = "/experiments/{id}/plots/{name}", tag = "experiments",
    params(("id" = String, Path, description = "Experiment id"),
           ("name" = String, Path, description = "figure5_u.svg, figure5_exx.svg, figure6_v.svg, figure6_eyy.svg", pattern = r"^[A-Za-z0-9_][A-Za-z0-9._+\-]{0,127}$")),
    responses((status = 200, description = "SVG", content_type = "image/svg+xml"),
              (status = 404, body = Problem)))]
pub async fn plot(
    State(svc): State<Service>,
    Path((id, name)): Path<(String, String)>,
) -> ApiResult<Response> {
    let id = run_id(&id)?;
    file(&svc, &id, Some(RunKind::Experiment), "plots", &name).await
}
