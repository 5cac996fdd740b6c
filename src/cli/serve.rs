//! `ffdic serve`: the daemon. With no config it runs the embedded default — the mock bench, data
//! under ./data, 127.0.0.1:8080. SIGINT/SIGTERM stop it within 10 s: no new work, the running
//! experiment cancelled cooperatively and written as cancelled, the stage stopped.

use anyhow::{Context, Result};
use clap::Args;
use ffdic::service::{open_bench, DaemonConfig, Service};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Daemon config (default: the embedded config/ffdic.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Address to listen on, overriding the config (port 0 picks a free port).
    #[arg(long)]
    pub listen: Option<SocketAddr>,
    /// Data folder, overriding the config.
    #[arg(long)]
    pub data: Option<PathBuf>,
}

/// Time the running job gets, after the server has drained (`http.drain_ms`, 3 s by default), to
/// notice its cancellation and write itself as cancelled: the two stay within 10 s.
const SHUTDOWN_GRACE: Duration = Duration::from_secs(5);

/// Threads for blocking work (the store, TIFF headers, file reads of served files): tokio's
/// default of 512 reserves 1 GB of stacks under load.
const MAX_BLOCKING_THREADS: usize = 128;

pub fn run(args: &ServeArgs) -> Result<()> {
    bound_malloc_arenas();
    super::logging::init();
    let mut config = match &args.config {
        Some(p) => DaemonConfig::load(p)?,
        None => DaemonConfig::embedded(),
    };
    if let Some(l) = args.listen {
        config.listen = l;
    }
    if let Some(d) = &args.data {
        config.data_dir = d.clone();
    }
    let addr = config.listen;
    // Refuse an open address without a token before touching hardware or data.
    ffdic::api::check_bind(addr, config.token().as_deref())?;
    let hardware = open_bench(&config)?;
    let (service, recovery) = Service::start(config, hardware)?;
    for id in &recovery.failed {
        tracing::warn!(run = %id, "left unfinished by an earlier server: marked failed");
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .max_blocking_threads(MAX_BLOCKING_THREADS)
        .build()
        .context("cannot start the async runtime")?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .with_context(|| format!("cannot listen on {addr}"))?;
        let bound = listener.local_addr()?;
        // The first line on stdout is the address: scripts and tests that asked for port 0 read it.
        println!("listening on http://{bound}");
        let shutdown = service.shutdown.clone();
        tokio::spawn(wait_for_signal(service.clone()));
        let app = ffdic::api::app(service.clone(), ffdic::dashboard::router());
        ffdic::api::run(listener, app, shutdown, &service.config.http).await?;
        anyhow::Ok(())
    })?;
    tracing::info!("stopping: waiting for cancelled runs to record their end");
    service.stop(SHUTDOWN_GRACE);
    // Blocking tasks still waiting on the bench or the store are left, not waited for.
    runtime.shutdown_timeout(Duration::from_millis(200));
    tracing::info!("stopped");
    Ok(())
}

/// glibc gives each thread that allocates an arena of its own, up to eight per core, and
/// reserves 64 MB of address space for each: an idle daemon reserved 400 MB, and under an
/// address-space limit (`prlimit --as`, a systemd `MemoryMax` on virtual memory) a 32 MB frame
/// buffer could not be had at 1 GiB. Two arenas serve the daemon's few busy threads as well.
fn bound_malloc_arenas() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets an allocator parameter; called before any thread is started.
    unsafe {
        libc::mallopt(libc::M_ARENA_MAX, 2);
    }
}

/// On SIGINT or SIGTERM: cancel the running work first (so an experiment never goes on, let
/// alone succeeds, after the signal), then let the server drain its requests for a bounded time.
async fn wait_for_signal(service: Service) {
    let ctrl_c = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
            .expect("install the SIGTERM handler");
        tokio::select! {
            _ = ctrl_c => {},
            _ = term.recv() => {},
        }
    }
    #[cfg(not(unix))]
    let _ = ctrl_c.await;
    tracing::info!("signal received: cancelling running work, then shutting down");
    let s = service.clone();
    if tokio::task::spawn_blocking(move || s.begin_stop())
        .await
        .is_err()
    {
        service.shutdown.cancel();
    }
}
