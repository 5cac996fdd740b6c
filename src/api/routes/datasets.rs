//! Measurement datasets (`ffdic-dataset/1`) made elsewhere: upload, list, and analyse as a job.
//!
//! An upload is `multipart/form-data`: one part `dataset.json` and one part per frame (TIFF, PNG
//! or BMP), each named by its file name (`curl -F dataset.json=@dataset.json -F
//! b_ref.tif=@b_ref.tif …`). Everything lands in a staging folder first; only a dataset whose
//! manifest is valid and whose every frame decodes is moved into place — anything else leaves
//! nothing behind.

use super::blocking;
use crate::api::json::ApiJson;
use crate::api::page;
use crate::api::problem::{ApiError, ApiResult, Problem};
use crate::dataset::{check_frames, is_plain_file_name, FrameCheckError, Manifest};
use crate::diagnose::{read_history, HistoryEntry};
use crate::image::read_image_header;
use crate::report::history_chart;
use crate::service::job::{
    dataset_page_row, AnalysisJob, AnalysisRequest, CompareRequest, ComparisonJob, DatasetPageRow,
    DiagnosisJob, OnBenchJob,
};
use crate::service::Service;
use crate::store::{DatasetId, DatasetRecord, DatasetSource, RunKind};
use axum::extract::{Multipart, Path, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use tokio::io::AsyncWriteExt;
use tokio_util::sync::CancellationToken;

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
                 description = "dataset.json and the frames it names (TIFF, PNG or BMP), one part each"),
    responses((status = 201, description = "Stored; Location names it", body = Object),
              (status = 400, body = Problem), (status = 401, body = Problem),
              (status = 408, description = "The upload was slower than uploads.min_bytes_per_s or took longer than uploads.deadline_ms", body = Problem),
              (status = 413, body = Problem),
              (status = 507, description = "The stored datasets and this upload would pass datasets_quota_bytes", body = Problem),
              (status = 422, description = "Invalid manifest, missing, corrupt or oversized frame, too many runs", body = Problem)))]
