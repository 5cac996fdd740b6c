//! Every error the API returns is an RFC 9457 problem document (`application/problem+json`).
//! Internal details go to the log with the request id; the client gets a status, a title and a
//! detail that names what it can fix — never a path, a backtrace or a driver message it cannot act on.

use crate::bench::BenchError;

use crate::experiment::FieldError;
use crate::store::StoreError;
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use ffdic_hw::HwError;
use serde::Serialize;

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub struct Problem {
    /// A URI naming the problem type (`about:blank` when the status says it all).
    #[serde(rename = "type")]
    pub kind: String,
    pub title: String,
    pub status: u16,
    pub detail: String,
    /// The request field at fault (validation errors).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
}

#[derive(Debug, Clone)]
pub struct ApiError {
    pub status: StatusCode,
    pub kind: &'static str,
    pub detail: String,
    pub field: Option<String>,
    /// Sent as `Retry-After` (429: a full queue).
    pub retry_after_s: Option<u64>,
}

impl ApiError {
    pub fn new(status: StatusCode, kind: &'static str, detail: impl Into<String>) -> Self {
        Self {
            status,
            kind,
            detail: detail.into(),
            field: None,
            retry_after_s: None,
        }
    }

    /// 429: come back in `retry_after_s` seconds.
    pub fn too_many(detail: impl Into<String>, retry_after_s: u64) -> Self {
        Self {
            retry_after_s: Some(retry_after_s),
            ..Self::new(StatusCode::TOO_MANY_REQUESTS, "queue-full", detail)
        }
    }

    pub fn bad_request(detail: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, "bad-request", detail)
    }

    pub fn invalid(field: impl Into<String>, detail: impl Into<String>) -> Self {
        Self {
            field: Some(field.into()),
            ..Self::new(StatusCode::UNPROCESSABLE_ENTITY, "validation", detail)
        }
    }

    pub fn not_found(detail: impl Into<String>) -> Self {
        Self::new(StatusCode::NOT_FOUND, "not-found", detail)
    }

    pub fn conflict(detail: impl Into<String>) -> Self {
        Self::new(StatusCode::CONFLICT, "conflict", detail)
    }

    pub fn unavailable(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "hardware-unavailable",
            detail,
        )
    }

    /// An error the client cannot fix: logged in full, answered in general terms.
    pub fn internal(what: &str, err: impl std::fmt::Display) -> Self {
        tracing::error!("{what}: {err}");
        Self::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal",
            format!("{what} failed; the server log has the details"),
        )
    }

    pub fn problem(&self) -> Problem {
        Problem {
            kind: if self.kind == "about:blank" {
                "about:blank".into()
            } else {
                format!("https://ffdic.invalid/problems/{}", self.kind)
            },
            title: self
                .status
                .canonical_reason()
                .unwrap_or("Error")
                .to_string(),
            status: self.status.as_u16(),
            detail: self.detail.clone(),
            field: self.field.clone(),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = serde_json::to_vec(&self.problem()).expect("a problem serialises");
        let mut response = (
            self.status,
            [(header::CONTENT_TYPE, "application/problem+json")],
            body,
        )
            .into_response();
        if let Some(s) = self.retry_after_s {
            response
                .headers_mut()
                .insert(header::RETRY_AFTER, header::HeaderValue::from(s));
        }
        response
    }
}

impl From<FieldError> for ApiError {
    fn from(e: FieldError) -> Self {
        Self::invalid(e.field, e.reason)
    }
}

impl From<HwError> for ApiError {
    fn from(e: HwError) -> Self {
        match e {
            HwError::Timeout { .. } => Self::new(
                StatusCode::GATEWAY_TIMEOUT,
                "hardware-timeout",
                e.to_string(),
            ),
            HwError::Disconnected(_) => Self::unavailable(e.to_string()),
            HwError::Busy(_) => Self::conflict(e.to_string()),
            HwError::OutOfRange { ref what, .. } => Self::invalid(what.clone(), e.to_string()),
            HwError::Unsupported(_) => Self::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "unsupported",
                e.to_string(),
            ),
            HwError::NotReferenced(_) => {
                Self::new(StatusCode::CONFLICT, "stage-not-referenced", e.to_string())
            }
            HwError::Protocol(_) => {
                Self::new(StatusCode::BAD_GATEWAY, "hardware-protocol", e.to_string())
            }
        }
    }
}

impl From<BenchError> for ApiError {
    fn from(e: BenchError) -> Self {
        match e {
            BenchError::Hw(hw) => hw.into(),
            BenchError::Busy { .. } => Self::conflict(e.to_string()),
            BenchError::NoStage | BenchError::NoTargetMount | BenchError::Stopped => {
                Self::unavailable(e.to_string())
            }
            BenchError::Panicked(_) => Self::internal("a bench command", e),
            BenchError::Unresponsive { .. } => Self::new(
                StatusCode::GATEWAY_TIMEOUT,
                "hardware-timeout",
                e.to_string(),
            ),
        }
    }
}

impl From<StoreError> for ApiError {
    fn from(e: StoreError) -> Self {
        match e {
            StoreError::NotFound(_) => Self::not_found(e.to_string()),
            StoreError::BadId(_) => Self::not_found(e.to_string()),
            StoreError::BadPath(_) => Self::bad_request(e.to_string()),
            StoreError::Finished(_) | StoreError::Transition { .. } | StoreError::Conflict(..) => {
                Self::conflict(e.to_string())
            }
            StoreError::InUse(_) => Self::new(StatusCode::CONFLICT, "in-use", e.to_string()),
            StoreError::QuotaFull { .. } => Self::new(
                StatusCode::INSUFFICIENT_STORAGE,
                "quota-full",
                e.to_string(),
            ),
            StoreError::Dataset(_) => Self::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "invalid-dataset",
                e.to_string(),
            ),
            full if full.is_storage_full() => {
                tracing::error!("the run store: {full}");
                Self::new(
                    StatusCode::INSUFFICIENT_STORAGE,
                    "storage-full",
                    "the data folder's disk is full: free space and try again".to_string(),
                )
            }
            other => Self::internal("the run store", other),
        }
    }
}

pub type ApiResult<T> = Result<T, ApiError>;
