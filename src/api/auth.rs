//! Bearer-token auth. With a token configured, every request that changes something needs it;
//! reads need it too when the daemon listens off loopback (or the config says so), so a lab
//! network cannot read frames and results without it. With no token (loopback only) nothing is
//! checked.

use super::problem::ApiError;
use axum::extract::{Request, State};
use axum::http::{header, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::sync::Arc;

pub struct AuthConfig {
    pub token: Option<String>,
    pub reads_need_token: bool,
}

pub async fn require_token(
    State(config): State<Arc<AuthConfig>>,
    req: Request,
    next: Next,
) -> Response {
    let Some(token) = config.token.as_deref() else {
        return next.run(req).await;
    };
    let is_read = matches!(*req.method(), Method::GET | Method::HEAD | Method::OPTIONS);
    // The liveness probe, the CORS preflight and the dashboard's static pages (no data in them;
    // their data comes from the API) stay open.
    let path = req.uri().path();
    let open = req.method() == Method::OPTIONS
        || path == "/api/v1/health"
        || (is_read && !path.starts_with("/api/"));
    if open || (is_read && !config.reads_need_token) {
        return next.run(req).await;
    }
    let given = req
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(bearer);
    if given.is_some_and(|g| constant_time_eq(g.as_bytes(), token.as_bytes())) {
        return next.run(req).await;
    }
    let mut response = ApiError::new(
        StatusCode::UNAUTHORIZED,
        "unauthorized",
        if is_read {
            "this daemon serves reads to token holders only: send Authorization: Bearer <token>"
        } else {
            "this request changes the bench or the store: send Authorization: Bearer <token>"
        },
    )
    .into_response();
    response.headers_mut().insert(
        header::WWW_AUTHENTICATE,
        header::HeaderValue::from_static("Bearer"),
    );
    response
}

/// The credentials of `Bearer <token>`; the scheme is case-insensitive (RFC 9110 §11.1).
fn bearer(value: &str) -> Option<&str> {
    let (scheme, rest) = value.trim().split_once(' ')?;
    scheme
        .eq_ignore_ascii_case("bearer")
        .then(|| rest.trim_start())
}

/// Compares without an early exit, so the time taken says nothing about the token.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    #[test]
    fn equal_only_when_equal() {
        assert!(super::constant_time_eq(b"abc", b"abc"));
        assert!(!super::constant_time_eq(b"abc", b"abd"));
        assert!(!super::constant_time_eq(b"abc", b"abcd"));
    }

    #[test]
    fn the_scheme_is_case_insensitive() {
        assert_eq!(super::bearer("Bearer t0k"), Some("t0k"));
        assert_eq!(super::bearer("bearer t0k"), Some("t0k"));
        assert_eq!(super::bearer("BEARER  t0k"), Some("t0k"));
        assert_eq!(super::bearer("Basic t0k"), None);
        assert_eq!(super::bearer("Bearer"), None);
    }
}