pub async fn upload(State(svc): State<Service>, mut form: Multipart) -> ApiResult<Response> {
    let store = svc.store.clone();
    let (staging, used_bytes) = blocking(move || -> Result<_, crate::store::StoreError> {
        Ok((store.stage_dataset()?, store.datasets_bytes()?))
    })
    .await??;
    let mut pace = UploadPace::new(&svc.config.uploads, svc.uploads_in_flight.clone());
    let quota_bytes = svc.config.datasets_quota_bytes;
    let names = stage_parts(&mut form, &staging, &mut pace, (used_bytes, quota_bytes)).await?;
    // One upload's frames are checked at a time (a check holds up to two decoded frames); the
    // permit travels with the check, which outlives this future if the client leaves.
    let permit = svc
        .frame_checks
        .clone()
        .acquire_owned()
        .await
        .map_err(|e| ApiError::internal("waiting for the frame check", e))?;
    // Cancelled when this future is dropped (the client left): the check stops at its next
    // frame and the staging folder goes with it.
    let abandoned = CancellationToken::new();
    let _abandon_on_drop = abandoned.clone().drop_guard();
    let store = svc.store.clone();
    let limits = svc.config.uploads.frames();
    let own_bytes = pace.received_bytes;
    let record = blocking(move || -> ApiResult<DatasetRecord> {
        let _permit = permit;
        let manifest = Manifest::read(staging.path())
            .map_err(|e| ApiError::invalid("dataset.json", e.without_folder()))?;
        // A dataset holds what its manifest names: a stray part would be kept, counted against
        // the quota and never read.
        let named: std::collections::HashSet<&str> = manifest
            .runs
            .iter()
            .flat_map(|r| {
                [r.reference.as_str(), r.deformed.as_str()]
                    .into_iter()
                    .chain(r.repeat.iter().map(String::as_str))
            })
            .chain(["dataset.json"])
            .collect();
        if let Some(stray) = names.iter().find(|n| !named.contains(n.as_str())) {
            return Err(ApiError::invalid(
                "file",
                format!(
                    "'{stray}' is not named by dataset.json: send only the manifest and its frames"
                ),
            ));
        }
        let left = || abandoned.is_cancelled();
        // Held again at the commit, against what is stored now: checks and commits run one at
        // a time (the permit), so the stored datasets never pass the quota together.
        let stored = store.datasets_bytes()?;
        if stored + own_bytes > quota_bytes {
            return Err(over_quota(stored, own_bytes, quota_bytes));
        }
        check_frames(staging.path(), &manifest, limits, &left).map_err(|e| {
            if matches!(e, FrameCheckError::Abandoned) {
                tracing::info!("an upload's client left during its check: nothing kept");
            }
            ApiError::invalid(e.field(), e.to_string())
        })?;
        if left() {
            tracing::info!("an upload's client left before its commit: nothing kept");
            return Err(ApiError::invalid("file", "the client left"));
        }
        let name = manifest.name.clone();
        Ok(store.commit_dataset(staging, &name, DatasetSource::Upload)?)
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

/// Writes every part of the upload into `staging` as it arrives, at the upload's pace and within
/// the datasets quota (`(used, quota)` bytes); the names of the parts.
async fn stage_parts(
    form: &mut Multipart,
    staging: &crate::store::StagingDir,
    pace: &mut UploadPace,
    (used_bytes, quota_bytes): (u64, u64),
) -> ApiResult<Vec<String>> {
    let mut names: Vec<String> = Vec::new();
    while let Some(mut field) = pace
        .within(form.next_field())
        .await?
        .map_err(multipart_error)?
    {
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
        let staging_error = |e| staging_failed(&path, e);
        let mut file = tokio::fs::File::create(&path)
            .await
            .map_err(staging_error)?;
        while let Some(chunk) = pace.within(field.chunk()).await?.map_err(multipart_error)? {
            // Refused as soon as the stored datasets and every upload in progress would pass
            // the quota: the staging folder goes with it.
            let all_staged = pace.received(chunk.len());
            if used_bytes + all_staged > quota_bytes {
                return Err(over_quota(used_bytes, all_staged, quota_bytes));
            }
            file.write_all(&chunk).await.map_err(staging_error)?;
        }
        file.sync_all().await.map_err(staging_error)?;
        names.push(name);
    }
    if !names.iter().any(|n| n == "dataset.json") {
        return Err(ApiError::invalid(
            "dataset.json",
            "the upload has no dataset.json part",
        ));
    }
    Ok(names)
}

/// An upload's pace: every piece must arrive before the upload falls below
/// `min_bytes_per_s` on average (after `grace_ms`) or passes `deadline_ms` in all. The body
/// timeout alone (30 s between pieces) let a client sending a byte every 20 s hold its
/// connection for as long as it liked.
struct UploadPace {
    started: tokio::time::Instant,
    received_bytes: u64,
    /// Every upload's bytes so far ([`Service::uploads_in_flight`]): this one's are added as
    /// they arrive and given back when it ends, whichever way (they are then stored or removed).
    all_in_flight: std::sync::Arc<std::sync::atomic::AtomicU64>,
    min_bytes_per_s: u64,
    grace: std::time::Duration,
    deadline: std::time::Duration,
}

impl UploadPace {
    fn new(
        limits: &crate::service::UploadLimits,
        all_in_flight: std::sync::Arc<std::sync::atomic::AtomicU64>,
    ) -> Self {
        Self {
            started: tokio::time::Instant::now(),
            received_bytes: 0,
            all_in_flight,
            min_bytes_per_s: limits.min_bytes_per_s.max(1),
            grace: std::time::Duration::from_millis(limits.grace_ms),
            deadline: std::time::Duration::from_millis(limits.deadline_ms),
        }
    }

    /// Counts `bytes` more of this upload; every upload's bytes so far, together.
    fn received(&mut self, bytes: usize) -> u64 {
        self.received_bytes += bytes as u64;
        self.all_in_flight
            .fetch_add(bytes as u64, std::sync::atomic::Ordering::SeqCst)
            + bytes as u64
    }

    /// When the next piece is due: the bytes so far cover the pace until then.
    fn due(&self) -> tokio::time::Instant {
        let covered = std::time::Duration::from_secs_f64(
            self.received_bytes as f64 / self.min_bytes_per_s as f64,
        );
        self.started + self.grace.max(covered).min(self.deadline)
    }

    async fn within<T>(&self, piece: impl std::future::Future<Output = T>) -> ApiResult<T> {
        tokio::time::timeout_at(self.due(), piece)
            .await
            .map_err(|_| {
                let secs = self.started.elapsed().as_secs_f64();
                ApiError::new(
                    StatusCode::REQUEST_TIMEOUT,
                    "upload-too-slow",
                    format!(
                        "the upload sent {} bytes in {secs:.0} s: an upload must keep {} bytes/s on average after its first {} s and end within {} s (uploads.min_bytes_per_s, grace_ms, deadline_ms)",
                        self.received_bytes,
                        self.min_bytes_per_s,
                        self.grace.as_secs(),
                        self.deadline.as_secs()
                    ),
                )
            })
    }
}

/// A part that could not be written: 507 on a full disk (as for every store write), else 500.
fn staging_failed(path: &std::path::Path, source: std::io::Error) -> ApiError {
    crate::store::StoreError::Io {
        path: path.to_owned(),
        source,
    }
    .into()
}

/// 507: the stored datasets and the uploads in progress would pass `datasets_quota_bytes`.
fn over_quota(used_bytes: u64, staged_bytes: u64, quota_bytes: u64) -> ApiError {
    ApiError::new(
        StatusCode::INSUFFICIENT_STORAGE,
        "datasets-quota",
        format!(
            "the stored datasets take {used_bytes} bytes of the {quota_bytes}-byte quota (datasets_quota_bytes); with {staged_bytes} bytes of uploads in progress this upload would pass it: delete datasets (DELETE /api/v1/datasets/{{id}}) or raise the quota"
        ),
    )
}

impl Drop for UploadPace {
    /// This upload's bytes leave the uploads in flight (they are stored now, or removed).
    fn drop(&mut self) {
        self.all_in_flight
            .fetch_sub(self.received_bytes, std::sync::atomic::Ordering::SeqCst);
    }
}

#[derive(Debug, serde::Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
pub struct DatasetListQuery {
    /// At most this many, newest first (default 50, at most 1000).
    #[param(minimum = 1, maximum = 1000)]
    pub limit: Option<u32>,
    /// Where the page begins: the cursor a full page's `Link: <…>; rel="next"` carries.
    #[param(
        pattern = r"^[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9]{2}:[0-9]{2}:[0-9]{2}\.[0-9]{3}Z_[a-z0-9][a-z0-9-]{0,63}$"
    )]
    pub after: Option<String>,
}

#[utoipa::path(get, path = "/datasets", tag = "datasets", params(DatasetListQuery),
    responses((status = 200, description = "Newest first; a full page has a `Link` header (rel=\"next\") to the next one", body = Vec<Object>),
              (status = 422, body = Problem)))]
