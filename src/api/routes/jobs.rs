//! Any run, whatever its kind (experiment, analysis, comparison, diagnosis): its record, its
//! cancellation, its events, its files. The experiment routes are these, restricted to experiments.

use super::blocking;
use crate::api::problem::{ApiError, ApiResult, Problem};
use crate::api::sse::{self, SseResponse};
use crate::service::Service;
use crate::store::{RunId, RunKind, RunRecord, StoreError};
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;

/// Parses an id from the path: anything malformed is simply not found (and never a path).
pub fn run_id(raw: &str) -> ApiResult<RunId> {
    raw.parse()
        .map_err(|_| ApiError::not_found(format!("no run '{}'", truncate(raw))))
}

fn truncate(s: &str) -> String {
    s.chars().take(64).collect()
}

/// The run `id`, which must be of `kind` when one is given.
pub async fn load(svc: &Service, id: &RunId, kind: Option<RunKind>) -> ApiResult<RunRecord> {
    let store = svc.store.clone();
    let key = id.clone();
    let record = blocking(move || store.get(&key)).await??;
    match kind {
        Some(k) if record.kind != k => Err(ApiError::not_found(format!("no {k} '{id}'"))),
        _ => Ok(record),
    }
}

pub async fn cancel(
    svc: &Service,
    id: &RunId,
    kind: Option<RunKind>,
) -> ApiResult<Json<RunRecord>> {
    load(svc, id, kind).await?;
    let jobs = svc.jobs.clone();
    let key = id.clone();
    match blocking(move || jobs.cancel(&key)).await? {
        Ok(r) => Ok(Json(r)),
        Err(StoreError::Finished(_)) => {
            Err(ApiError::conflict(format!("run {id} has already ended")))
        }
        Err(e) => Err(e.into()),
    }
}

/// Deletes ended run `id` (of `kind` when one is given): 204, or 409 while it is queued or
/// running.
pub async fn delete(svc: &Service, id: &RunId, kind: Option<RunKind>) -> ApiResult<StatusCode> {
    load(svc, id, kind).await?;
    let store = svc.store.clone();
    let key = id.clone();
    blocking(move || store.delete_run(&key)).await??;
    Ok(StatusCode::NO_CONTENT)
}

/// The piece a served file is read and sent in.
const FILE_PIECE_BYTES: usize = 64 * 1024;

/// Folders of a run folder a client may read.
const READABLE: [&str; 3] = ["frames", "results", "plots"];

pub async fn file(
    svc: &Service,
    id: &RunId,
    kind: Option<RunKind>,
    folder: &str,
    name: &str,
) -> ApiResult<Response> {
    if !READABLE.contains(&folder) {
        return Err(ApiError::not_found(format!(
            "no folder '{}': frames, results or plots",
            truncate(folder)
        )));
    }
    load(svc, id, kind).await?;
    let rel = format!("{folder}/{name}");
    let store = svc.store.clone();
    let key = id.clone();
    let name = rel.clone();
    let (file, len) = blocking(move || store.open_file(&key, &name)).await??;
    // Streamed in pieces: a client that stops reading holds one piece until the server's write
    // stall timeout closes its connection, not the whole file (80 such readers once held 890 MB).
    let body = axum::body::Body::from_stream(tokio_util::io::ReaderStream::with_capacity(
        tokio::fs::File::from_std(file),
        FILE_PIECE_BYTES,
    ));
    let mime = match rel.rsplit('.').next() {
        Some("json") => "application/json",
        Some("csv") => "text/csv; charset=utf-8",
        Some("svg") => "image/svg+xml",
        Some("tif") | Some("tiff") => "image/tiff",
        Some("png") => "image/png",
        Some("jsonl") => "application/jsonl",
        Some("arrow") => "application/vnd.apache.arrow.file",
        _ => "application/octet-stream",
    };
    Ok((
        [
            (header::CONTENT_TYPE, mime.to_string()),
            (header::CONTENT_LENGTH, len.to_string()),
        ],
        body,
    )
        .into_response())
}

#[utoipa::path(get, path = "/jobs/{id}", tag = "jobs",
    params(("id" = String, Path, description = "Run id")),
    responses((status = 200, body = Object), (status = 404, body = Problem)))]
pub async fn get_job(
    State(svc): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<Json<RunRecord>> {
    Ok(Json(load(&svc, &run_id(&id)?, None).await?))
}

#[utoipa::path(delete, path = "/jobs/{id}", tag = "jobs",
    params(("id" = String, Path, description = "Run id")),
    responses((status = 204, description = "Deleted with its folder (a dataset an experiment registered stays)"),
              (status = 404, body = Problem),
              (status = 409, description = "Queued or running: cancel it first", body = Problem)))]
pub async fn delete_job(
    State(svc): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<StatusCode> {
    delete(&svc, &run_id(&id)?, None).await
}

#[utoipa::path(post, path = "/jobs/{id}/cancel", tag = "jobs",
    params(("id" = String, Path, description = "Run id")),
    responses((status = 200, body = Object), (status = 404, body = Problem),
              (status = 409, description = "Already ended", body = Problem)))]
pub async fn cancel_job(
    State(svc): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<Json<RunRecord>> {
    cancel(&svc, &run_id(&id)?, None).await
}

#[utoipa::path(get, path = "/jobs/{id}/events", tag = "jobs",
    params(("id" = String, Path, description = "Run id"),
           ("Last-Event-ID" = Option<u64>, Header, description = "Resume after this event")),
    responses((status = 200, description = "Server-sent events: each named by its kind (the `EventKind` schema), its data the stored event as JSON (id, run_id, kind, progress, message, at, data); the stream ends after succeeded, failed or cancelled", content_type = "text/event-stream"),
              (status = 404, body = Problem)))]
pub async fn job_events(
    State(svc): State<Service>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult<SseResponse> {
    let id = run_id(&id)?;
    load(&svc, &id, None).await?;
    Ok(sse::stream(svc, id, sse::last_event_id(&headers)?))
}

#[utoipa::path(get, path = "/jobs/{id}/files/{folder}/{name}", tag = "jobs",
    params(("id" = String, Path, description = "Run id"),
           ("folder" = String, Path, description = "frames, results or plots", pattern = "^(frames|results|plots)$"),
           ("name" = String, Path, description = "File name", pattern = r"^[A-Za-z0-9_][A-Za-z0-9._+\-]{0,127}$")),
    responses((status = 200, description = "The file"), (status = 404, body = Problem)))]
pub async fn job_file(
    State(svc): State<Service>,
    Path((id, folder, name)): Path<(String, String, String)>,
) -> ApiResult<Response> {
    file(&svc, &run_id(&id)?, None, &folder, &name).await
}
