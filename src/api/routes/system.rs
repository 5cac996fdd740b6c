//! `GET /health` (no hardware I/O: a load balancer may call it every second) and `GET /status`.

use super::blocking;
use crate::api::problem::{ApiResult, Problem};
use crate::service::Service;
use crate::store::{RunKind, RunStatus};
use axum::extract::State;
use axum::Json;
use serde::Serialize;
use serde_json::Value;

#[derive(Serialize, utoipa::ToSchema)]
pub struct Health {
    pub status: &'static str,
    pub version: &'static str,
}

#[utoipa::path(get, path = "/health", tag = "system",
    responses((status = 200, description = "The server is up", body = Health)))]
pub async fn health() -> Json<Health> {
    Json(Health {
        status: "ok",
        version: crate::VERSION,
    })
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct Status {
    pub version: &'static str,
    /// Camera, stage and who holds the bench.
    #[schema(value_type = Object)]
    pub bench: Value,
    pub experiments_queued: usize,
    pub experiments_running: usize,
    pub data_dir: String,
}

#[utoipa::path(get, path = "/status", tag = "system",
    responses((status = 200, description = "Bench and queue", body = Status),
              (status = 503, description = "Hardware unavailable", body = Problem),
              (status = 504, description = "Hardware timeout", body = Problem)))]
pub async fn status(State(svc): State<Service>) -> ApiResult<Json<Status>> {
    let bench = svc.bench.clone();
    let s = blocking(move || bench.status()).await??;
    let count = |st| {
        svc.store
            .list(Some(st), Some(RunKind::Experiment), usize::MAX)
            .map(|v| v.len())
    };
    Ok(Json(Status {
        version: crate::VERSION,
        bench: serde_json::to_value(s).expect("status serialises"),
        experiments_queued: count(RunStatus::Queued)?,
        experiments_running: count(RunStatus::Running)?,
        data_dir: svc.config.data_dir.display().to_string(),
    }))
}