pub async fn list(
    State(svc): State<Service>,
    axum::extract::Query(q): axum::extract::Query<DatasetListQuery>,
) -> ApiResult<Response> {
    let limit = page::limit(q.limit)?;
    let after = page::after(q.after.as_deref())?;
    let store = svc.store.clone();
    let datasets = blocking(move || store.list_datasets_page(limit, after.as_ref())).await??;
    Ok(page::page(
        datasets,
        limit,
        |after| format!("/api/v1/datasets?limit={limit}&after={after}"),
        |d: &DatasetRecord| (d.created_at.as_str(), d.id.as_str()),
    ))
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

#[utoipa::path(delete, path = "/datasets/{id}", tag = "datasets",
    params(("id" = String, Path, description = "Dataset id")),
    responses((status = 204, description = "Deleted: its frames and record (ended runs that analysed it keep their results)"),
              (status = 404, body = Problem),
              (status = 409, description = "A queued or running run names it", body = Problem)))]
pub async fn delete(State(svc): State<Service>, Path(id): Path<String>) -> ApiResult<StatusCode> {
    let id = dataset_id(&id)?;
    let store = svc.store.clone();
    blocking(move || store.delete_dataset(&id)).await??;
    Ok(StatusCode::NO_CONTENT)
}

#[utoipa::path(post, path = "/datasets/{id}/analyses", tag = "datasets", request_body = AnalysisRequest,
    params(("id" = String, Path, description = "Dataset id"),
           ("Idempotency-Key" = Option<String>, Header, description = "Repeat-safe submission")),
    responses((status = 202, description = "Queued as a job; Location names it", body = Object),
              (status = 429, description = "The lane already has jobs.max_queued_per_lane jobs waiting; Retry-After says when to try again", body = Problem),
              (status = 404, body = Problem), (status = 422, body = Problem)))]
