//! `GET /health` (no hardware I/O: a load balancer may call it every second) and `GET /status`.

use super::blocking;
use crate::api::problem::{ApiResult, Problem};
use crate::service::Service;
use crate::store::{RunKind, RunStatus};
use axum::extract::State;
use axum::http::StatusCode;
use axum::Json;
use serde::Serialize;
use serde_json::Value;

#[derive(Serialize, utoipa::ToSchema)]
pub struct Health {
    /// `ok`, or `degraded` when a part of the daemon has stopped (then the status is 503).
    pub status: &'static str,
    pub version: &'static str,
    /// What has stopped: `bench` (the actor owning camera and stage), `stage` (its last call
    /// found it disconnected; its port is opened again at the next call), `lane:bench`,
    /// `lane:compute` (the job workers). Empty when all is well.
    pub stopped: Vec<String>,
}

#[utoipa::path(get, path = "/health", tag = "system",
    responses((status = 200, description = "The server is up", body = Health),
              (status = 503, description = "A part of the daemon has stopped", body = Health)))]
pub async fn health(State(svc): State<Service>) -> (StatusCode, Json<Health>) {
    let mut stopped: Vec<String> = Vec::new();
    if !svc.bench.is_alive() {
        stopped.push("bench".into());
    }
    if svc.limits.has_stage() && !svc.bench.stage_connected() {
        stopped.push("stage".into());
    }
    for lane in svc.jobs.dead_lanes() {
        stopped.push(format!("lane:{}", format!("{lane:?}").to_lowercase()));
    }
    let status = if stopped.is_empty() {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    let health = Health {
        status: if stopped.is_empty() { "ok" } else { "degraded" },
        version: crate::VERSION,
        stopped,
    };
    (status, Json(health))
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
