//! A job's submission over HTTP: the plan queued off the async threads, an `Idempotency-Key`
//! read, the 202 (or the 200 of a repeated key) written, and a refused submission's status.

use super::blocking;
use crate::api::problem::{ApiError, ApiResult};
use crate::service::job::Job;
use crate::service::{Service, SubmitError};
use crate::store::{RunRecord, MAX_IDEMPOTENCY_KEY_LEN};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;

/// Plans a job with `plan` and queues it (both off the async threads: planning reads the store):
/// 202 and `Location: {location}/{id}`, or 200 and the run made before for a repeated
/// `Idempotency-Key`.
pub async fn queue<J: Job>(
    svc: &Service,
    headers: &HeaderMap,
    location: &'static str,
    plan: impl FnOnce(&Service) -> Result<J, SubmitError> + Send + 'static,
) -> Result<Response, ApiError> {
    let key = idempotency_key(headers)?;
    let s = svc.clone();
    let (record, created) = blocking(move || s.submit(plan(&s)?, key.as_deref())).await??;
    let location = format!("{location}/{}", record.id);
    Ok(accepted(record, created, location))
}

/// The request's `Idempotency-Key`, refused (naming the header) when empty, too long or not
/// visible ASCII.
fn idempotency_key(headers: &HeaderMap) -> ApiResult<Option<String>> {
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
fn accepted(record: RunRecord, created: bool, location: String) -> Response {
    let status = if created {
        StatusCode::ACCEPTED
    } else {
        StatusCode::OK
    };
    (status, [(header::LOCATION, location)], Json(record)).into_response()
}