pub async fn analyse(
    State(svc): State<Service>,
    Path(id): Path<String>,
    headers: HeaderMap,
    ApiJson(request): ApiJson<AnalysisRequest>,
) -> ApiResult<Response> {
    let id = dataset_id(&id)?;
    super::queue(&svc, &headers, "/api/v1/jobs", move |s| {
        AnalysisJob::plan(s, &id, request)
    })
    .await
}

#[utoipa::path(post, path = "/datasets/{id}/comparisons", tag = "datasets", request_body = CompareRequest,
    params(("id" = String, Path, description = "Dataset id"),
           ("Idempotency-Key" = Option<String>, Header, description = "Repeat-safe submission")),
    responses((status = 202, description = "Queued as a job; Location names it. Its results/comparison.json and plots/*.svg hold the comparison, which the dataset's history keeps. Each run's `accuracy` is the measured side against the commanded move (commanded_px, bias_px ± bias_se_px, std_px, and in µm); plots/accuracy_vs_commanded.svg draws bias (± 2 SE) and std against the commanded displacement: for a step series, its S-curve", body = Object),
              (status = 429, description = "The lane already has jobs.max_queued_per_lane jobs waiting; Retry-After says when to try again", body = Problem),
              (status = 404, body = Problem), (status = 422, body = Problem)))]
pub async fn compare(
    State(svc): State<Service>,
    Path(id): Path<String>,
    headers: HeaderMap,
    ApiJson(request): ApiJson<CompareRequest>,
) -> ApiResult<Response> {
    let id = dataset_id(&id)?;
    super::queue(&svc, &headers, "/api/v1/jobs", move |s| {
        ComparisonJob::plan(s, &id, request)
    })
    .await
}

#[utoipa::path(post, path = "/datasets/{id}/diagnoses", tag = "datasets", request_body = CompareRequest,
    params(("id" = String, Path, description = "Dataset id"),
           ("Idempotency-Key" = Option<String>, Header, description = "Repeat-safe submission")),
    responses((status = 202, description = "Queued as a job; Location names it. Its results/diagnosis.json ranks the candidates; results/winner-model.toml is the model with the verdict added", body = Object),
              (status = 429, description = "The lane already has jobs.max_queued_per_lane jobs waiting; Retry-After says when to try again", body = Problem),
              (status = 404, body = Problem), (status = 422, body = Problem)))]
pub async fn diagnose(
    State(svc): State<Service>,
    Path(id): Path<String>,
    headers: HeaderMap,
    ApiJson(request): ApiJson<CompareRequest>,
) -> ApiResult<Response> {
    let id = dataset_id(&id)?;
    super::queue(&svc, &headers, "/api/v1/jobs", move |s| {
        DiagnosisJob::plan(s, &id, request)
    })
    .await
}

#[utoipa::path(post, path = "/datasets/{id}/on-bench", tag = "datasets", request_body = CompareRequest,
    params(("id" = String, Path, description = "Dataset id"),
           ("Idempotency-Key" = Option<String>, Header, description = "Repeat-safe submission")),
    responses((status = 202, description = "Queued as a job on the bench lane; Location names it. The dataset is diagnosed (results/diagnosis.json); the runs that separate what it left open (its rounds' runs_to_separate: moves of several sizes, along both axes, a step series, static frames) are captured on the bench, appended to the dataset's runs as a new stored dataset and diagnosed again. results/on-bench.json holds before, open_before, bench (runs, plan, captured and merged dataset ids), after and open_after", body = Object),
              (status = 429, description = "The lane already has jobs.max_queued_per_lane jobs waiting; Retry-After says when to try again", body = Problem),
              (status = 404, body = Problem), (status = 503, description = "No stage is configured", body = Problem), (status = 422, body = Problem)))]
