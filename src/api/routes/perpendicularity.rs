//! Perpendicularity checks: a move back and forth on the bench, the target's tilt and the
//! stage's angle read from the two fields (the dashboard's setup aid). A check is a run like any
//! other: its events, cancellation and files are also under `/jobs/{id}`.

use super::jobs::{file, load, run_id};
use crate::api::json::ApiJson;
use crate::api::problem::{ApiResult, Problem};
use crate::experiment::PerpendicularityCheck;
use crate::service::job::PerpendicularityJob;
use crate::service::Service;
use crate::store::{RunKind, RunRecord};
use axum::extract::{Path, State};
use axum::http::HeaderMap;
use axum::response::Response;
use axum::Json;

#[utoipa::path(post, path = "/perpendicularity-checks", tag = "calibrations", request_body = PerpendicularityCheck,
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
    ApiJson(check): ApiJson<PerpendicularityCheck>,
) -> ApiResult<Response> {
    super::queue(
        &svc,
        &headers,
        "/api/v1/perpendicularity-checks",
        move |s| PerpendicularityJob::plan(s, check),
    )
    .await
}

#[utoipa::path(get, path = "/perpendicularity-checks/{id}", tag = "calibrations",
    params(("id" = String, Path, description = "Perpendicularity check id")),
    responses((status = 200, description = "The run: status, progress, the check as `request`", body = Object),
              (status = 404, body = Problem)))]
pub async fn get(State(svc): State<Service>, Path(id): Path<String>) -> ApiResult<Json<RunRecord>> {
    Ok(Json(
        load(&svc, &run_id(&id)?, Some(RunKind::Perpendicularity)).await?,
    ))
}

#[utoipa::path(get, path = "/perpendicularity-checks/{id}/reading", tag = "calibrations",
    params(("id" = String, Path, description = "Perpendicularity check id")),
    responses((status = 200, description = "The reading: both tilt angles and the stage's angle, each with its standard error, at the bench's working distance (stated or assumed)", body = crate::diagnose::PerpendicularityReading),
              (status = 404, description = "No such check, or no reading yet", body = Problem)))]
pub async fn reading(State(svc): State<Service>, Path(id): Path<String>) -> ApiResult<Response> {
    let id = run_id(&id)?;
    file(
        &svc,
        &id,
        Some(RunKind::Perpendicularity),
        "results",
        "perpendicularity.json",
    )
    .await
}
