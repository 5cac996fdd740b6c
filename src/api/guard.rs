//! What every request passes before a handler sees it, and what every error looks like after.
//!
//! - `Host` must be a name this daemon serves: a loopback name, an IP literal or a configured
//!   name. A page that rebinds its own DNS name to 127.0.0.1 still sends its own name, and is
//!   refused (421).
//! - A request that changes something and comes from another site is refused (403): browsers
//!   send `Origin` (and `Sec-Fetch-Site`) with every cross-site POST, including the "simple"
//!   ones that need no CORS preflight (`mode: 'no-cors'`, forms, `sendBeacon`).
//! - A body whose `Content-Length` is over the route's limit is refused (413) before a handler
//!   sees it; up to 1 MiB of it is read and dropped first, so the client reads the answer instead
//!   of a connection reset.
//! - A request other than an SSE stream or an upload is answered within the request timeout.
//! - Every error leaves as `application/problem+json`, the framework's own (404, 405, 413,
//!   415, a bad path or query) included; a handler's own JSON document for an error status
//!   (`/health`'s 503, naming what stopped) stays as it is. hyper's answers to requests it
//!   cannot parse are rewritten on the connection (`parse_errors.rs`); a header field over
//!   8 KiB or a head over 32 KiB is 431.

use super::problem::ApiError;
use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, HeaderValue, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::net::IpAddr;
use std::sync::Arc;
use std::time::Duration;

/// What the guard checks against, built once from the configuration.
#[derive(Clone, Debug)]
pub struct GuardConfig {
    /// Extra host names (lower case, no port).
    pub allowed_hosts: Vec<String>,
    /// Origins allowed by CORS: they may also send mutating requests.
    pub cors_origins: Vec<String>,
    pub max_json_bytes: usize,
    pub max_upload_bytes: usize,
    pub request_timeout: Duration,
}

/// The upload route: the only one with the upload limit and without the request timeout.
fn is_upload(req: &Request) -> bool {
    req.method() == Method::POST && req.uri().path() == "/api/v1/datasets"
}

/// SSE streams last as long as their run: no request timeout.
fn is_stream(req: &Request) -> bool {
    req.method() == Method::GET && req.uri().path().ends_with("/events")
}

fn is_mutating(method: &Method) -> bool {
    !matches!(*method, Method::GET | Method::HEAD | Method::OPTIONS)
}

pub async fn guard(State(config): State<Arc<GuardConfig>>, req: Request, next: Next) -> Response {
    if let Err(e) = check_header_size(req.headers()) {
        return e.into_response();
    }
    if let Err(e) = check_host(&config, req.version(), req.headers()) {
        return e.into_response();
    }
    if is_mutating(req.method()) {
        if let Err(e) = check_same_site(&config, req.headers()) {
            return e.into_response();
        }
    }
    let limit = if is_upload(&req) {
        config.max_upload_bytes
    } else {
        config.max_json_bytes
    };
    if let Some(len) = content_length(req.headers()) {
        if len > limit as u64 {
            if len <= DRAIN_BEFORE_REFUSING_BYTES {
                // Closing with the client's bytes still unread makes the kernel reset the
                // connection, and the client may lose the answer before reading it: read and drop
                // a modest body first, so it sees the 413 (a larger one gets the reset).
                let _ = axum::body::to_bytes(req.into_body(), DRAIN_BEFORE_REFUSING_BYTES as usize)
                    .await;
            }
            return ApiError::new(
                StatusCode::PAYLOAD_TOO_LARGE,
                "too-large",
                format!("the body of {len} bytes is over this endpoint's limit of {limit} bytes"),
            )
            .into_response();
        }
    }
    let response = if is_stream(&req) || is_upload(&req) {
        next.run(req).await
    } else {
        match tokio::time::timeout(config.request_timeout, next.run(req)).await {
            Ok(r) => r,
            Err(_) => ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "timeout",
                format!(
                    "no answer within {} s; the work may still finish (see GET /experiments)",
                    config.request_timeout.as_secs()
                ),
            )
            .into_response(),
        }
    };
    as_problem(response).await
}

/// The longest header field (name and value) and all of them together a request may send: a
/// browser's largest (cookies) stay under 8 KiB; hyper took a single 100 KB header.
pub const MAX_HEADER_FIELD_BYTES: usize = 8 * 1024;
pub const MAX_HEADERS_BYTES: usize = 32 * 1024;

