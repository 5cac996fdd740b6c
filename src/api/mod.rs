//! The HTTP API under `/api/v1` (axum), its OpenAPI document (utoipa) at
//! `/api/v1/openapi.json`, problem+json errors, SSE progress, bearer-token auth for mutating
//! requests, body limits and request ids. No numerics here: handlers call the service.

mod auth;
mod guard;
mod json;
mod openapi;
mod page;
mod parse_errors;
mod problem;
mod request_schemas;
mod routes;
mod server;
mod sse;
mod stall_guard;

pub use problem::{ApiError, Problem};

use crate::service::{HttpLimits, Service};
use axum::extract::DefaultBodyLimit;
use axum::http::{HeaderName, HeaderValue, Method};
use axum::Router;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio_util::sync::CancellationToken;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::timeout::RequestBodyTimeoutLayer;
use tower_http::trace::TraceLayer;

const REQUEST_ID: &str = "x-request-id";

/// The whole application: API, OpenAPI document, and whatever `extra` the caller mounts at the
/// root (the dashboard).
pub fn app(service: Service, extra: Router<Service>) -> Router {
    let (api, spec) = openapi::router(service.config.max_upload_bytes).split_for_parts();
    let spec_json = serde_json::to_string_pretty(&openapi::finish_document(&spec))
        .expect("the OpenAPI document serialises");
    let auth = auth::AuthConfig {
        token: service.config.token(),
        reads_need_token: service.config.reads_need_token(),
    };
    let max_json = service.config.max_json_bytes;
    let guard = Arc::new(guard::GuardConfig {
        allowed_hosts: service
            .config
            .allowed_hosts
            .iter()
            .map(|h| h.trim().to_ascii_lowercase())
            .collect(),
        cors_origins: service.config.cors_origins.clone(),
        max_json_bytes: max_json,
        max_upload_bytes: service.config.max_upload_bytes,
        request_timeout: Duration::from_millis(service.config.http.request_timeout_ms),
    });
    let body_timeout = Duration::from_millis(service.config.http.body_read_timeout_ms);
    let cors = cors_layer(&service.config.cors_origins);
    let request_id = HeaderName::from_static(REQUEST_ID);

    let mut router = Router::new()
        .merge(api)
        .route(
            "/api/v1/openapi.json",
            axum::routing::get(move || {
                let body = spec_json.clone();
                async move { ([("content-type", "application/json")], body) }
            }),
        )
        .merge(extra)
        .fallback(|| async { ApiError::not_found("no such route") })
        .method_not_allowed_fallback(|| async {
            ApiError::new(
                axum::http::StatusCode::METHOD_NOT_ALLOWED,
                "method-not-allowed",
                "this route does not take that method (the Allow header lists those it takes)",
            )
        })
        .layer(axum::middleware::from_fn_with_state(
            Arc::new(auth),
            auth::require_token,
        ))
        .layer(DefaultBodyLimit::max(max_json))
        .layer(RequestBodyTimeoutLayer::new(body_timeout))
        .with_state(service);
    // Outside the routes: CORS answers preflights, the guard sees every request (the
    // fallbacks' too) and turns every error into a problem document.
    router = router.layer(axum::middleware::from_fn_with_state(guard, guard::guard));
    if let Some(cors) = cors {
        router = router.layer(cors);
    }
    router
        .layer(
            TraceLayer::new_for_http().make_span_with(|req: &axum::http::Request<_>| {
                let id = req
                    .headers()
                    .get(REQUEST_ID)
                    .and_then(|v| v.to_str().ok())
                    .unwrap_or("-");
                tracing::info_span!("request", request_id = %id, method = %req.method(), uri = %req.uri())
            })
            // One line per request at the default level: status and latency.
            .on_response(
                tower_http::trace::DefaultOnResponse::new()
                    .level(tracing::Level::INFO)
                    .latency_unit(tower_http::LatencyUnit::Millis),
            ),
        )
        .layer(PropagateRequestIdLayer::new(request_id.clone()))
        .layer(SetRequestIdLayer::new(request_id, MakeRequestUuid))
}

fn cors_layer(origins: &[String]) -> Option<CorsLayer> {
    if origins.is_empty() {
        return None;
    }
    let origins: Vec<HeaderValue> = origins.iter().filter_map(|o| o.parse().ok()).collect();
    Some(
        CorsLayer::new()
            .allow_origin(AllowOrigin::list(origins))
            .allow_methods([Method::GET, Method::POST, Method::PATCH, Method::DELETE])
            .allow_headers([
                axum::http::header::CONTENT_TYPE,
                axum::http::header::AUTHORIZATION,
                HeaderName::from_static("idempotency-key"),
                HeaderName::from_static("last-event-id"),
            ])
            // A created job or dataset is named by Location, a list's next page by Link; a page must
            // be able to read both.
            .expose_headers([axum::http::header::LOCATION, axum::http::header::LINK]),
    )
}

#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error(
        "refusing to listen on {0} without a token: set auth_token in the config or FFDIC_TOKEN"
    )]
    NoToken(SocketAddr),
    #[error("the token (auth_token or FFDIC_TOKEN) has {0} characters; at least {MIN_TOKEN_CHARS} are needed (e.g. `openssl rand -hex 16`)")]
    ShortToken(usize),
    #[error("cannot serve: {0}")]
    Io(#[from] std::io::Error),
}

/// The shortest bearer token the daemon takes: 16 random hex characters are 64 bits.
pub const MIN_TOKEN_CHARS: usize = 16;

/// Whether the configured address is safe to serve without a token, and the token (if any)
/// long enough to be one.
pub fn check_bind(addr: SocketAddr, token: Option<&str>) -> Result<(), ServeError> {
    if !addr.ip().is_loopback() && token.is_none() {
        return Err(ServeError::NoToken(addr));
    }
    if let Some(t) = token {
        if t.chars().count() < MIN_TOKEN_CHARS {
            return Err(ServeError::ShortToken(t.chars().count()));
        }
    }
    Ok(())
}

/// Serves `app` on `listener` until `shutdown` is cancelled, then stops taking requests and
/// gives the open ones `limits.drain_ms` to finish (SSE streams end with a terminal event).
pub async fn run(
    listener: tokio::net::TcpListener,
    app: Router,
    shutdown: CancellationToken,
    limits: &HttpLimits,
) -> Result<(), ServeError> {
    let addr = listener.local_addr()?;
    tracing::info!("listening on http://{addr}");
    server::serve(listener, app, shutdown, limits).await?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 36: tokens had no minimum length.
    #[test]
    fn a_short_token_is_refused_wherever_the_daemon_listens() {
        let open: SocketAddr = "0.0.0.0:8080".parse().unwrap();
        let local: SocketAddr = "127.0.0.1:8080".parse().unwrap();
        assert!(matches!(
            check_bind(open, None),
            Err(ServeError::NoToken(_))
        ));
        for addr in [open, local] {
            assert!(matches!(
                check_bind(addr, Some("abc")),
                Err(ServeError::ShortToken(3))
            ));
            assert!(check_bind(addr, Some("0123456789abcdef")).is_ok());
        }
        assert!(check_bind(local, None).is_ok());
    }
}
