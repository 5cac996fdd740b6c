//! Measurement datasets (`ffdic-dataset/1`) made elsewhere: upload, list, and analyse as a job.
//!
//! An upload is `multipart/form-data`: one part `dataset.json` and one part per TIFF, each named
//! by its file name (`curl -F dataset.json=@dataset.json -F b_ref.tif=@b_ref.tif …`). Everything
//! lands in a staging folder first; only a dataset whose manifest is valid and whose every frame
//! decodes is moved into place — anything else leaves nothing behind.

use super::blocking;
use super::experiments::{accepted, idempotency_key};
use crate::api::json::ApiJson;
use crate::api::problem::{ApiError, ApiResult, Problem};
use crate::dataset::{is_plain_file_name, Manifest};
use crate::diagnose::{history_chart, read_history, HistoryEntry};
use crate::image::read_tiff;
use crate::service::{AnalysisRequest, CompareRequest, Service};
use crate::store::{DatasetId, DatasetRecord, RunKind};
use axum::extract::{Multipart, Path, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use tokio::io::AsyncWriteExt;

pub fn dataset_id(raw: &str) -> ApiResult<DatasetId> {
    raw.parse().map_err(|_| {
        ApiError::not_found(format!(
            "no dataset '{}'",
            raw.chars().take(64).collect::<String>()
        ))
    })
}

fn multipart_error(e: axum::extract::multipart::MultipartError) -> ApiError {
    if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "too-large",
            "the upload is larger than the server accepts (max_upload_bytes)",
        )
    } else {
        ApiError::bad_request(format!("malformed multipart body: {}", e.body_text()))
    }
}

#[utoipa::path(post, path = "/datasets", tag = "datasets",
    request_body(content_type = "multipart/form-data",
                 description = "dataset.json and the TIFF frames it names, one part each"),
    responses((status = 201, description = "Stored; Location names it", body = Object),
              (status = 400, body = Problem), (status = 401, body = Problem),
              (status = 413, body = Problem),
              (status = 422, description = "Invalid manifest, missing or corrupt frame", body = Problem)))]
pub async fn upload(State(svc): State<Service>, mut form: Multipart) -> ApiResult<Response> {
    let store = svc.store.clone();
    let staging = blocking(move || store.stage_dataset()).await??;
    let mut names: Vec<String> = Vec::new();
    while let Some(mut field) = form.next_field().await.map_err(multipart_error)? {
        let name = field
            .file_name()
            .or(field.name())
            .unwrap_or_default()
            .to_string();
        if !is_plain_file_name(&name) || name.starts_with('.') || name.len() > 128 {
            return Err(ApiError::invalid(
                "file",
                format!(
                    "'{}' is not a plain file name",
                    name.chars().take(64).collect::<String>()
                ),
            ));
        }
        if names.contains(&name) {
            return Err(ApiError::invalid("file", format!("'{name}' sent twice")));
        }
        let path = staging.path().join(&name);
        let mut file = tokio::fs::File::create(&path)
            .await
            .map_err(|e| ApiError::internal("staging an upload", e))?;
        while let Some(chunk) = field.chunk().await.map_err(multipart_error)? {
            file.write_all(&chunk)
                .await
                .map_err(|e| ApiError::internal("staging an upload", e))?;
        }
        file.sync_all()
            .await
            .map_err(|e| ApiError::internal("staging an upload", e))?;
        names.push(name);
    }
    if !names.iter().any(|n| n == "dataset.json") {
        return Err(ApiError::invalid(
            "dataset.json",
            "the upload has no dataset.json part",
        ));
    }
    let store = svc.store.clone();
    let record = blocking(move || -> ApiResult<DatasetRecord> {
        let manifest = Manifest::read(staging.path())
            .map_err(|e| ApiError::invalid("dataset.json", e.to_string()))?;
        check_frames(staging.path(), &manifest)?;
        let name = manifest.name.clone();
        Ok(store.commit_dataset(staging, &name, "upload")?)
    })
    .await??;
    let location = format!("/api/v1/datasets/{}", record.id);
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, location)],
        Json(record),
    )
        .into_response())
}

/// Every frame the manifest names decodes, and each run's two frames have one size.
fn check_frames(dir: &std::path::Path, m: &Manifest) -> ApiResult<()> {
    let mut sizes = std::collections::HashMap::new();
    for run in &m.runs {
        for name in std::iter::once(&run.reference)
            .chain([&run.deformed])
            .chain(&run.repeat)
        {
            if sizes.contains_key(name) {
                continue;
            }
            let path = dir.join(name);
            if !path.is_file() {
                return Err(ApiError::invalid(
                    "file",
                    format!("run {}: '{name}' was not uploaded", run.id),
                ));
            }
            let (img, _) = read_tiff(&path).map_err(|e| {
                ApiError::invalid(
                    "file",
                    format!("run {}: '{name}': {e}", run.id)
                        .replace(&dir.display().to_string(), ""),
                )
            })?;
            if img.width() < 64 || img.height() < 64 {
                return Err(ApiError::invalid(
                    "file",
                    format!(
                        "'{name}' is {}x{} px; at least 64x64",
                        img.width(),
                        img.height()
                    ),
                ));
            }
            sizes.insert(name.clone(), (img.width(), img.height()));
        }
        if sizes[&run.reference] != sizes[&run.deformed] {
            return Err(ApiError::invalid(
                "file",
                format!("run {}: reference and deformed differ in size", run.id),
            ));
        }
    }
    Ok(())
}

#[utoipa::path(get, path = "/datasets", tag = "datasets",
    responses((status = 200, body = Vec<Object>)))]