/// 431 for a header field or a head over [`MAX_HEADER_FIELD_BYTES`] / [`MAX_HEADERS_BYTES`].
fn check_header_size(headers: &HeaderMap) -> Result<(), ApiError> {
    let mut total = 0;
    for (name, value) in headers {
        let field = name.as_str().len() + value.len();
        total += field;
        if field > MAX_HEADER_FIELD_BYTES || total > MAX_HEADERS_BYTES {
            let detail = if field > MAX_HEADER_FIELD_BYTES {
                format!(
                    "header '{}' has {field} bytes; at most {MAX_HEADER_FIELD_BYTES} a field",
                    name.as_str().chars().take(64).collect::<String>()
                )
            } else {
                format!("the headers pass {MAX_HEADERS_BYTES} bytes together")
            };
            return Err(ApiError::new(
                StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
                "headers-too-large",
                detail,
            ));
        }
    }
    Ok(())
}

/// An over-limit body up to this size is read and dropped before the 413 (see [`guard`]).
const DRAIN_BEFORE_REFUSING_BYTES: u64 = 1 << 20;

fn content_length(headers: &HeaderMap) -> Option<u64> {
    headers
        .get(header::CONTENT_LENGTH)?
        .to_str()
        .ok()?
        .trim()
        .parse()
        .ok()
}

/// The host part of a `Host` header or an origin's authority: `[::1]:8080` → `::1`,
/// `Example.org:80` → `example.org`.
fn host_name(authority: &str) -> String {
    let a = authority.trim();
    let host = if let Some(rest) = a.strip_prefix('[') {
        rest.split(']').next().unwrap_or("")
    } else {
        a.rsplit_once(':').map_or(a, |(h, port)| {
            if port.chars().all(|c| c.is_ascii_digit()) {
                h
            } else {
                a
            }
        })
    };
    host.trim_end_matches('.').to_ascii_lowercase()
}

fn check_host(
    config: &GuardConfig,
    version: axum::http::Version,
    headers: &HeaderMap,
) -> Result<(), ApiError> {
    // RFC 9112 §3.2: an HTTP/1.1 request without Host, or with more than one, is answered 400.
    // HTTP/1.0 clients may omit it; browsers never do, and only browsers rebind DNS.
    let mut hosts = headers.get_all(header::HOST).iter();
    let (Some(value), None) = (hosts.next(), hosts.next()) else {
        let count = headers.get_all(header::HOST).iter().count();
        if count == 0 && version < axum::http::Version::HTTP_11 {
            return Ok(());
        }
        return Err(ApiError::bad_request(format!(
            "an HTTP/1.1 request carries exactly one Host header; this one has {count}"
        )));
    };
    let host = value.to_str().map(host_name).unwrap_or_default();
    let allowed = host == "localhost"
        || host.ends_with(".localhost")
        || host.parse::<IpAddr>().is_ok()
        || config.allowed_hosts.iter().any(|h| h == &host);
    if allowed {
        return Ok(());
    }
    Err(ApiError::new(
        StatusCode::MISDIRECTED_REQUEST,
        "unknown-host",
        format!(
            "this daemon does not serve the host '{host}': use an IP address or localhost, or add \
             the name to allowed_hosts in the config"
        ),
    ))
}

/// A mutating request must come from the daemon's own pages (same origin), from a configured
/// CORS origin, or from a client that is not a browser (no `Origin`, no `Sec-Fetch-Site`).
fn check_same_site(config: &GuardConfig, headers: &HeaderMap) -> Result<(), ApiError> {
    let text = |name: &str| headers.get(name).and_then(|v| v.to_str().ok());
    let own_host = text("host").map(|h| h.trim().to_ascii_lowercase());
    let refuse = |why: String| {
        Err(ApiError::new(
            StatusCode::FORBIDDEN,
            "cross-site",
            format!("{why}: requests that change the bench or the store must come from this daemon's own pages or a configured CORS origin"),
        ))
    };
    match text("origin") {
        Some(origin) => {
            let origin = origin.trim().to_ascii_lowercase();
            let same = own_host.as_deref().is_some_and(|h| {
                origin == format!("http://{h}") || origin == format!("https://{h}")
            });
            let listed = config
                .cors_origins
                .iter()
                .any(|o| o.trim_end_matches('/').eq_ignore_ascii_case(&origin));
            if same || listed {
                Ok(())
            } else {
                refuse(format!("Origin {origin} is another site"))
            }
        }
        None => match text("sec-fetch-site") {
            Some("same-origin") | Some("none") | None => Ok(()),
            Some(other) => refuse(format!("Sec-Fetch-Site is {other}")),
        },
    }
}

