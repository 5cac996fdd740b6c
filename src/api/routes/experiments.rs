//! Experiments: start one (`{}` runs the paper's study), follow it, cancel it, fetch what it made.

use super::jobs::{cancel, file, load, run_id};
use crate::api::json::ApiJson;
use crate::api::page;
use crate::api::problem::{ApiError, ApiResult, Problem};
use crate::api::sse::{self, SseResponse};
use crate::experiment::ExperimentRequest;
use crate::service::job::ExperimentJob;
use crate::service::Service;
use crate::store::{RunKind, RunRecord, RunStatus};
use axum::extract::{Path, Query, State};
use axum::http::HeaderMap;
use axum::response::Response;
use axum::Json;
use serde::Deserialize;

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
    super::queue(&svc, &headers, "/api/v1/experiments", move |s| {
        ExperimentJob::plan(s, request)
    })
    .await
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
    /// Where the page begins: the cursor a full page's `Link: <…>; rel="next"` carries.
    #[param(
        pattern = r"^[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9]{2}:[0-9]{2}:[0-9]{2}\.[0-9]{3}Z_[a-z0-9][a-z0-9-]{0,63}$"
    )]
    pub after: Option<String>,
}

#[utoipa::path(get, path = "/experiments", tag = "experiments", params(ListQuery),
    responses((status = 200, description = "Newest first; a full page has a `Link` header (rel=\"next\") to the next one", body = Vec<Object>),
              (status = 422, body = Problem)))]
pub async fn list(State(svc): State<Service>, Query(q): Query<ListQuery>) -> ApiResult<Response> {
    list_runs(&svc, RunKind::Experiment, "/api/v1/experiments", &q).await
}

/// A page of the runs of `kind` (listed at `path`), newest first, filtered as `q` asks.
pub async fn list_runs(
    svc: &Service,
    kind: RunKind,
    path: &'static str,
    q: &ListQuery,
) -> ApiResult<Response> {
    let status = match q.status.as_deref() {
        None => None,
        Some(s) => Some(
            serde_json::from_value::<RunStatus>(serde_json::json!(s)).map_err(|_| {
                ApiError::invalid("status", "queued, running, succeeded, failed or cancelled")
            })?,
        ),
    };
    let limit = page::limit(q.limit)?;
    let after = page::after(q.after.as_deref())?;
    let store = svc.store.clone();
    let runs = super::blocking(move || store.list_page(status, Some(kind), limit, after.as_ref()))
        .await??;
    let status = status.map_or(String::new(), |s| format!("&status={s}"));
    Ok(page::page(
        runs,
        limit,
        |after| format!("{path}?limit={limit}{status}&after={after}"),
        |r: &RunRecord| (r.created_at.as_str(), r.id.as_str()),
    ))
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