pub async fn list(State(svc): State<Service>) -> ApiResult<Json<Vec<DatasetRecord>>> {
    let store = svc.store.clone();
    Ok(Json(blocking(move || store.list_datasets()).await??))
}

#[utoipa::path(get, path = "/datasets/{id}", tag = "datasets",
    params(("id" = String, Path, description = "Dataset id")),
    responses((status = 200, body = Object), (status = 404, body = Problem)))]
pub async fn get(
    State(svc): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<Json<DatasetRecord>> {
    let id = dataset_id(&id)?;
    let store = svc.store.clone();
    Ok(Json(blocking(move || store.get_dataset(&id)).await??))
}

#[utoipa::path(post, path = "/datasets/{id}/analyses", tag = "datasets", request_body = AnalysisRequest,
    params(("id" = String, Path, description = "Dataset id"),
           ("Idempotency-Key" = Option<String>, Header, description = "Repeat-safe submission")),
    responses((status = 202, description = "Queued as a job; Location names it", body = Object),
              (status = 404, body = Problem), (status = 422, body = Problem)))]
pub async fn analyse(
    State(svc): State<Service>,
    Path(id): Path<String>,
    headers: HeaderMap,
    ApiJson(request): ApiJson<AnalysisRequest>,
) -> ApiResult<Response> {
    let id = dataset_id(&id)?;
    let key = idempotency_key(&headers)?;
    let s = svc.clone();
    let (record, created) =
        blocking(move || s.submit_analysis(&id, &request, key.as_deref())).await??;
    let location = format!("/api/v1/jobs/{}", record.id);
    Ok(accepted(record, created, location))
}

#[utoipa::path(post, path = "/datasets/{id}/comparisons", tag = "datasets", request_body = CompareRequest,
    params(("id" = String, Path, description = "Dataset id"),
           ("Idempotency-Key" = Option<String>, Header, description = "Repeat-safe submission")),
    responses((status = 202, description = "Queued as a job; Location names it. Its results/comparison.json and plots/*.svg hold the comparison, which the dataset's history keeps", body = Object),
              (status = 404, body = Problem), (status = 422, body = Problem)))]
pub async fn compare(
    State(svc): State<Service>,
    Path(id): Path<String>,
    headers: HeaderMap,
    ApiJson(request): ApiJson<CompareRequest>,
) -> ApiResult<Response> {
    submit_model_job(svc, RunKind::Comparison, &id, &headers, request).await
}

#[utoipa::path(post, path = "/datasets/{id}/diagnoses", tag = "datasets", request_body = CompareRequest,
    params(("id" = String, Path, description = "Dataset id"),
           ("Idempotency-Key" = Option<String>, Header, description = "Repeat-safe submission")),
    responses((status = 202, description = "Queued as a job; Location names it. Its results/diagnosis.json ranks the candidates; results/winner-model.toml is the model with the verdict added", body = Object),
              (status = 404, body = Problem), (status = 422, body = Problem)))]
pub async fn diagnose(
    State(svc): State<Service>,
    Path(id): Path<String>,
    headers: HeaderMap,
    ApiJson(request): ApiJson<CompareRequest>,
) -> ApiResult<Response> {
    submit_model_job(svc, RunKind::Diagnosis, &id, &headers, request).await
}

/// Queues a comparison or a diagnosis of dataset `raw_id`: 202 + Location of the job.
async fn submit_model_job(
    svc: Service,
    kind: RunKind,
    raw_id: &str,
    headers: &HeaderMap,
    request: CompareRequest,
) -> ApiResult<Response> {
    let id = dataset_id(raw_id)?;
    let key = idempotency_key(headers)?;
    let (record, created) = blocking(move || match kind {
        RunKind::Diagnosis => svc.submit_diagnosis(&id, &request, key.as_deref()),
        _ => svc.submit_comparison(&id, &request, key.as_deref()),
    })
    .await??;
    let location = format!("/api/v1/jobs/{}", record.id);
    Ok(accepted(record, created, location))
}

/// `GET /datasets/{id}/history`: every comparison of the dataset, oldest first.
#[derive(serde::Serialize, utoipa::ToSchema)]
pub struct History {
    pub dataset: String,
    #[schema(value_type = Vec<Object>)]
    pub entries: Vec<HistoryEntry>,
}

async fn read_dataset_history(svc: &Service, raw: &str) -> ApiResult<Vec<HistoryEntry>> {
    let id = dataset_id(raw)?;
    let store = svc.store.clone();
    blocking(move || -> ApiResult<Vec<HistoryEntry>> {
        store.get_dataset(&id)?;
        read_history(&store.dataset_dir(&id))
            .map_err(|e| ApiError::internal("reading a dataset's history", e))
    })
    .await?
}

#[utoipa::path(get, path = "/datasets/{id}/history", tag = "datasets",
    params(("id" = String, Path, description = "Dataset id")),
    responses((status = 200, body = History), (status = 404, body = Problem)))]
pub async fn history(
    State(svc): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<Json<History>> {
    let entries = read_dataset_history(&svc, &id).await?;
    Ok(Json(History {
        dataset: id,
        entries,
    }))
}

#[utoipa::path(get, path = "/datasets/{id}/history.svg", tag = "datasets",
    params(("id" = String, Path, description = "Dataset id")),
    responses((status = 200, description = "The discrepancy across model versions", content_type = "image/svg+xml", body = String),
              (status = 404, body = Problem)))]
pub async fn history_svg(
    State(svc): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<Response> {
    let entries = read_dataset_history(&svc, &id).await?;
    let svg = history_chart(&entries);
    Ok(([(header::CONTENT_TYPE, "image/svg+xml")], svg).into_response())
}
