//! Server-sent events of one run: every stored event after `Last-Event-ID` first, then the live
//! ones as they happen, each with its `id:` so a client that reconnects resumes where it stopped;
//! the stream ends after the run's terminal event, or when the server shuts down.

use crate::service::Service;
use crate::store::{Event as RunEvent, RunId};
use axum::http::HeaderMap;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::IntoResponse;
use std::convert::Infallible;
use std::time::Duration;
use tokio::sync::{broadcast, mpsc};
use tokio_stream::wrappers::ReceiverStream;

/// An SSE response (the stream with its keep-alives).
pub type SseResponse = axum::response::Response;

/// The last event of a stream the server closes before its run has ended: a word of the stream,
/// not a run event (never stored).
const SHUTDOWN_EVENT: &str = "server_shutdown";
/// How long a stream waits, at shutdown, for its run's terminal event.
const SHUTDOWN_WAIT: Duration = Duration::from_secs(2);

/// The `Last-Event-ID` a reconnecting client sends: absent, or an event id (a whole number);
/// anything else is refused (400) rather than silently replaying from the start.
pub fn last_event_id(headers: &HeaderMap) -> Result<Option<u64>, crate::api::ApiError> {
    let Some(v) = headers.get("last-event-id") else {
        return Ok(None);
    };
    v.to_str()
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .map(Some)
        .ok_or_else(|| {
            crate::api::ApiError::bad_request(
                "Last-Event-ID must be an event id (a whole number below 2^64)",
            )
        })
}

fn to_sse(e: &RunEvent) -> Event {
    Event::default()
        .id(e.id.to_string())
        .event(e.kind.as_str())
        .data(serde_json::to_string(e).expect("an event serialises"))
}

pub fn stream(svc: Service, id: RunId, after: Option<u64>) -> SseResponse {
    let (tx, rx) = mpsc::channel(64);
    tokio::spawn(async move {
        // Subscribe before reading the log, so nothing falls between the two.
        let mut live = svc.jobs.subscribe(&id);
        let mut last = after.unwrap_or(0);
        let mut ended = false;
        if !replay(&svc, &id, &mut last, &mut ended, &tx).await {
            return;
        }
        let shutdown = svc.shutdown.clone();
        while !ended {
            let Some(rx) = live.as_mut() else {
                // The run ended before we subscribed: the log has everything.
                let _ = replay(&svc, &id, &mut last, &mut ended, &tx).await;
                return;
            };
            tokio::select! {
                _ = shutdown.cancelled() => {
                    // The server cancels running work before it drains: give the run a moment
                    // to record its end, then close with a terminal event either way.
                    let grace = tokio::time::sleep(SHUTDOWN_WAIT);
                    tokio::pin!(grace);
                    while !ended {
                        tokio::select! {
                            _ = &mut grace => break,
                            got = rx.recv() => match got {
                                Ok(e) if e.id > last => {
                                    if !forward(&e, &mut last, &mut ended, &tx).await {
                                        return;
                                    }
                                }
                                Ok(_) => {}
                                Err(_) => break,
                            }
                        }
                    }
                    // The log may hold the end the live channel missed.
                    let open = ended || replay(&svc, &id, &mut last, &mut ended, &tx).await;
                    if open && !ended {
                        let bye = Event::default().event(SHUTDOWN_EVENT).data(
                            r#"{"message":"the server is shutting down; the run's record stays in the store"}"#,
                        );
                        let _ = tx.send(Ok(bye)).await;
                    }
                    return;
                }
                _ = tx.closed() => return,
                got = rx.recv() => match got {
                    Ok(e) if e.id > last => {
                        if !forward(&e, &mut last, &mut ended, &tx).await {
                            return;
                        }
                    }
                    Ok(_) => {}
                    // Fell behind, or the run ended: the log is the truth.
                    Err(broadcast::error::RecvError::Lagged(_)) => {
                        if !replay(&svc, &id, &mut last, &mut ended, &tx).await {
                            return;
                        }
                    }
                    Err(broadcast::error::RecvError::Closed) => live = None,
                }
            }
        }
    });
    Sse::new(ReceiverStream::new(rx))
        .keep_alive(
            KeepAlive::new()
                .interval(Duration::from_secs(10))
                .text("keep-alive"),
        )
        .into_response()
}

/// Sends the stored events after `last`; false when the client has gone.
async fn replay(
    svc: &Service,
    id: &RunId,
    last: &mut u64,
    ended: &mut bool,
    tx: &mpsc::Sender<Result<Event, Infallible>>,
) -> bool {
    let store = svc.store.clone();
    let key = id.clone();
    let after = *last;
    let events = tokio::task::spawn_blocking(move || store.events(&key, Some(after)))
        .await
        .ok()
        .and_then(Result::ok)
        .unwrap_or_default();
    for e in events {
        if !forward(&e, last, ended, tx).await {
            return false;
        }
    }
    true
}

/// Sends one event and records where the stream stands; false when the client has gone.
async fn forward(
    e: &RunEvent,
    last: &mut u64,
    ended: &mut bool,
    tx: &mpsc::Sender<Result<Event, Infallible>>,
) -> bool {
    *last = e.id;
    *ended = e.kind.is_terminal();
    tx.send(Ok(to_sse(e))).await.is_ok()
}
