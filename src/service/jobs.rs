//! Long work as jobs: experiments on the bench, analyses, comparisons and diagnoses of datasets.
//! A job is a run in the store; it is queued, then one worker per lane runs it — one experiment at
//! a time on the bench lane, others wait their turn — and its events go to the run's log and to
//! live subscribers (SSE). Cancellation is cooperative: the work checks its token between steps.

use crate::diagnose::{CameraCard, Comparison, PerpendicularityReading, Rounds};
use crate::experiment::RunSink;
use crate::run_event::EventKind;
use crate::service::job::OnBenchCapture;
use crate::store::{DatasetId, Event, RunId, RunKind, RunRecord, RunStatus, RunStore, StoreError};
use crate::study::StudyRow;
use serde_json::Value;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{mpsc, Arc, Mutex, OnceLock};
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
    /// A calibration: its diagnosis rounds, the camera card, and the dataset its runs became.
    Calibration {
        rounds: Box<Rounds>,
        card: Box<CameraCard>,
        dataset: DatasetId,
    },
    /// A diagnosis completed on the bench: the stored dataset's rounds, what the bench
    /// captured and the merged dataset, and the rounds on it (none when the first diagnosis
    /// left nothing a bench's runs resolve).
    OnBench {
        before: Box<Rounds>,
        bench: Box<OnBenchCapture>,
        after: Option<Box<Rounds>>,
    },
    /// A perpendicularity check's reading.
    Perpendicularity(Box<PerpendicularityReading>),
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
    waiting: WaitingSlot,
}

/// A queued job's place in its lane's count of waiting jobs, given back once: by the worker
/// that takes the job, or by a cancel before that (a cancelled job then no longer holds a slot
/// while it waits to be skipped).
#[derive(Clone)]
struct WaitingSlot {
    count: Arc<AtomicUsize>,
    given_back: Arc<AtomicBool>,
}

impl WaitingSlot {
    fn give_back(&self) {
        if !self.given_back.swap(true, Ordering::SeqCst) {
            self.count.fetch_sub(1, Ordering::SeqCst);
        }
    }
}

/// A run's live event channel, made by its first subscriber: 3,000 queued jobs once took a
/// 256-slot channel each up front (+113 MB) that nobody listened to.
type LiveEvents = Arc<OnceLock<broadcast::Sender<Event>>>;

/// Sends `event` to a run's subscribers, if it has any.
fn send_live(events: &LiveEvents, event: Event) {
    if let Some(tx) = events.get() {
        let _ = tx.send(event);
    }
}

struct Live {
    cancel: CancellationToken,
    events: LiveEvents,
    /// Set when the work has returned: a run still not terminal then is one whose end could not
    /// be written yet (a full disk), which cancel ends itself.
    work_done: Arc<AtomicBool>,
    waiting: WaitingSlot,
}

/// The context a job runs in; also the experiment runner's [`RunSink`].
pub struct JobContext {
    pub run_id: RunId,
    store: Arc<RunStore>,
    events: LiveEvents,
    cancel: CancellationToken,
}

impl JobContext {
    pub fn store(&self) -> &RunStore {
        &self.store
    }
}

