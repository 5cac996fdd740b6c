//! The JSON body extractor: malformed JSON is 400, a wrong type or an unknown field is 422 naming
//! the field (serde_path_to_error gives its path), an oversized body is 413 — each as a problem.

use super::problem::ApiError;
use axum::body::Bytes;
use axum::extract::{FromRequest, Request};
use axum::http::{header, StatusCode};
use serde::de::DeserializeOwned;

pub struct ApiJson<T>(pub T);

impl<S, T> FromRequest<S> for ApiJson<T>
where
    S: Send + Sync,
    T: DeserializeOwned,
{
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        let is_json = req
            .headers()
            .get(header::CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .map(|v| {
                let essence = v
                    .split(';')
                    .next()
                    .unwrap_or("")
                    .trim()
                    .to_ascii_lowercase();
                essence == "application/json"
                    || (essence.starts_with("application/") && essence.ends_with("+json"))
            });
        let bytes = Bytes::from_request(req, state).await.map_err(|e| {
            if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
                ApiError::new(
                    StatusCode::PAYLOAD_TOO_LARGE,
                    "too-large",
                    "the request body is larger than this endpoint accepts",
                )
            } else {
                ApiError::bad_request(format!("cannot read the body: {e}"))
            }
        })?;
        // An empty body means "all defaults". Anything else must say it is JSON: a body without
        // a JSON content type is what a cross-site form or `fetch(.., {mode: 'no-cors'})` sends,
        // and is never read as JSON.
        let bytes = if bytes.is_empty() {
            Bytes::from_static(b"{}")
        } else {
            if is_json != Some(true) {
                return Err(ApiError::new(
                    StatusCode::UNSUPPORTED_MEDIA_TYPE,
                    "unsupported-media-type",
                    "send JSON with Content-Type: application/json",
                ));
            }
            bytes
        };
        parse(&bytes).map(ApiJson)
    }
}

/// Parses JSON, naming the field at fault. Every request body is an object: serde's derived
/// structs would also take an array (`[]` as "all defaults"), which no client means.
pub fn parse<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let first = bytes.iter().find(|b| !b.is_ascii_whitespace());
    if first.is_some_and(|&b| b != b'{') {
        return Err(ApiError::invalid("body", "the body must be a JSON object"));
    }
    let de = &mut serde_json::Deserializer::from_slice(bytes);
    let value = serde_path_to_error::deserialize(&mut *de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        match inner.classify() {
            serde_json::error::Category::Data => {
                let field = if path == "." {
                    unknown_field(&inner.to_string()).unwrap_or_else(|| "body".into())
                } else {
                    path
                };
                ApiError::invalid(field, strip_position(&inner.to_string()))
            }
            _ => ApiError::bad_request(format!("malformed JSON: {inner}")),
        }
    })?;
    // One object and nothing after it: `{"dx_mm":0.0} xyz` or two objects once passed as the
    // first alone.
    de.end().map_err(|e| {
        ApiError::bad_request(format!(
            "malformed JSON: {}",
            strip_position(&e.to_string()).replace("trailing characters", "data after the object")
        ))
    })?;
    Ok(value)
}

/// serde names an unknown field in its message (``unknown field `foo` ``); the path stops at
/// its parent.
fn unknown_field(message: &str) -> Option<String> {
    let rest = message.strip_prefix("unknown field `")?;
    Some(rest[..rest.find('`')?].to_string())
}

fn strip_position(message: &str) -> String {
    match message.rfind(" at line ") {
        Some(i) => message[..i].to_string(),
        None => message.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Body {
        a: u32,
        inner: Option<Inner>,
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Inner {
        b: f64,
    }

    #[test]
    fn problems_name_the_field() {
        let e = parse::<Body>(br#"{"a":"x"}"#).unwrap_err();
        assert_eq!((e.status.as_u16(), e.field.as_deref()), (422, Some("a")));
        let e = parse::<Body>(br#"{"a":1,"inner":{"b":true}}"#).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("inner.b"));
        let e = parse::<Body>(br#"{"a":1,"zz":2}"#).unwrap_err();
        assert_eq!(e.status.as_u16(), 422);
        assert!(e.detail.contains("zz"), "{}", e.detail);
        let e = parse::<Body>(br#"{"a":1"#).unwrap_err();
        assert_eq!(e.status.as_u16(), 400);
        let e = parse::<Body>(b" []").unwrap_err();
        assert_eq!((e.status.as_u16(), e.field.as_deref()), (422, Some("body")));
    }

    /// Issue 36: trailing data and a second object were accepted as the first object alone.
    #[test]
    fn one_object_and_nothing_after_it() {
        for bad in [&br#"{"a":1} xyz"#[..], br#"{"a":1}{"a":2}"#] {
            let e = parse::<Body>(bad).unwrap_err();
            assert_eq!(e.status.as_u16(), 400, "{}", String::from_utf8_lossy(bad));
            assert!(e.detail.contains("after the object"), "{}", e.detail);
        }
        assert!(
            parse::<Body>(b"{\"a\":1} \n").is_ok(),
            "trailing white space is fine"
        );
    }
}
