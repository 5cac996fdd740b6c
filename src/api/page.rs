//! Pages of the newest-first lists (runs of a kind, datasets): `limit` items at most, from the
//! opaque cursor `after`; a full page carries `Link: <…>; rel="next"` (RFC 8288) naming the
//! next one. The cursor holds the last item's creation time and id, so items deleted between
//! two pages shift nothing.

use super::problem::{ApiError, ApiResult};
use crate::store::PageAfter;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::Serialize;

/// Items per page unless `limit` says otherwise, and the most a page holds.
pub const DEFAULT_LIMIT: u32 = 50;
pub const MAX_LIMIT: u32 = 1000;

/// `limit` checked (1 to [`MAX_LIMIT`], [`DEFAULT_LIMIT`] when absent).
pub fn limit(given: Option<u32>) -> ApiResult<usize> {
    let limit = given.unwrap_or(DEFAULT_LIMIT);
    if !(1..=MAX_LIMIT).contains(&limit) {
        return Err(ApiError::invalid("limit", format!("1 to {MAX_LIMIT}")));
    }
    Ok(limit as usize)
}

/// Separates the time from the id in a cursor (neither holds it).
const CURSOR_SEPARATOR: char = '_';

/// Whether `s` has the shape of the store's times, `2026-11-26T10:15:00.123Z`.
fn is_stamp(s: &str) -> bool {
    const SHAPE: &[u8; 24] = b"dddd-dd-ddTdd:dd:dd.dddZ";
    s.len() == SHAPE.len()
        && s.bytes().zip(SHAPE).all(|(c, &want)| match want {
            b'd' => c.is_ascii_digit(),
            other => c == other,
        })
}

/// The cursor of a page that ends with the item created at `created_at` with id `id`.
pub fn cursor(created_at: &str, id: &str) -> String {
    format!("{created_at}{CURSOR_SEPARATOR}{id}")
}

/// `after` checked: a cursor from a `Link` header, or none.
pub fn after(given: Option<&str>) -> ApiResult<Option<PageAfter>> {
    let Some(raw) = given else {
        return Ok(None);
    };
    let bad = || {
        ApiError::invalid(
            "after",
            "not a cursor: use the `after` of the previous page's Link header",
        )
    };
    // Checked by its shape only (the `after` pattern of the OpenAPI document): the store
    // compares it as text, so any cursor of that shape is a place in the list, if perhaps past
    // its end.
    let (created_at, id) = raw.split_once(CURSOR_SEPARATOR).ok_or_else(bad)?;
    if !is_stamp(created_at) {
        return Err(bad());
    }
    id.parse::<crate::store::RunId>().map_err(|_| bad())?;
    Ok(Some(PageAfter {
        created_at: created_at.to_string(),
        id: id.to_string(),
    }))
}

/// `items` as JSON; when the page is full (`limit` items), with a `Link` to the next page:
/// `next_page(cursor)` is its URL, `key(item)` the item's creation time and id.
pub fn page<T: Serialize>(
    items: Vec<T>,
    limit: usize,
    next_page: impl Fn(&str) -> String,
    key: impl Fn(&T) -> (&str, &str),
) -> Response {
    let next = (items.len() == limit)
        .then(|| items.last())
        .flatten()
        .map(|last| {
            let (created_at, id) = key(last);
            format!("<{}>; rel=\"next\"", next_page(&cursor(created_at, id)))
        });
    let mut response = Json(items).into_response();
    if let Some(link) = next.and_then(|l| l.parse().ok()) {
        response.headers_mut().insert(header::LINK, link);
    }
    response
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cursor_reads_back_and_anything_else_is_refused() {
        let c = cursor("2026-11-26T10:15:00.123Z", "exp-20261126t101500-abcdef");
        assert_eq!(
            after(Some(&c)).unwrap(),
            Some(PageAfter {
                created_at: "2026-11-26T10:15:00.123Z".into(),
                id: "exp-20261126t101500-abcdef".into()
            })
        );
        for bad in [
            "",
            "x",
            "2026-11-26T10:15:00.123Z",
            "yesterday_exp-1",
            "2026-11-26T10:15:00.123Z_../x",
            "2026-11-26T10:15:00Z_exp-1",
        ] {
            assert!(after(Some(bad)).is_err(), "{bad}");
        }
        assert_eq!(after(None).unwrap(), None);
        assert!(limit(Some(0)).is_err() && limit(Some(1001)).is_err());
        assert_eq!(limit(None).unwrap(), 50);
    }
}
