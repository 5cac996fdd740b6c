//! Calibrations: run a plan on the bench and get its camera card (`ffdic calibrate` through the
//! daemon). A calibration is a run like any other: its events, cancellation and files are also
//! under `/jobs/{id}`; its frames become a dataset and its card's model a stored model.

use super::experiments::ListQuery;
use super::jobs::{file, load, run_id};
use crate::api::json::ApiJson;
use crate::api::problem::{ApiResult, Problem};
use crate::experiment::CalibrationPlan;
use crate::service::job::CalibrationJob;
use crate::service::Service;
use crate::store::{RunKind, RunRecord};
use axum::extract::{Path, Query, State};
use axum::http::HeaderMap;
use axum::response::Response;
use axum::Json;

#[utoipa::path(post, path = "/calibrations", tag = "calibrations", request_body = CalibrationPlan,
    params(("Idempotency-Key" = Option<String>, Header, description = "Repeat-safe submission")),
    responses((status = 202, description = "Queued on the bench lane; Location names it", body = Object),
              (status = 429, description = "The lane already has jobs.max_queued_per_lane jobs waiting; Retry-After says when to try again", body = Problem),
              (status = 200, description = "Same Idempotency-Key: the run made before", body = Object),
              (status = 400, body = Problem), (status = 401, body = Problem),
              (status = 413, body = Problem), (status = 422, body = Problem),
              (status = 503, body = Problem)))]
pub async fn create(
    State(svc): State<Service>,
    headers: HeaderMap,
    ApiJson(plan): ApiJson<CalibrationPlan>,
) -> ApiResult<Response> {
    super::queue(&svc, &headers, "/api/v1/calibrations", move |s| {
        CalibrationJob::plan(s, plan)
    })
    .await
}

#[utoipa::path(get, path = "/calibrations", tag = "calibrations", params(ListQuery),
    responses((status = 200, description = "Newest first; a full page has a `Link` header (rel=\"next\") to the next one", body = Vec<Object>),
              (status = 422, body = Problem)))]
pub async fn list(State(svc): State<Service>, Query(q): Query<ListQuery>) -> ApiResult<Response> {
    super::experiments::list_runs(&svc, RunKind::Calibration, "/api/v1/calibrations", &q).await
}

#[utoipa::path(get, path = "/calibrations/{id}", tag = "calibrations",
    params(("id" = String, Path, description = "Calibration id")),
    responses((status = 200, description = "The run: status, progress, the plan as `request`, the dataset its frames became", body = Object),
              (status = 404, body = Problem)))]
pub async fn get(State(svc): State<Service>, Path(id): Path<String>) -> ApiResult<Json<RunRecord>> {
    Ok(Json(
        load(&svc, &run_id(&id)?, Some(RunKind::Calibration)).await?,
    ))
}

#[utoipa::path(get, path = "/calibrations/{id}/card", tag = "calibrations",
    params(("id" = String, Path, description = "Calibration id")),
    responses((status = 200, description = "The camera card (`card`: geometry, stage map, imaging chain, each with its standard error and significance; the discrepancy before and with it), the stored model's name (`model`), the diagnosis rounds, the plan and the experiment it became", body = Object),
              (status = 404, description = "No such calibration, or no card yet", body = Problem)))]
pub async fn card(State(svc): State<Service>, Path(id): Path<String>) -> ApiResult<Response> {
    let id = run_id(&id)?;
    file(
        &svc,
        &id,
        Some(RunKind::Calibration),
        "results",
        "card.json",
    )
    .await
}
