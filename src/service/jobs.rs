//! Long work as jobs: experiments on the bench, analyses, comparisons and diagnoses of datasets.
//! A job is a run in the store; it is queued, then one worker per lane runs it — one experiment at
//! a time on the bench lane, others wait their turn — and its events go to the run's log and to
//! live subscribers (SSE). Cancellation is cooperative: the work checks its token between steps.

use crate::diagnose::{Comparison, Rounds};
use crate::experiment::{RunSink, StudyRow};
use crate::run_event::EventKind;
use crate::store::{DatasetId, Event, RunId, RunKind, RunRecord, RunStatus, RunStore, StoreError};
use serde_json::Value;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::time::Duration;
use tokio::sync::broadcast;
use tokio_util::sync::CancellationToken;

/// Jobs that need the bench run on one lane, compute-only jobs on the other, so an analysis of an
/// uploaded dataset never waits for an experiment (and never takes the bench).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Lane {
    Bench,
    Compute,
}

/// What a job reports when it ends well: a message for its record (the files it wrote are in
/// the record's `result_files`) and its typed result, which a caller in the same process may
/// take ([`Jobs::take_result`]) instead of reading the files back by key.
pub struct JobOutput {
    pub message: String,
    pub result: JobResult,
}

/// A finished job's result as the library holds it.
#[derive(Clone, Debug)]
pub enum JobResult {
    /// An experiment's or an analysis' study: the rows pooled over captures, and every
    /// capture's own rows (empty for a single capture).
    Study {
        rows: Vec<StudyRow>,
        captures: Vec<StudyRow>,
    },
    Comparison(Box<Comparison>),
    /// Every round of a diagnosis and the model with every verdict added.
    Diagnosis(Box<Rounds>),
    /// Nothing beyond the files the job wrote (a design map's merged files).
    Files,
}

/// Results kept for [`Jobs::take_result`]; `None`: none are kept (the daemon's clients read
/// the files).
type KeptResults = Arc<Mutex<Option<HashMap<RunId, JobResult>>>>;

#[derive(Debug, thiserror::Error)]
pub enum JobError {
    #[error("cancelled")]
    Cancelled,
    #[error("{0}")]
    Failed(String),
}

impl JobError {
    /// A failure carrying the error's message (the run's `error` field): for `map_err`.
    pub fn failed(e: impl std::fmt::Display) -> JobError {
        JobError::Failed(e.to_string())
    }
}

pub type Work = Box<dyn FnOnce(&JobContext) -> Result<JobOutput, JobError> + Send>;

struct Queued {
    id: RunId,
    work: Work,
}

struct Live {
    cancel: CancellationToken,
    events: broadcast::Sender<Event>,
    /// Set when the work has returned: a run still not terminal then is one whose end could not
    /// be written yet (a full disk), which cancel ends itself.
    work_done: Arc<AtomicBool>,
}

/// The context a job runs in; also the experiment runner's [`RunSink`].
pub struct JobContext {
    pub run_id: RunId,
    store: Arc<RunStore>,
    events: broadcast::Sender<Event>,
    cancel: CancellationToken,
}

impl JobContext {
    pub fn store(&self) -> &RunStore {
        &self.store
    }

    pub fn is_cancelled(&self) -> bool {
        self.cancel.is_cancelled()
    }
}

impl RunSink for JobContext {
    fn event(&self, kind: EventKind, progress: f64, message: &str, data: Value) {
        let _ = self.store.set_progress(&self.run_id, progress, message);
        match self
            .store
            .append_event(&self.run_id, kind, progress, message, data)
        {
            Ok(e) => {
                let _ = self.events.send(e);
            }
            Err(err) => tracing::warn!(run = %self.run_id, "event not stored: {err}"),
        }
    }

    fn write(&self, rel: &str, bytes: &[u8]) -> Result<PathBuf, String> {
        self.store
            .write_file(&self.run_id, rel, bytes)
            .map_err(|e| e.to_string())
    }

    fn cancelled(&self) -> bool {
        self.cancel.is_cancelled()
    }
}

pub struct Jobs {
    store: Arc<RunStore>,
    live: Arc<Mutex<HashMap<RunId, Live>>>,
    kept: KeptResults,
    lanes: Mutex<HashMap<Lane, mpsc::Sender<Queued>>>,
    workers: Mutex<Vec<(Lane, std::thread::JoinHandle<()>)>>,
}

impl Jobs {
    pub fn start(store: Arc<RunStore>) -> Arc<Self> {
        let jobs = Arc::new(Self {
            store,
            live: Arc::new(Mutex::new(HashMap::new())),
            kept: Arc::new(Mutex::new(None)),
            lanes: Mutex::new(HashMap::new()),
            workers: Mutex::new(Vec::new()),
        });
        for lane in [Lane::Bench, Lane::Compute] {
            let (tx, rx) = mpsc::channel::<Queued>();
            let store = jobs.store.clone();
            let live = jobs.live.clone();
            let kept = jobs.kept.clone();
            let handle = std::thread::Builder::new()
                .name(format!("jobs-{lane:?}").to_lowercase())
                .spawn(move || worker(rx, store, live, kept))
                .expect("spawn a job worker");
            jobs.lanes.lock().expect("lanes").insert(lane, tx);
            jobs.workers.lock().expect("workers").push((lane, handle));
        }
        jobs
    }

