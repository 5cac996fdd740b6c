//! Analysis models: the embedded ones and those users added (a diagnosis's winner, say). A model
//! name is its version for good: adding a changed model under a stored name is a conflict.

use super::blocking;
use crate::api::json::ApiJson;
use crate::api::problem::{ApiError, ApiResult, Problem};
use crate::service::{ModelDetail, ModelStoreError, ModelSummary, NewModel, Service};
use axum::extract::{Path, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;

impl From<ModelStoreError> for ApiError {
    fn from(e: ModelStoreError) -> Self {
        match e {
            ModelStoreError::Invalid(m) => ApiError::invalid("toml", m),
            ModelStoreError::Reserved(_) => ApiError::conflict(e.to_string()),
            ModelStoreError::NotFound(_) => ApiError::not_found(e.to_string()),
            ModelStoreError::Store(s) => s.into(),
        }
    }
}

#[utoipa::path(get, path = "/models", tag = "models",
    responses((status = 200, body = Vec<ModelSummary>)))]
pub async fn list(State(svc): State<Service>) -> ApiResult<Json<Vec<ModelSummary>>> {
    Ok(Json(blocking(move || svc.models()).await??))
}

#[utoipa::path(get, path = "/models/{name}", tag = "models",
    params(("name" = String, Path, description = "Model name", pattern = r"^[A-Za-z0-9_+.\-]{1,96}$")),
    responses((status = 200, body = ModelDetail), (status = 404, body = Problem)))]
pub async fn get(
    State(svc): State<Service>,
    Path(name): Path<String>,
) -> ApiResult<Json<ModelDetail>> {
    // A name no model can have names no model: 404, as for any other absent one.
    Ok(Json(blocking(move || svc.model(&name)).await?.map_err(
        |e| match e {
            ModelStoreError::Invalid(m) => ApiError::not_found(m),
            other => other.into(),
        },
    )?))
}

#[utoipa::path(post, path = "/models", tag = "models", request_body = NewModel,
    responses((status = 201, description = "Stored; Location names it", body = ModelDetail),
              (status = 200, description = "The identical model was already stored", body = ModelDetail),
              (status = 400, body = Problem), (status = 401, body = Problem),
              (status = 409, description = "The name is embedded or holds another model", body = Problem),
              (status = 422, description = "Not a valid model; the message names the key", body = Problem)))]
pub async fn add(
    State(svc): State<Service>,
    ApiJson(new): ApiJson<NewModel>,
) -> ApiResult<Response> {
    let (detail, created) = blocking(move || svc.add_model(&new)).await??;
    let status = if created {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    let location = format!("/api/v1/models/{}", detail.summary.name);
    Ok((status, [(header::LOCATION, location)], Json(detail)).into_response())
}

#[utoipa::path(delete, path = "/models/{name}", tag = "models",
    params(("name" = String, Path, description = "Model name", pattern = r"^[A-Za-z0-9_+.\-]{1,96}$")),
    responses((status = 204, description = "Deleted: out of the list; its name stays its text's (the same text may be added again, another may not)"),
              (status = 404, body = Problem),
              (status = 409, description = "An embedded model, or one a queued or running run names", body = Problem)))]
pub async fn delete(State(svc): State<Service>, Path(name): Path<String>) -> ApiResult<StatusCode> {
    blocking(move || svc.delete_model(&name))
        .await?
        .map_err(|e| match e {
            ModelStoreError::Invalid(m) => ApiError::not_found(m),
            other => other.into(),
        })?;
    Ok(StatusCode::NO_CONTENT)
}
