//! hyper answers a request it cannot parse itself, before any handler runs: a malformed request
//! line or header (400), a request target over its limit (414), too many headers or too large a
//! head (431), an HTTP version it does not speak (505) — each with `content-length: 0`, then it
//! closes. Every error the API sends is a problem document, and a probe found 16 of these empty
//! ones. This wrapper of the connection recognises that answer as hyper writes it and sends a
//! problem document in its place. The app's own answers never match: every error it sends has a
//! problem body (`guard::as_problem`).

use super::problem::ApiError;
use axum::http::StatusCode;
use std::io;
use std::pin::Pin;
use std::task::{Context, Poll};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

pub struct ProblemBodies<T> {
    inner: T,
    /// The problem answer being written in place of hyper's, and how many of hyper's bytes it
    /// stands for (reported written once it is all out).
    replacing: Option<Replacement>,
}

struct Replacement {
    bytes: Vec<u8>,
    written: usize,
    stands_for: usize,
}

impl<T> ProblemBodies<T> {
    pub fn new(inner: T) -> Self {
        Self {
            inner,
            replacing: None,
        }
    }
}

/// The problem answer for `head` when it is hyper's own empty error answer, whole.
fn replacement_for(head: &[u8]) -> Option<Vec<u8>> {
    let rest = head.strip_prefix(b"HTTP/1.1 ")?;
    let (status, kind, detail) = match rest.get(..3)? {
        b"400" => (
            StatusCode::BAD_REQUEST,
            "bad-request",
            "the request line or a header is malformed",
        ),
        b"414" => (
            StatusCode::URI_TOO_LONG,
            "uri-too-long",
            "the request target is too long",
        ),
        b"431" => (
            StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
            "headers-too-large",
            "the request has too many headers (at most 100) or too large a head",
        ),
        b"505" => (
            StatusCode::HTTP_VERSION_NOT_SUPPORTED,
            "http-version",
            "this server speaks HTTP/1.0 and HTTP/1.1",
        ),
        _ => return None,
    };
    let lower = head.to_ascii_lowercase();
    let empty = lower.windows(21).any(|w| w == b"\r\ncontent-length: 0\r\n");
    if !(empty && lower.ends_with(b"\r\n\r\n")) {
        return None;
    }
    let body = serde_json::to_vec(&ApiError::new(status, kind, detail).problem())
        .expect("a problem serialises");
    let mut out = format!(
        "HTTP/1.1 {} {}\r\ncontent-type: application/problem+json\r\ncontent-length: {}\r\nconnection: close\r\n\r\n",
        status.as_u16(),
        status.canonical_reason().unwrap_or("Error"),
        body.len()
    )
    .into_bytes();
    out.extend_from_slice(&body);
    Some(out)
}

impl<T: AsyncWrite + Unpin> ProblemBodies<T> {
    /// Writes the replacement on; done, it reports hyper's bytes written.
    fn drive(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<usize>> {
        let r = self.replacing.as_mut().expect("a replacement is under way");
        while r.written < r.bytes.len() {
            match Pin::new(&mut self.inner).poll_write(cx, &r.bytes[r.written..]) {
                Poll::Ready(Ok(0)) => return Poll::Ready(Err(io::ErrorKind::WriteZero.into())),
                Poll::Ready(Ok(n)) => r.written += n,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Pending => return Poll::Pending,
            }
        }
        Poll::Ready(Ok(r.stands_for))
    }

    /// Starts a replacement when `head` is hyper's empty error answer (only once: hyper closes
    /// the connection after it).
    fn notice(&mut self, head: &[u8], stands_for: usize) {
        if self.replacing.is_none() {
            if let Some(bytes) = replacement_for(head) {
                self.replacing = Some(Replacement {
                    bytes,
                    written: 0,
                    stands_for,
                });
            }
        }
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for ProblemBodies<T> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for ProblemBodies<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        self.notice(buf, buf.len());
        if self.replacing.is_some() {
            return self.drive(cx);
        }
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        // hyper's error answer is a head alone: one slice (any empty ones aside).
        let mut parts = bufs.iter().filter(|b| !b.is_empty());
        if let (Some(head), None) = (parts.next(), parts.next()) {
            self.notice(head, head.len());
        }
        if self.replacing.is_some() {
            return self.drive(cx);
        }
        Pin::new(&mut self.inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_hypers_empty_error_answers_are_replaced() {
        let hyper_431 = b"HTTP/1.1 431 Request Header Fields Too Large\r\nconnection: close\r\ncontent-length: 0\r\ndate: Thu, 26 Nov 2026 10:57:40 GMT\r\n\r\n";
        let out = String::from_utf8(replacement_for(hyper_431).unwrap()).unwrap();
        let (head, body) = out.split_once("\r\n\r\n").unwrap();
        assert!(head.starts_with("HTTP/1.1 431 "), "{head}");
        assert!(head.contains("content-type: application/problem+json"));
        assert!(head.contains(&format!("content-length: {}", body.len())));
        let problem: serde_json::Value = serde_json::from_str(body).unwrap();
        assert_eq!(problem["status"], 431);
        // An answer with a body, a success, or one cut short: left alone.
        for other in [
            &b"HTTP/1.1 400 Bad Request\r\ncontent-length: 57\r\n\r\n"[..],
            b"HTTP/1.1 204 No Content\r\ncontent-length: 0\r\n\r\n",
            b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n",
            b"HTTP/1.1 404 Not Found\r\ncontent-length: 0\r\n\r\n",
        ] {
            assert!(
                replacement_for(other).is_none(),
                "{:?}",
                String::from_utf8_lossy(other)
            );
        }
    }
}