/// Turns an error response that is not yet a problem document (the framework's rejections)
/// into one, keeping its status and headers such as `Allow`.
async fn as_problem(response: Response) -> Response {
    let status = response.status();
    // A problem already, or a handler's own JSON document for that status (`/health`'s 503
    // names what stopped): left as it is. The framework's errors are plain text.
    let is_document = response
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| {
            let v = v.as_bytes();
            v.starts_with(b"application/problem+json") || v.starts_with(b"application/json")
        });
    if !(status.is_client_error() || status.is_server_error()) || is_document {
        return response;
    }
    let (mut parts, body) = response.into_parts();
    let text = axum::body::to_bytes(body, 4096)
        .await
        .map(|b| String::from_utf8_lossy(&b).trim().to_string())
        .unwrap_or_default();
    let detail = if text.is_empty() {
        status.canonical_reason().unwrap_or("error").to_string()
    } else {
        text
    };
    let problem = ApiError::new(status, kind_of(status), detail).problem();
    let body = serde_json::to_vec(&problem).expect("a problem serialises");
    parts.headers.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/problem+json"),
    );
    parts.headers.remove(header::CONTENT_LENGTH);
    Response::from_parts(parts, Body::from(body))
}

fn kind_of(status: StatusCode) -> &'static str {
    match status {
        StatusCode::BAD_REQUEST => "bad-request",
        StatusCode::NOT_FOUND => "not-found",
        StatusCode::METHOD_NOT_ALLOWED => "method-not-allowed",
        StatusCode::PAYLOAD_TOO_LARGE => "too-large",
        StatusCode::UNSUPPORTED_MEDIA_TYPE => "unsupported-media-type",
        StatusCode::UNPROCESSABLE_ENTITY => "validation",
        s if s.is_server_error() => "internal",
        _ => "about:blank",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> GuardConfig {
        GuardConfig {
            allowed_hosts: vec!["bench.lab".into()],
            cors_origins: vec!["http://dash.lab:3000".into()],
            max_json_bytes: 1,
            max_upload_bytes: 1,
            request_timeout: Duration::from_secs(1),
        }
    }

    fn headers(pairs: &[(&'static str, &str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.insert(*k, v.parse().unwrap());
        }
        h
    }

    #[test]
    fn hosts() {
        let c = config();
        for ok in [
            "127.0.0.1:8080",
            "localhost:1",
            "[::1]:8080",
            "10.0.0.7",
            "BENCH.lab:80",
        ] {
            assert!(
                check_host(&c, V11, &headers(&[("host", ok)])).is_ok(),
                "{ok}"
            );
        }
        for bad in [
            "evil.example:8080",
            "127.0.0.1.evil.example",
            "localhost.evil.example",
        ] {
            let e = check_host(&c, V11, &headers(&[("host", bad)])).unwrap_err();
            assert_eq!(e.status, StatusCode::MISDIRECTED_REQUEST, "{bad}");
        }
    }

    const V11: axum::http::Version = axum::http::Version::HTTP_11;

    /// Issue 36: a request without Host, or with two, was answered 200.
    #[test]
    fn an_http_1_1_request_has_exactly_one_host() {
        let c = config();
        let e = check_host(&c, V11, &HeaderMap::new()).unwrap_err();
        assert_eq!(e.status, StatusCode::BAD_REQUEST);
        let mut two = headers(&[("host", "127.0.0.1")]);
        two.append(header::HOST, "localhost".parse().unwrap());
        assert_eq!(
            check_host(&c, V11, &two).unwrap_err().status,
            StatusCode::BAD_REQUEST
        );
        assert!(check_host(&c, axum::http::Version::HTTP_10, &HeaderMap::new()).is_ok());
    }

    #[test]
    fn cross_site_writes_are_refused() {
        let c = config();
        let own = [
            ("host", "127.0.0.1:8080"),
            ("origin", "http://127.0.0.1:8080"),
        ];
        assert!(check_same_site(&c, &headers(&own)).is_ok());
        let listed = [
            ("host", "127.0.0.1:8080"),
            ("origin", "http://dash.lab:3000"),
        ];
        assert!(check_same_site(&c, &headers(&listed)).is_ok());
        // Another port on the same machine is another origin (and the same *site*).
        let other_port = [
            ("host", "127.0.0.1:8080"),
            ("origin", "http://127.0.0.1:9999"),
        ];
        assert!(check_same_site(&c, &headers(&other_port)).is_err());
        let null = [("host", "127.0.0.1:8080"), ("origin", "null")];
        assert!(check_same_site(&c, &headers(&null)).is_err());
        let fetch_site = [("host", "127.0.0.1:8080"), ("sec-fetch-site", "cross-site")];
        assert!(check_same_site(&c, &headers(&fetch_site)).is_err());
        // curl, Python, reqwest: no Origin, no Sec-Fetch-Site.
        assert!(check_same_site(&c, &headers(&[("host", "127.0.0.1:8080")])).is_ok());
    }
}
