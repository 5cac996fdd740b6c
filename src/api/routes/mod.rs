//! Route handlers, one file per resource.

pub mod calibrations;
pub mod camera;
pub mod datasets;
pub mod experiments;
pub mod jobs;
pub mod models;
pub mod stage;
pub mod sweeps;
pub mod system;

use super::problem::ApiError;

/// Runs a blocking call (the bench actor, the store, TIFF decoding) off the async runtime.
pub async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> T + Send + 'static,
) -> Result<T, ApiError> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| ApiError::internal("a blocking task", e))
}

/// Plans a job with `plan` and queues it (both off the async threads: planning reads the store):
/// 202 and `Location: {location}/{id}`, or 200 and the run made before for a repeated
/// `Idempotency-Key`.
pub async fn queue<J: crate::service::job::Job>(
    svc: &crate::service::Service,
    headers: &axum::http::HeaderMap,
    location: &'static str,
    plan: impl FnOnce(&crate::service::Service) -> Result<J, crate::service::SubmitError>
        + Send
        + 'static,
) -> Result<axum::response::Response, ApiError> {
    let key = experiments::idempotency_key(headers)?;
    let s = svc.clone();
    let (record, created) = blocking(move || s.submit(plan(&s)?, key.as_deref())).await??;
    let location = format!("{location}/{}", record.id);
    Ok(experiments::accepted(record, created, location))
}