    pub fn store(&self) -> &Arc<RunStore> {
        &self.store
    }

    /// From now on, keeps every successful job's typed result until [`Jobs::take_result`]
    /// takes it: for a caller in this process that waits for its jobs (`ffdic reproduce`); a
    /// daemon does not keep them (nobody would take them).
    pub fn keep_results(&self) {
        self.kept
            .lock()
            .expect("kept results")
            .get_or_insert_with(HashMap::new);
    }

    /// The typed result of run `id`, once it has succeeded (with [`Jobs::keep_results`]).
    pub fn take_result(&self, id: &RunId) -> Option<JobResult> {
        self.kept.lock().expect("kept results").as_mut()?.remove(id)
    }

    /// Lanes whose worker has ended although the server still takes work: `/health` reports
    /// them (a job's panic is caught and fails the job only, so this means a bug).
    pub fn dead_lanes(&self) -> Vec<Lane> {
        let taking_work = !self.lanes.lock().expect("lanes").is_empty();
        if !taking_work {
            return Vec::new();
        }
        self.workers
            .lock()
            .expect("workers")
            .iter()
            .filter(|(_, h)| h.is_finished())
            .map(|(lane, _)| *lane)
            .collect()
    }

    /// Queues `work` as a new run, or returns the run an earlier request with the same
    /// idempotency key made (`false`: nothing new was queued).
    pub fn submit(
        &self,
        kind: RunKind,
        lane: Lane,
        request: Value,
        idempotency_key: Option<&str>,
        dataset_id: Option<DatasetId>,
        work: Work,
    ) -> Result<(RunRecord, bool), StoreError> {
        let (record, created) =
            self.store
                .create_run(kind, request, idempotency_key, dataset_id)?;
        if !created {
            return Ok((record, false));
        }
        let (events, _) = broadcast::channel(256);
        self.live.lock().expect("live").insert(
            record.id.clone(),
            Live {
                cancel: CancellationToken::new(),
                events,
                work_done: Arc::new(AtomicBool::new(false)),
            },
        );
        let sent = self
            .lanes
            .lock()
            .expect("lanes")
            .get(&lane)
            .map(|tx| {
                tx.send(Queued {
                    id: record.id.clone(),
                    work,
                })
                .is_ok()
            })
            .unwrap_or(false);
        if !sent {
            let _ = self.store.set_status(
                &record.id,
                RunStatus::Failed,
                "the server is shutting down and takes no more work",
            );
        }
        Ok((self.store.get(&record.id)?, true))
    }

    /// Live events of a run still queued or running (`None` once it has ended).
    pub fn subscribe(&self, id: &RunId) -> Option<broadcast::Receiver<Event>> {
        self.live
            .lock()
            .expect("live")
            .get(id)
            .map(|l| l.events.subscribe())
    }

    /// Asks a run to stop. A queued run is cancelled at once; a running one at its next check.
    pub fn cancel(&self, id: &RunId) -> Result<RunRecord, StoreError> {
        let record = self.store.get(id)?;
        if record.status.is_terminal() {
            return Err(StoreError::Finished(id.clone()));
        }
        let work_done = match self.live.lock().expect("live").get(id) {
            Some(live) => {
                live.cancel.cancel();
                live.work_done.load(Ordering::SeqCst)
            }
            // Not queued or running here: a run of another process's lifetime, left behind.
            None => true,
        };
        if record.status == RunStatus::Running && work_done {
            // Nothing will check the token any more: end the run here, or say why not.
            let r = self.store.set_status(
                id,
                RunStatus::Cancelled,
                "cancelled after its work had ended (its end could not be recorded)",
            )?;
            self.publish_terminal(id);
            return Ok(r);
        }
        if record.status == RunStatus::Queued {
            let r =
                self.store
                    .set_status(id, RunStatus::Cancelled, "cancelled before it started")?;
            self.publish_terminal(id);
            return Ok(r);
        }
        self.store.get(id)
    }

    fn publish_terminal(&self, id: &RunId) {
        publish_last(&self.store, &self.live, id);
    }

    /// Stops taking work and cancels every queued and running run (the running ones at their
    /// next check). Returns at once: what comes first when the daemon is asked to stop.
    pub fn cancel_all(&self) {
        self.lanes.lock().expect("lanes").clear();
        let ids: Vec<RunId> = self.live.lock().expect("live").keys().cloned().collect();
        for id in ids {
            if let Ok(r) = self.store.get(&id) {
                if r.status == RunStatus::Queued {
                    let _ = self.store.set_status(
                        &id,
                        RunStatus::Cancelled,
                        "cancelled: the server shut down",
                    );
                }
            }
            if let Some(l) = self.live.lock().expect("live").get(&id) {
                l.cancel.cancel();
            }
        }
    }

