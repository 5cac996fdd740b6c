//! The accept loop. `axum::serve` keeps a connection for as long as the client wants and waits
//! for every open request at shutdown; a daemon left beside a bench for weeks cannot. Here each
//! connection is HTTP/1 with hyper's header-read timer (it runs from the moment a connection is
//! idle, so it bounds both a client that never sends a head and an idle keep-alive), the number
//! of open connections is capped (over the cap a connection is closed as soon as it is
//! accepted, so the listen backlog never fills with them) in all and per client address, a write
//! that waits on a client who stopped reading fails after `write_stall_timeout_ms`, and shutdown
//! drains the open requests for a bounded time, then leaves.

use super::parse_errors::ProblemBodies;
use super::stall_guard::StallGuarded;
use crate::service::HttpLimits;
use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::server::graceful::GracefulShutdown;
use hyper_util::service::TowerToHyperService;
use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::Semaphore;
use tokio_util::sync::CancellationToken;

/// Serves `app` on `listener` until `shutdown` is cancelled, then stops accepting, asks every
/// connection to close after its current request and waits at most `limits.drain_ms`.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    shutdown: CancellationToken,
    limits: &HttpLimits,
) -> std::io::Result<()> {
    raise_open_files_limit();
    let slots = Arc::new(Semaphore::new(limits.max_connections));
    let per_client = PerClient::new(limits.max_connections_per_client);
    let write_stall = Duration::from_millis(limits.write_stall_timeout_ms);
    let graceful = GracefulShutdown::new();
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(Duration::from_millis(limits.header_read_timeout_ms))
        .max_buf_size(64 * 1024);
    loop {
        let accepted = tokio::select! {
            _ = shutdown.cancelled() => break,
            a = listener.accept() => a,
        };
        let (stream, peer) = match accepted {
            Ok(s) => s,
            Err(e) => {
                // Out of file descriptors (or a connection reset before accept): back off a
                // little rather than spin; the connections we hold will time out.
                tracing::warn!("accept failed: {e}");
                tokio::time::sleep(Duration::from_millis(50)).await;
                continue;
            }
        };
        let Some(client_slot) = per_client.take(peer.ip()) else {
            tracing::warn!(
                "{} connections open from {}: closing a new one",
                limits.max_connections_per_client,
                peer.ip()
            );
            drop(stream);
            continue;
        };
        let Ok(slot) = slots.clone().try_acquire_owned() else {
            tracing::warn!(
                "{} connections open: closing a new one",
                limits.max_connections
            );
            drop(stream);
            continue;
        };
        let _ = stream.set_nodelay(true);
        let service = TowerToHyperService::new(app.clone());
        let io = TokioIo::new(StallGuarded::new(ProblemBodies::new(stream), write_stall));
        let connection = graceful.watch(http.serve_connection(io, service));
        tokio::spawn(async move {
            // A timed-out or reset connection is the client's business, not an error of ours.
            if let Err(e) = connection.await {
                tracing::debug!("connection ended: {e}");
            }
            drop(slot);
            drop(client_slot);
        });
    }
    drop(listener);
    let drain = Duration::from_millis(limits.drain_ms);
    if tokio::time::timeout(drain, graceful.shutdown())
        .await
        .is_err()
    {
        tracing::warn!(
            "open requests did not finish within {} ms: leaving them",
            limits.drain_ms
        );
    }
    Ok(())
}

/// Open connections per client address, each at most `max`: one client (a script opening a
/// connection per frame and never reading) cannot take the slots every other client needs.
#[derive(Clone)]
struct PerClient {
    open: Arc<Mutex<HashMap<IpAddr, usize>>>,
    max: usize,
}

/// One connection's place in [`PerClient`]; given back when dropped.
struct ClientSlot {
    open: Arc<Mutex<HashMap<IpAddr, usize>>>,
    ip: IpAddr,
}

impl PerClient {
    fn new(max: usize) -> Self {
        Self {
            open: Arc::default(),
            max,
        }
    }

    fn take(&self, ip: IpAddr) -> Option<ClientSlot> {
        let mut open = self.open.lock().unwrap_or_else(|e| e.into_inner());
        let n = open.entry(ip).or_insert(0);
        if *n >= self.max {
            return None;
        }
        *n += 1;
        Some(ClientSlot {
            open: self.open.clone(),
            ip,
        })
    }
}

impl Drop for ClientSlot {
    fn drop(&mut self) {
        let mut open = self.open.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(n) = open.get_mut(&self.ip) {
            *n -= 1;
            if *n == 0 {
                open.remove(&self.ip);
            }
        }
    }
}

/// Lifts the soft limit on open files to the hard one: each connection is a descriptor, and the
/// common soft default (1024) is what let 1,100 half-open connections take the daemon offline.
fn raise_open_files_limit() {
    // SAFETY: getrlimit/setrlimit only read and write the struct we pass.
    unsafe {
        let mut l = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut l) == 0 && l.rlim_cur < l.rlim_max {
            let wanted = libc::rlimit {
                rlim_cur: l.rlim_max,
                rlim_max: l.rlim_max,
            };
            if libc::setrlimit(libc::RLIMIT_NOFILE, &wanted) != 0 {
                tracing::debug!("cannot raise the open-files limit");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_client_holds_at_most_its_share_and_gets_it_back() {
        let per_client = PerClient::new(2);
        let a: IpAddr = "127.0.0.2".parse().unwrap();
        let b: IpAddr = "127.0.0.1".parse().unwrap();
        let first = per_client.take(a).unwrap();
        let _second = per_client.take(a).unwrap();
        assert!(per_client.take(a).is_none(), "a third from one address");
        assert!(
            per_client.take(b).is_some(),
            "another address is not held up"
        );
        drop(first);
        assert!(
            per_client.take(a).is_some(),
            "a closed connection gives its slot back"
        );
    }
}
