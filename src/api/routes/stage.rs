//! The stage: where it is, and moves (absolute or relative, waiting until it has settled).

use super::blocking;
use crate::api::json::ApiJson;
use crate::api::problem::{ApiError, ApiResult, Problem};
use crate::bench::{Owner, StageAxis};
use crate::service::Service;
use axum::extract::State;
use axum::Json;
use ffdic_hw::StagePosition;
use serde::Deserialize;
use serde_json::Value;
use std::time::Duration;

#[utoipa::path(get, path = "/stage", tag = "bench",
    responses((status = 200, description = "Stage info (model, axes, travel per axis, resolution_mm: the step a move is commanded in — a requested move is rounded to it), position, homed", body = Object),
              (status = 503, description = "No stage configured", body = Problem)))]
pub async fn get_stage(State(svc): State<Service>) -> ApiResult<Json<Value>> {
    let bench = svc.bench.clone();
    let status = blocking(move || bench.status()).await??;
    let stage = status
        .stage
        .ok_or_else(|| ApiError::unavailable("no stage is configured"))?;
    Ok(Json(
        serde_json::to_value(stage).expect("stage status serialises"),
    ))
}

/// A move: absolute (`x_mm`, `y_mm`) or relative (`dx_mm`, `dy_mm`), or `home: true`.
#[derive(Debug, Default, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct StageMoveRequest {
    pub x_mm: Option<f64>,
    pub y_mm: Option<f64>,
    pub dx_mm: Option<f64>,
    pub dy_mm: Option<f64>,
    #[serde(default)]
    pub home: bool,
}

#[utoipa::path(post, path = "/stage/moves", tag = "bench", request_body = StageMoveRequest,
    responses((status = 200, description = "Where the stage settled", body = Object),
              (status = 409, description = "An experiment holds the bench", body = Problem),
              (status = 422, description = "Outside the travel, or a bad request", body = Problem),
              (status = 503, body = Problem), (status = 504, body = Problem)))]
pub async fn move_stage(
    State(svc): State<Service>,
    ApiJson(m): ApiJson<StageMoveRequest>,
) -> ApiResult<Json<StagePosition>> {
    let absolute = m.x_mm.is_some() || m.y_mm.is_some();
    let relative = m.dx_mm.is_some() || m.dy_mm.is_some();
    if absolute && relative {
        return Err(ApiError::invalid(
            "dx_mm",
            "give an absolute (x_mm, y_mm) or a relative (dx_mm, dy_mm) move, not both",
        ));
    }
    if !absolute && !relative && !m.home {
        return Err(ApiError::invalid(
            "x_mm",
            "give x_mm/y_mm, dx_mm/dy_mm or home: true",
        ));
    }
    for (field, v) in [
        ("x_mm", m.x_mm),
        ("y_mm", m.y_mm),
        ("dx_mm", m.dx_mm),
        ("dy_mm", m.dy_mm),
    ] {
        if v.is_some_and(|v| !v.is_finite()) {
            return Err(ApiError::invalid(field, "must be a finite number"));
        }
    }
    // An absolute target is checked against the travel here; a relative one depends on where
    // the stage is, and the driver refuses it (422) before moving.
    if absolute {
        let (x, y) = (m.x_mm.unwrap_or(0.0), m.y_mm.unwrap_or(0.0));
        svc.limits.check_move(x, y).map_err(|e| {
            let field = match e.axis {
                StageAxis::X => "x_mm",
                StageAxis::Y => "y_mm",
            };
            ApiError::invalid(field, e.reason)
        })?;
    }
    let bench = svc.bench.clone();
    let t = svc.timeouts();
    let settled = blocking(move || {
        if m.home {
            bench.home(Owner::Direct, t.home)?;
        }
        if absolute {
            let here = bench
                .status()?
                .stage
                .and_then(|s| s.position)
                .unwrap_or_default();
            let target = StagePosition {
                x_mm: m.x_mm.unwrap_or(here.x_mm),
                y_mm: m.y_mm.unwrap_or(here.y_mm),
            };
            bench.move_to(Owner::Direct, target, t.settle)
        } else if relative {
            bench.move_by(
                Owner::Direct,
                m.dx_mm.unwrap_or(0.0),
                m.dy_mm.unwrap_or(0.0),
                t.settle,
            )
        } else {
            bench.move_by(Owner::Direct, 0.0, 0.0, Duration::from_secs(1))
        }
    })
    .await??;
    Ok(Json(settled))
}
