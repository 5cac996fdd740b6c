//! Design maps through the daemon: start a sweep, list them, fetch one's map. A sweep is a run
//! like any other: its events, cancellation and files are under `/jobs/{id}`.

use super::experiments::ListQuery;
use super::jobs::{file, load, run_id};
use crate::api::json::ApiJson;
use crate::api::problem::{ApiResult, Problem};
use crate::service::job::SweepJob;
use crate::service::Service;
use crate::store::{RunKind, RunRecord};
use crate::sweep::SweepSpec;
use axum::extract::{Path, Query, State};
use axum::http::HeaderMap;
use axum::response::Response;
use axum::Json;

#[utoipa::path(post, path = "/sweeps", tag = "sweeps", request_body = SweepSpec,
    params(("Idempotency-Key" = Option<String>, Header, description = "Repeat-safe submission")),
    responses((status = 202, description = "Queued on the compute lane; Location names it", body = Object),
              (status = 429, description = "The lane already has jobs.max_queued_per_lane jobs waiting; Retry-After says when to try again", body = Problem),
              (status = 200, description = "Same Idempotency-Key: the run made before", body = Object),
              (status = 400, body = Problem), (status = 401, body = Problem),
              (status = 413, body = Problem), (status = 422, body = Problem)))]
pub async fn create(
    State(svc): State<Service>,
    headers: HeaderMap,
    ApiJson(spec): ApiJson<SweepSpec>,
) -> ApiResult<Response> {
    super::queue(&svc, &headers, "/api/v1/sweeps", move |s| {
        SweepJob::plan(s, spec)
    })
    .await
}

#[utoipa::path(get, path = "/sweeps", tag = "sweeps", params(ListQuery),
    responses((status = 200, description = "Newest first; a full page has a `Link` header (rel=\"next\") to the next one", body = Vec<Object>),
              (status = 422, body = Problem)))]
pub async fn list(State(svc): State<Service>, Query(q): Query<ListQuery>) -> ApiResult<Response> {
    super::experiments::list_runs(&svc, RunKind::Sweep, "/api/v1/sweeps", &q).await
}

#[utoipa::path(get, path = "/sweeps/{id}", tag = "sweeps",
    params(("id" = String, Path, description = "Sweep id")),
    responses((status = 200, description = "The run: status, progress, the spec as `request`", body = Object),
              (status = 404, body = Problem)))]
pub async fn get(State(svc): State<Service>, Path(id): Path<String>) -> ApiResult<Json<RunRecord>> {
    Ok(Json(load(&svc, &run_id(&id)?, Some(RunKind::Sweep)).await?))
}

#[utoipa::path(get, path = "/sweeps/{id}/map", tag = "sweeps",
    params(("id" = String, Path, description = "Sweep id")),
    responses((status = 200, description = "The merged map: one cell per combination of the axes but the seed, each statistic's mean and 95 % interval, the recommendations and the figures' names", body = Object),
              (status = 404, description = "No such sweep, or not merged yet", body = Problem)))]
pub async fn map(State(svc): State<Service>, Path(id): Path<String>) -> ApiResult<Response> {
    result_file(&svc, &id, "map.json").await
}

#[utoipa::path(get, path = "/sweeps/{id}/map.csv", tag = "sweeps",
    params(("id" = String, Path, description = "Sweep id")),
    responses((status = 200, description = "The map as CSV, one row per cell", content_type = "text/csv"),
              (status = 404, body = Problem)))]
pub async fn map_csv(State(svc): State<Service>, Path(id): Path<String>) -> ApiResult<Response> {
    result_file(&svc, &id, "map.csv").await
}

#[utoipa::path(get, path = "/sweeps/{id}/map.arrow", tag = "sweeps",
    params(("id" = String, Path, description = "Sweep id")),
    responses((status = 200, description = "The map as an Arrow IPC file: the CSV's columns, typed, nulls for NaN", content_type = "application/vnd.apache.arrow.file"),
              (status = 404, body = Problem)))]
pub async fn map_arrow(State(svc): State<Service>, Path(id): Path<String>) -> ApiResult<Response> {
    result_file(&svc, &id, "map.arrow").await
}

/// One of a sweep's merged files in `results/`.
async fn result_file(svc: &Service, id: &str, name: &str) -> ApiResult<Response> {
    file(svc, &run_id(id)?, Some(RunKind::Sweep), "results", name).await
}

#[utoipa::path(get, path = "/sweeps/{id}/plots/{name}", tag = "sweeps",
    params(("id" = String, Path, description = "Sweep id"),
           ("name" = String, Path, description = "A figure named in the map's `figures`: map_u_std_px_0.svg, bias_u_ff50_0.svg, …", pattern = r"^[A-Za-z0-9_][A-Za-z0-9._+\-]{0,127}$")),
    responses((status = 200, description = "SVG", content_type = "image/svg+xml"),
              (status = 404, body = Problem)))]
pub async fn plot(
    State(svc): State<Service>,
    Path((id, name)): Path<(String, String)>,
) -> ApiResult<Response> {
    file(&svc, &run_id(&id)?, Some(RunKind::Sweep), "plots", &name).await
}