pub async fn on_bench(
    State(svc): State<Service>,
    Path(id): Path<String>,
    headers: HeaderMap,
    ApiJson(request): ApiJson<CompareRequest>,
) -> ApiResult<Response> {
    let id = dataset_id(&id)?;
    super::queue(&svc, &headers, "/api/v1/jobs", move |s| {
        OnBenchJob::plan(s, &id, request)
    })
    .await
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

/// Most jobs `GET /datasets/{id}/jobs` lists.
const DATASET_JOBS_LIMIT: usize = 200;

/// One comparison, diagnosis or analysis of a dataset, with its headline figures.
#[derive(serde::Serialize, utoipa::ToSchema)]
pub struct DatasetJob {
    pub id: String,
    /// `comparison`, `diagnosis` or `analysis`.
    pub kind: String,
    pub status: String,
    pub created_at: String,
    pub finished_at: Option<String>,
    pub message: String,
    /// The model the request named (comparisons and diagnoses).
    pub model: Option<String>,
    /// The discrepancy against that model, full-resolution px (once succeeded).
    pub discrepancy_px: Option<f64>,
    /// A diagnosis's verdict (`none` when no candidate explains the discrepancy); several
    /// rounds give their verdicts in order.
    pub verdicts: Vec<String>,
    /// After the diagnosis's found effects were added, px.
    pub final_discrepancy_px: Option<f64>,
    /// Files the job wrote (`results/…`, `plots/…`), as `GET /jobs/{id}/files/…` serves them.
    pub result_files: Vec<String>,
}

impl DatasetJob {
    /// The record and, for a succeeded comparison or diagnosis, its results file's headline.
    fn of(record: crate::store::RunRecord, results: Option<serde_json::Value>) -> Self {
        let r = results.unwrap_or(serde_json::Value::Null);
        let verdicts = match r.get("verdicts").and_then(|v| v.as_array()) {
            Some(list) if !list.is_empty() => list
                .iter()
                .filter_map(|v| v.as_str().map(str::to_string))
                .collect(),
            _ => r
                .get("verdict")
                .and_then(|v| v.as_str())
                .map(|v| vec![v.to_string()])
                .unwrap_or_default(),
        };
        DatasetJob {
            id: record.id.to_string(),
            kind: record.kind.as_str().to_string(),
            status: record.status.as_str().to_string(),
            created_at: record.created_at,
            finished_at: record.finished_at,
            message: record.message,
            model: record
                .request
                .get("model")
                .and_then(|m| m.as_str())
                .map(str::to_string),
            discrepancy_px: r.get("discrepancy_px").and_then(|v| v.as_f64()),
            verdicts,
            final_discrepancy_px: r.get("final_discrepancy_px").and_then(|v| v.as_f64()),
            result_files: record.result_files,
        }
    }
}

/// The results file whose headline a job's row shows.
fn results_file(kind: RunKind) -> Option<&'static str> {
    match dataset_page_row(kind) {
        DatasetPageRow::Headline(file) => Some(file),
        DatasetPageRow::Listed | DatasetPageRow::NotListed => None,
    }
}

#[utoipa::path(get, path = "/datasets/{id}/jobs", tag = "datasets",
    params(("id" = String, Path, description = "Dataset id")),
    responses((status = 200, description = "The dataset's comparisons, diagnoses and analyses, newest first, with their headline figures", body = Vec<DatasetJob>),
              (status = 404, body = Problem)))]