    /// Waits up to `grace` for the workers to write their runs' ends.
    pub fn join_workers(&self, grace: Duration) {
        let deadline = std::time::Instant::now() + grace;
        let handles: Vec<_> = self.workers.lock().expect("workers").drain(..).collect();
        for (_, h) in handles {
            while !h.is_finished() && std::time::Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
            if h.is_finished() {
                let _ = h.join();
            }
        }
    }
}

/// Sends the run's last stored event to live subscribers and forgets the run.
fn publish_last(store: &RunStore, live: &Mutex<HashMap<RunId, Live>>, id: &RunId) {
    let entry = live.lock().expect("live").remove(id);
    if let (Some(l), Ok(events)) = (entry, store.events(id, None)) {
        if let Some(last) = events.last() {
            let _ = l.events.send(last.clone());
        }
    }
}

fn worker(
    rx: mpsc::Receiver<Queued>,
    store: Arc<RunStore>,
    live: Arc<Mutex<HashMap<RunId, Live>>>,
    kept: KeptResults,
) {
    while let Ok(job) = rx.recv() {
        let Some((cancel, events, work_done)) = live
            .lock()
            .expect("live")
            .get(&job.id)
            .map(|l| (l.cancel.clone(), l.events.clone(), l.work_done.clone()))
        else {
            continue;
        };
        // Cancelled while queued: already written as such.
        if cancel.is_cancelled() {
            if let Ok(r) = store.get(&job.id) {
                if !r.status.is_terminal() {
                    let _ = store.set_status(&job.id, RunStatus::Cancelled, "cancelled");
                }
            }
            publish_last(&store, &live, &job.id);
            continue;
        }
        if let Err(e) = store.set_status(&job.id, RunStatus::Running, "running") {
            tracing::warn!(run = %job.id, "cannot start: {e}");
            publish_last(&store, &live, &job.id);
            continue;
        }
        if let Ok(events_so_far) = store.events(&job.id, None) {
            if let Some(last) = events_so_far.last() {
                let _ = events.send(last.clone());
            }
        }
        let ctx = JobContext {
            run_id: job.id.clone(),
            store: store.clone(),
            events,
            cancel: cancel.clone(),
        };
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| (job.work)(&ctx)));
        let (status, message) = match outcome {
            Ok(Ok(out)) => {
                if let Some(results) = kept.lock().expect("kept results").as_mut() {
                    results.insert(job.id.clone(), out.result);
                }
                (RunStatus::Succeeded, out.message)
            }
            Ok(Err(JobError::Cancelled)) => (RunStatus::Cancelled, "cancelled".to_string()),
            Ok(Err(JobError::Failed(m))) => (RunStatus::Failed, m),
            Err(_) => (
                RunStatus::Failed,
                "internal error: the job panicked (see the server log)".to_string(),
            ),
        };
        work_done.store(true, Ordering::SeqCst);
        match store.set_status(&job.id, status, &message) {
            Ok(_) => {
                tracing::info!(run = %job.id, ?status, "{message}");
                publish_last(&store, &live, &job.id);
            }
            Err(StoreError::Finished(_)) => publish_last(&store, &live, &job.id),
            Err(e) => {
                tracing::warn!(run = %job.id, "cannot record the end ({status:?}): {e}");
                record_end_when_possible(store.clone(), live.clone(), job.id, status, message);
            }
        }
    }
}

/// How often a run whose end could not be written tries again.
const END_RETRY: Duration = Duration::from_millis(500);

/// A run whose terminal write failed (a full disk, say) would otherwise stay `running` for ever:
/// retry in the background until the store takes it — as `failed`, since the run's files may be
/// incomplete — or until someone else (cancel) has ended it.
fn record_end_when_possible(
    store: Arc<RunStore>,
    live: Arc<Mutex<HashMap<RunId, Live>>>,
    id: RunId,
    status: RunStatus,
    message: String,
) {
    let spawned = std::thread::Builder::new()
        .name("jobs-end-retry".into())
        .spawn(move || {
            let message = format!(
                "could not record the end of the run when it came ({}: {message}); its files may be incomplete",
                status.as_str()
            );
            loop {
                std::thread::sleep(END_RETRY);
                match store.set_status(&id, RunStatus::Failed, &message) {
                    Ok(_) | Err(StoreError::Finished(_)) => break,
                    Err(StoreError::NotFound(_)) => return,
                    Err(_) => continue,
                }
            }
            tracing::info!(run = %id, "end recorded after a failed write");
            publish_last(&store, &live, &id);
        });
    if let Err(e) = spawned {
        tracing::error!("cannot start the end-retry thread: {e}");
    }
}
