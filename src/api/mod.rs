//! The HTTP API under `/api/v1` (axum), its OpenAPI document (utoipa) at
//! `/api/v1/openapi.json`, problem+json errors, SSE progress, bearer-token auth for mutating
//! requests, body limits and request ids. No numerics here: handlers call the service.

mod auth;
mod json;
mod openapi;
mod problem;
mod routes;
mod sse;

pub use problem::{ApiError, Problem};

use crate::service::Service;
use axum::extract::DefaultBodyLimit;
use axum::http::{HeaderName, HeaderValue, Method};
use axum::Router;
use std::net::SocketAddr;
use tokio_util::sync::CancellationToken;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::trace::TraceLayer;

const REQUEST_ID: &str = "x-request-id";

/// The whole application: API, OpenAPI document, and whatever `extra` the caller mounts at the
/// root (the dashboard).
pub fn app(service: Service, extra: Router<Service>) -> Router {
    let (api, spec) = openapi::router(service.config.max_upload_bytes).split_for_parts();
    let spec_json = serde_json::to_string_pretty(&spec).expect("the OpenAPI document serialises");
    let token = service.config.token();
    let max_json = service.config.max_json_bytes;
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
        .layer(axum::middleware::from_fn_with_state(
            token,
            auth::require_token,
        ))
        .layer(DefaultBodyLimit::max(max_json))
        .with_state(service);
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
            }),
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
            .allow_methods([Method::GET, Method::POST, Method::PATCH])
            .allow_headers([
                axum::http::header::CONTENT_TYPE,
                axum::http::header::AUTHORIZATION,
            ]),
    )
}

#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error(
        "refusing to listen on {0} without a token: set auth_token in the config or FFDIC_TOKEN"
    )]
    NoToken(SocketAddr),
    #[error("cannot serve: {0}")]
    Io(#[from] std::io::Error),
}

/// Whether the configured address is safe to serve without a token.
pub fn check_bind(addr: SocketAddr, token: Option<&str>) -> Result<(), ServeError> {
    if !addr.ip().is_loopback() && token.is_none() {
        return Err(ServeError::NoToken(addr));
    }
    Ok(())
}

/// Serves `app` on `listener` until `shutdown` is cancelled, then stops taking requests and lets
/// the running ones finish (SSE streams end with the server).
pub async fn run(
    listener: tokio::net::TcpListener,
    app: Router,
    shutdown: CancellationToken,
) -> Result<(), ServeError> {
    let addr = listener.local_addr()?;
    tracing::info!("listening on http://{addr}");
    axum::serve(listener, app)
        .with_graceful_shutdown(async move { shutdown.cancelled().await })
        .await?;
    Ok(())
}
