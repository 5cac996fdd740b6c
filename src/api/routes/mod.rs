//! Route handlers, one file per resource.

pub mod calibrations;
pub mod camera;
pub mod datasets;
pub mod experiments;
pub mod jobs;
pub mod models;
pub mod perpendicularity;
pub mod stage;
mod submit;
pub mod sweeps;
pub mod system;

use super::problem::ApiError;
pub use submit::queue;

/// Runs a blocking call (the bench actor, the store, TIFF decoding) off the async runtime.
pub async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> T + Send + 'static,
) -> Result<T, ApiError> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| ApiError::internal("a blocking task", e))
}