impl RunSink for JobContext {
    fn event(&self, kind: EventKind, progress: f64, message: &str, data: Value) {
        let _ = self.store.set_progress(&self.run_id, progress, message);
        match self
            .store
            .append_event(&self.run_id, kind, progress, message, data)
        {
            Ok(e) => send_live(&self.events, e),
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

/// A lane's queue is full: the job was not queued.
#[derive(Debug, thiserror::Error)]
pub enum QueueError {
    #[error("{queued} jobs are waiting on the {lane:?} lane, its limit (jobs.max_queued_per_lane): try again later")]
    Full { lane: Lane, queued: usize },
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// What every worker shares with [`Jobs`].
#[derive(Clone)]
struct Shared {
    store: Arc<RunStore>,
    live: Arc<Mutex<HashMap<RunId, Live>>>,
    kept: KeptResults,
    /// Set when the server begins to stop: no job starts after it.
    stopping: Arc<AtomicBool>,
    /// Called by a lane's worker after each job it ran has ended (the store's retention).
    after_each: Arc<OnceLock<AfterEachJob>>,
}

/// What a lane's worker does after each job it ran (see [`Jobs::after_each_job`]).
pub type AfterEachJob = Box<dyn Fn() + Send + Sync>;

pub struct Jobs {
    shared: Shared,
    lanes: Mutex<HashMap<Lane, mpsc::Sender<Queued>>>,
    /// Jobs sent to each lane and not yet taken by its worker.
    waiting: HashMap<Lane, Arc<AtomicUsize>>,
    max_waiting: usize,
    workers: Mutex<Vec<(Lane, std::thread::JoinHandle<()>)>>,
}

impl Jobs {
    /// Lanes with no limit on waiting jobs (a process that submits its own, `ffdic reproduce`).
    pub fn start(store: Arc<RunStore>) -> Arc<Self> {
        Self::with_queue_limit(store, usize::MAX)
    }

    /// Lanes on which at most `max_waiting` jobs wait each ([`QueueError::Full`] beyond).
    pub fn with_queue_limit(store: Arc<RunStore>, max_waiting: usize) -> Arc<Self> {
        const LANES: [Lane; 2] = [Lane::Bench, Lane::Compute];
        let jobs = Arc::new(Self {
            shared: Shared {
                store,
                live: Arc::new(Mutex::new(HashMap::new())),
                kept: Arc::new(Mutex::new(None)),
                stopping: Arc::new(AtomicBool::new(false)),
                after_each: Arc::default(),
            },
            lanes: Mutex::new(HashMap::new()),
            waiting: LANES.iter().map(|&l| (l, Arc::default())).collect(),
            max_waiting,
            workers: Mutex::new(Vec::new()),
        });
        for lane in LANES {
            let (tx, rx) = mpsc::channel::<Queued>();
            let shared = jobs.shared.clone();
            let handle = std::thread::Builder::new()
                .name(format!("jobs-{lane:?}").to_lowercase())
                .spawn(move || worker(rx, shared))
                .expect("spawn a job worker");
            jobs.lanes.lock().expect("lanes").insert(lane, tx);
            jobs.workers.lock().expect("workers").push((lane, handle));
        }
        jobs
    }

    pub fn store(&self) -> &Arc<RunStore> {
        &self.shared.store
    }

    /// Has each lane's worker call `f` after every job it ran has ended (once set, for good).
    pub fn after_each_job(&self, f: AfterEachJob) {
        if self.shared.after_each.set(f).is_err() {
            tracing::warn!("after_each_job set twice: the first stays");
        }
    }

    /// From now on, keeps every successful job's typed result until [`Jobs::take_result`]
    /// takes it: for a caller in this process that waits for its jobs (`ffdic reproduce`); a
    /// daemon does not keep them (nobody would take them).
    pub fn keep_results(&self) {
        self.shared
            .kept
            .lock()
            .expect("kept results")
            .get_or_insert_with(HashMap::new);
    }

    /// The typed result of run `id`, once it has succeeded (with [`Jobs::keep_results`]).
    pub fn take_result(&self, id: &RunId) -> Option<JobResult> {
        self.shared
            .kept
            .lock()
            .expect("kept results")
            .as_mut()?
            .remove(id)
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
    /// idempotency key made (`false`: nothing new was queued). Refused, with nothing written,
    /// when `lane` already has its limit of jobs waiting.
    pub fn submit(
        &self,
        kind: RunKind,
        lane: Lane,
        request: Value,
        idempotency_key: Option<&str>,
        dataset_id: Option<DatasetId>,
        work: Work,
    ) -> Result<(RunRecord, bool), QueueError> {
        let waiting = &self.waiting[&lane];
        // Reserved before the run is written, so concurrent submissions cannot pass the limit;
        // given back on every way out but a queued job's.
        let before = waiting.fetch_add(1, Ordering::SeqCst);
        let slot = WaitingSlot {
            count: waiting.clone(),
            given_back: Arc::default(),
        };
        if before >= self.max_waiting {
            slot.give_back();
            return Err(QueueError::Full {
                lane,
                queued: before,
            });
        }
        let store = &self.shared.store;
        let record = match store.create_run(kind, request, idempotency_key, dataset_id) {
            Ok((record, true)) => record,
            other => {
                slot.give_back();
                return Ok(other?);
            }
        };
        self.shared.live.lock().expect("live").insert(
            record.id.clone(),
            Live {
                cancel: CancellationToken::new(),
                events: LiveEvents::default(),
                work_done: Arc::new(AtomicBool::new(false)),
                waiting: slot.clone(),
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
                    waiting: slot.clone(),
                })
                .is_ok()
            })
            .unwrap_or(false);
        if !sent {
            slot.give_back();
            let _ = store.set_status(
                &record.id,
                RunStatus::Failed,
                "the server is shutting down and takes no more work",
            );
        }
        Ok((store.get(&record.id)?, true))
    }

    /// Live events of a run still queued or running (`None` once it has ended); the run's
    /// channel is made by its first subscriber.
    pub fn subscribe(&self, id: &RunId) -> Option<broadcast::Receiver<Event>> {
        self.shared.live.lock().expect("live").get(id).map(|l| {
            l.events
                .get_or_init(|| broadcast::channel(LIVE_EVENTS).0)
                .subscribe()
        })
    }

    /// Asks a run to stop. A queued run is cancelled at once; a running one at its next check.
    pub fn cancel(&self, id: &RunId) -> Result<RunRecord, StoreError> {
        let store = &self.shared.store;
        let record = store.get(id)?;
        if record.status.is_terminal() {
            return Err(StoreError::Finished(id.clone()));
        }
        let work_done = match self.shared.live.lock().expect("live").get(id) {
            Some(live) => {
                live.cancel.cancel();
                if record.status == RunStatus::Queued {
                    live.waiting.give_back();
                }
                live.work_done.load(Ordering::SeqCst)
            }
            // Not queued or running here: a run of another process's lifetime, left behind.
            None => true,
        };
        if record.status == RunStatus::Running && work_done {
            // Nothing will check the token any more: end the run here, or say why not.
            let r = store.set_status(
                id,
                RunStatus::Cancelled,
                "cancelled after its work had ended (its end could not be recorded)",
            )?;
            self.shared.publish_last(id);
            return Ok(r);
        }
        if record.status == RunStatus::Queued {
            let r = store.set_status(id, RunStatus::Cancelled, "cancelled before it started")?;
            self.shared.publish_last(id);
            return Ok(r);
        }
        store.get(id)
    }

    /// Stops taking work and cancels every queued and running run (the running ones at their
    /// next check): no job starts after this is called, the tokens are cancelled first (in
    /// memory), then the queued runs are written as cancelled in one batch. Returns at once:
    /// what comes first when the daemon is asked to stop.
    pub fn cancel_all(&self) {
        self.shared.stopping.store(true, Ordering::SeqCst);
        self.lanes.lock().expect("lanes").clear();
        let ids: Vec<RunId> = {
            let live = self.shared.live.lock().expect("live");
            for l in live.values() {
                l.cancel.cancel();
            }
            live.keys().cloned().collect()
        };
        match self.shared.store.end_queued(
            &ids,
            RunStatus::Cancelled,
            "cancelled: the server shut down",
        ) {
            Ok(ended) => {
                for id in &ended {
                    self.shared.publish_last(id);
                }
            }
            Err(e) => tracing::warn!("cannot record the queued runs as cancelled: {e}"),
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

/// Capacity of a run's live channel: a subscriber that falls this far behind re-reads the log.
const LIVE_EVENTS: usize = 256;

impl Shared {
    /// Sends the run's last stored event to live subscribers (if it has any) and forgets the
    /// run.
    fn publish_last(&self, id: &RunId) {
        let entry = self.live.lock().expect("live").remove(id);
        let Some(tx) = entry.as_ref().and_then(|l| l.events.get()) else {
            return;
        };
        if let Ok(events) = self.store.events(id, None) {
            if let Some(last) = events.last() {
                let _ = tx.send(last.clone());
            }
        }
    }
}

fn worker(rx: mpsc::Receiver<Queued>, shared: Shared) {
    let store = &shared.store;
    while let Ok(job) = rx.recv() {
        job.waiting.give_back();
        let Some((cancel, events, work_done)) = shared
            .live
            .lock()
            .expect("live")
            .get(&job.id)
            .map(|l| (l.cancel.clone(), l.events.clone(), l.work_done.clone()))
        else {
            continue;
        };
        // Cancelled while queued (already written as such), or the server is stopping.
        if cancel.is_cancelled() || shared.stopping.load(Ordering::SeqCst) {
            if let Ok(r) = store.get(&job.id) {
                if !r.status.is_terminal() {
                    let _ = store.set_status(&job.id, RunStatus::Cancelled, "cancelled");
                }
            }
            shared.publish_last(&job.id);
            continue;
        }
        if let Err(e) = store.set_status(&job.id, RunStatus::Running, "running") {
            tracing::warn!(run = %job.id, "cannot start: {e}");
            shared.publish_last(&job.id);
            continue;
        }
        if events.get().is_some() {
            if let Ok(events_so_far) = store.events(&job.id, None) {
                if let Some(last) = events_so_far.last() {
                    send_live(&events, last.clone());
                }
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
                if let Some(results) = shared.kept.lock().expect("kept results").as_mut() {
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
                shared.publish_last(&job.id);
            }
            Err(StoreError::Finished(_)) => shared.publish_last(&job.id),
            Err(e) => {
                tracing::warn!(run = %job.id, "cannot record the end ({status:?}): {e}");
                record_end_when_possible(shared.clone(), job.id, status, message);
            }
        }
        if let Some(after) = shared.after_each.get() {
            after();
        }
    }
}

/// How often a run whose end could not be written tries again.
const END_RETRY: Duration = Duration::from_millis(500);

/// A run whose terminal write failed (a full disk, say) would otherwise stay `running` for ever:
/// retry in the background until the store takes it — as `failed`, since the run's files may be
/// incomplete — or until someone else (cancel) has ended it.
fn record_end_when_possible(shared: Shared, id: RunId, status: RunStatus, message: String) {
    let spawned = std::thread::Builder::new()
        .name("jobs-end-retry".into())
        .spawn(move || {
            let message = format!(
                "could not record the end of the run when it came ({}: {message}); its files may be incomplete",
                status.as_str()
            );
            loop {
                std::thread::sleep(END_RETRY);
                match shared.store.set_status(&id, RunStatus::Failed, &message) {
                    Ok(_) | Err(StoreError::Finished(_)) => break,
                    Err(StoreError::NotFound(_)) => return,
                    Err(_) => continue,
                }
            }
            tracing::info!(run = %id, "end recorded after a failed write");
            shared.publish_last(&id);
        });
    if let Err(e) = spawned {
        tracing::error!("cannot start the end-retry thread: {e}");
    }
}