pub async fn jobs(
    State(svc): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<Json<Vec<DatasetJob>>> {
    let id = dataset_id(&id)?;
    let store = svc.store.clone();
    Ok(Json(
        blocking(move || -> ApiResult<Vec<DatasetJob>> {
            store.get_dataset(&id)?;
            // What was done to the dataset.
            let kinds: Vec<RunKind> = RunKind::ALL
                .into_iter()
                .filter(|k| !matches!(dataset_page_row(*k), DatasetPageRow::NotListed))
                .collect();
            let runs = store.list_for_dataset(&id, &kinds, DATASET_JOBS_LIMIT)?;
            Ok(runs
                .into_iter()
                .map(|run| {
                    let results = results_file(run.kind)
                        .filter(|f| run.result_files.iter().any(|r| r == f))
                        .and_then(|f| store.read_file(&run.id, f).ok())
                        .and_then(|bytes| serde_json::from_slice(&bytes).ok());
                    DatasetJob::of(run, results)
                })
                .collect())
        })
        .await??,
    ))
}

/// One run of a dataset's manifest: its frames and the commanded move in mm and in px.
#[derive(serde::Serialize, utoipa::ToSchema)]
pub struct DatasetRun {
    pub id: String,
    /// The speckle pattern's label, when the manifest names one.
    pub pattern: Option<String>,
    pub reference: String,
    pub deformed: String,
    /// Commanded stage move, mm.
    pub dx_mm: f64,
    pub dy_mm: f64,
    /// The same move in px of the run's frames (× scale_px_per_mm at full resolution, over the
    /// hardware scheme's block otherwise).
    pub dx_px: f64,
    pub dy_px: f64,
    /// Further static frames of the reference position.
    pub static_repeats: usize,
    /// The camera's own scheme the frames were read out in (`hw:…`); null: full resolution.
    pub capture: Option<String>,
    /// With `capture`: the full-resolution run of the same pattern and move.
    pub twin_of: Option<String>,
}

/// `GET /datasets/{id}/details`: what the manifest and the frames say of the measurement.
#[derive(serde::Serialize, utoipa::ToSchema)]
pub struct DatasetDetails {
    pub id: String,
    pub name: String,
    pub scale_px_per_mm: f64,
    /// Significant bits per sample: the manifest's camera, else the first reference frame's.
    pub bit_depth: Option<u8>,
    pub width: usize,
    pub height: usize,
    /// The stage's stated repeatability, 1σ per axis, µm.
    pub stage_repeatability_um: Option<f64>,
    pub runs: Vec<DatasetRun>,
}

#[utoipa::path(get, path = "/datasets/{id}/details", tag = "datasets",
    params(("id" = String, Path, description = "Dataset id")),
    responses((status = 200, body = DatasetDetails), (status = 404, body = Problem)))]
pub async fn details(
    State(svc): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<Json<DatasetDetails>> {
    let id = dataset_id(&id)?;
    let store = svc.store.clone();
    Ok(Json(
        blocking(move || -> ApiResult<DatasetDetails> {
            let record = store.get_dataset(&id)?;
            let dir = store.dataset_dir(&id);
            let m = Manifest::read(&dir)
                .map_err(|e| ApiError::internal("reading a stored dataset's manifest", e))?;
            // Recorded at upload; a record from before reads the header, never the pixels.
            let bit_depth = m
                .camera
                .as_ref()
                .map(|c| c.bit_depth)
                .or(record.bit_depth)
                .or_else(|| {
                    let first = m.runs.first()?;
                    read_image_header(&dir.join(&first.reference))
                        .ok()
                        .map(|info| info.bit_depth)
                });
            let scale = m.scale_px_per_mm;
            Ok(DatasetDetails {
                id: record.id.to_string(),
                name: m.name.clone(),
                scale_px_per_mm: scale,
                bit_depth,
                width: record.width,
                height: record.height,
                stage_repeatability_um: m.stage_repeatability_um,
                runs: m
                    .runs
                    .iter()
                    .map(|r| DatasetRun {
                        id: r.id.clone(),
                        pattern: r.pattern.as_ref().map(|p| p.label.clone()),
                        reference: r.reference.clone(),
                        deformed: r.deformed.clone(),
                        dx_mm: r.stage.dx_mm,
                        dy_mm: r.stage.dy_mm,
                        dx_px: r.stage.dx_mm * r.frame_px_per_mm(scale),
                        dy_px: r.stage.dy_mm * r.frame_px_per_mm(scale),
                        static_repeats: r.repeat.len(),
                        capture: r.capture.as_ref().map(|c| c.name.clone()),
                        twin_of: r.twin_of.clone(),
                    })
                    .collect(),
            })
        })
        .await??,
    ))
}
