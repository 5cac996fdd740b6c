//! The bench actor: one thread alone owns the camera and the stage; everybody else — the
//! experiment runner, the HTTP handlers — sends it commands over a channel and waits for the
//! reply (the pattern of strand-braid's `cam_arg_task`). Driver calls block, so the actor lives on
//! a thread of its own, never on the async runtime.
//!
//! While an experiment holds the bench (a [`BenchLease`]), direct control is refused with
//! [`BenchError::Busy`]: a person nudging the stage mid-experiment would corrupt the measurement.

use crate::model::SpecklePattern;
use ffdic_hw::{
    Camera, CameraCounters, CameraInfo, CameraSettings, Frame, HwError, Stage, StageInfo,
    StagePosition,
};
use serde::Serialize;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// How often a caller waiting on the bench is asked whether it still wants the answer.
const STOP_POLL: Duration = Duration::from_millis(50);

/// Puts a speckle target in front of the camera. The mock bench swaps the scene it renders; on a
/// real bench a person mounts the one target by hand, and there is no mount.
pub trait TargetMount: Send {
    fn mount(&mut self, label: &str, pattern: &SpecklePattern, seed: u64) -> Result<(), HwError>;
    /// The area a mounted print covers (mm, relative to the optical axis at the reference
    /// position): what sizes its layout.
    fn field_mm(&self) -> (f64, f64, f64, f64);
}

/// What the bench actor owns.
pub struct BenchHardware {
    pub camera: Box<dyn Camera>,
    pub stage: Option<Box<dyn Stage>>,
    pub targets: Option<Box<dyn TargetMount>>,
}

#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(transparent)]
    Hw(#[from] HwError),
    #[error("the bench is held by run {holder}")]
    Busy { holder: String },
    #[error("no stage is configured")]
    NoStage,
    #[error("this bench has no target changer: mount the target by hand and name one pattern")]
    NoTargetMount,
    #[error("the bench did not answer within {after_ms} ms")]
    Unresponsive { after_ms: u64 },
    #[error("the bench actor has stopped")]
    Stopped,
    /// A driver or the mock scene panicked inside a command: the command failed, the actor
    /// goes on (the stage is stopped first).
    #[error("the bench failed inside a command: {0}")]
    Panicked(String),
}

/// The state of the bench as one snapshot.
#[derive(Clone, Debug, Serialize)]
pub struct BenchStatus {
    pub camera: CameraStatus,
    pub stage: Option<StageStatus>,
    /// The run holding the bench, if any.
    pub holder: Option<String>,
    /// The target in front of the camera (mock bench) or `None` when unknown.
    pub target: Option<String>,
    pub has_target_mount: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct CameraStatus {
    pub info: CameraInfo,
    pub settings: CameraSettings,
    pub counters: CameraCounters,
}

#[derive(Clone, Debug, Serialize)]
pub struct StageStatus {
    pub info: StageInfo,
    pub position: Option<StagePosition>,
    pub homed: bool,
    /// Why the position could not be read, if it could not.
    pub error: Option<String>,
}

/// Who sends a command: a person or client directly, or the run that holds the bench.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Owner {
    Direct,
    Run(String),
}

/// The channel one command is answered on: each command carries its own, typed by what it
/// answers, so a reply cannot be of the wrong kind.
type Reply<T> = mpsc::SyncSender<Result<T, BenchError>>;

enum Command {
    Status(Reply<BenchStatus>),
    ApplyCamera(CameraSettings, Reply<CameraSettings>),
    Capture {
        count: usize,
        timeout: Duration,
        reply: Reply<Vec<Frame>>,
    },
    Home {
        timeout: Duration,
        reply: Reply<()>,
    },
    MoveTo {
        target: StagePosition,
        settle_timeout: Duration,
        reply: Reply<StagePosition>,
    },
    MoveBy {
        dx_mm: f64,
        dy_mm: f64,
        settle_timeout: Duration,
        reply: Reply<StagePosition>,
    },
    StopStage(Reply<()>),
    Mount {
        label: String,
        pattern: Box<SpecklePattern>,
        seed: u64,
        reply: Reply<()>,
    },
}

/// What a command may do while a run holds the bench.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Access {
    /// Reads: always allowed.
    Read,
    /// Changes the bench: the holder only.
    Change,
    /// A stop is a safety action: anyone may stop the stage.
    Stop,
}

struct Request {
    owner: Owner,
    command: Command,
}

/// A cloneable handle to the bench actor. Every call blocks until the actor answers; async
/// callers wrap it in `spawn_blocking`.
#[derive(Clone)]
pub struct BenchHandle {
    tx: mpsc::Sender<Request>,
    holder: Arc<Mutex<Option<String>>>,
    /// False once the actor thread has ended (for whatever reason): `/health` reports it.
    alive: Arc<AtomicBool>,
    /// False while the stage's last answer was `Disconnected`: `/health` reports it.
    stage_link: Arc<AtomicBool>,
    /// How long a caller waits for the actor before giving up (it may be inside a long capture).
    reply_timeout: Duration,
}

/// The bench held by one run; released when dropped.
pub struct BenchLease {
    handle: BenchHandle,
    pub run_id: String,
}

impl Drop for BenchLease {
    fn drop(&mut self) {
        let mut h = self.handle.holder.lock().expect("holder lock");
        if h.as_deref() == Some(self.run_id.as_str()) {
            *h = None;
        }
    }
}

impl BenchHandle {
    /// Starts the actor thread, which owns `hardware` until every handle is dropped.
    pub fn spawn(hardware: BenchHardware, reply_timeout: Duration) -> Self {
        let (tx, rx) = mpsc::channel::<Request>();
        let holder = Arc::new(Mutex::new(None));
        let actor_holder = holder.clone();
        let alive = Arc::new(AtomicBool::new(true));
        let flag = AliveFlag(alive.clone());
        let stage_link = Arc::new(AtomicBool::new(true));
        let actor_link = stage_link.clone();
        std::thread::Builder::new()
            .name("bench-actor".into())
            .spawn(move || {
                let _flag = flag;
                Actor::new(hardware, actor_holder, actor_link).serve(rx)
            })
            .expect("spawn the bench actor thread");
        Self {
            tx,
            holder,
            alive,
            stage_link,
            reply_timeout,
        }
    }

    /// Whether the actor thread still runs.
    pub fn is_alive(&self) -> bool {
        self.alive.load(Ordering::SeqCst)
    }

    /// Whether the stage answered its last call (false after a `Disconnected`: unplugged or
    /// powered off; true again once it answers). No I/O: `/health` asks it every second.
    pub fn stage_connected(&self) -> bool {
        self.stage_link.load(Ordering::SeqCst)
    }

    /// Takes the bench for `run_id`; direct control gets `Busy` until the lease is dropped.
    pub fn hold(&self, run_id: &str) -> Result<BenchLease, BenchError> {
        let mut h = self.holder.lock().expect("holder lock");
        if let Some(other) = h.as_ref() {
            return Err(BenchError::Busy {
                holder: other.clone(),
            });
        }
        *h = Some(run_id.to_string());
        Ok(BenchLease {
            handle: self.clone(),
            run_id: run_id.to_string(),
        })
    }

    pub fn holder(&self) -> Option<String> {
        self.holder.lock().expect("holder lock").clone()
    }

    /// Sends the command `make` builds around a reply channel and waits up to `wait` for the
    /// answer.
    fn call<T>(
        &self,
        owner: Owner,
        make: impl FnOnce(Reply<T>) -> Command,
        wait: Duration,
    ) -> Result<T, BenchError> {
        self.call_until(owner, make, wait, &|| false)
            .map(|answer| answer.expect("never asked to stop"))
    }

    /// [`Self::call`], asking `stop` every [`STOP_POLL`] while it waits: `Ok(None)` once it said
    /// so. The command itself runs to its end on the bench (an exposure is not cut short; the
    /// next command queues behind it) and its answer is dropped.
    fn call_until<T>(
        &self,
        owner: Owner,
        make: impl FnOnce(Reply<T>) -> Command,
        wait: Duration,
        stop: &dyn Fn() -> bool,
    ) -> Result<Option<T>, BenchError> {
        let (reply, rx) = mpsc::sync_channel(1);
        self.tx
            .send(Request {
                owner,
                command: make(reply),
            })
            .map_err(|_| BenchError::Stopped)?;
        let deadline = Instant::now() + wait;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match rx.recv_timeout(left.min(STOP_POLL)) {
                Ok(result) => return result.map(Some),
                Err(mpsc::RecvTimeoutError::Timeout) if left > STOP_POLL => {
                    if stop() {
                        return Ok(None);
                    }
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    return Err(BenchError::Unresponsive {
                        after_ms: wait.as_millis() as u64,
                    })
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => return Err(BenchError::Stopped),
            }
        }
    }

    pub fn status(&self) -> Result<BenchStatus, BenchError> {
        self.call(Owner::Direct, Command::Status, self.reply_timeout)
    }

    pub fn apply_camera(
        &self,
        owner: Owner,
        settings: CameraSettings,
    ) -> Result<CameraSettings, BenchError> {
        self.call(
            owner,
            |reply| Command::ApplyCamera(settings, reply),
            self.reply_timeout,
        )
    }

    /// `count` frames, each within `timeout`.
    pub fn capture(
        &self,
        owner: Owner,
        count: usize,
        timeout: Duration,
    ) -> Result<Vec<Frame>, BenchError> {
        self.capture_until(owner, count, timeout, &|| false)
            .map(|frames| frames.expect("never asked to stop"))
    }

    /// [`Self::capture`], no longer waited for once `stop` says so (`Ok(None)`): a cancelled
    /// run ends while a slow frame (a 2560x2160 mock exposure takes half a second) is still
    /// being read.
    pub fn capture_until(
        &self,
        owner: Owner,
        count: usize,
        timeout: Duration,
        stop: &dyn Fn() -> bool,
    ) -> Result<Option<Vec<Frame>>, BenchError> {
        let wait = self.reply_timeout + timeout * count as u32;
        self.call_until(
            owner,
            |reply| Command::Capture {
                count,
                timeout,
                reply,
            },
            wait,
            stop,
        )
    }

    pub fn home(&self, owner: Owner, timeout: Duration) -> Result<(), BenchError> {
        self.call(
            owner,
            |reply| Command::Home { timeout, reply },
            self.reply_timeout + timeout,
        )
    }

    /// Moves to `target` and waits until the stage has settled there.
    pub fn move_to(
        &self,
        owner: Owner,
        target: StagePosition,
        settle_timeout: Duration,
    ) -> Result<StagePosition, BenchError> {
        let cmd = |reply| Command::MoveTo {
            target,
            settle_timeout,
            reply,
        };
        self.call(owner, cmd, self.reply_timeout + settle_timeout)
    }

    pub fn move_by(
        &self,
        owner: Owner,
        dx_mm: f64,
        dy_mm: f64,
        settle_timeout: Duration,
    ) -> Result<StagePosition, BenchError> {
        let cmd = |reply| Command::MoveBy {
            dx_mm,
            dy_mm,
            settle_timeout,
            reply,
        };
        self.call(owner, cmd, self.reply_timeout + settle_timeout)
    }

    pub fn stop_stage(&self, owner: Owner) -> Result<(), BenchError> {
        self.call(owner, Command::StopStage, self.reply_timeout)
    }

    /// Asks the actor to stop the stage next, without waiting: a run that failed or was
    /// cancelled ends while the command before (a slow exposure) finishes; the stop still runs
    /// before anything sent after it (the actor takes its commands in order), and a stop is
    /// admitted whoever holds the bench.
    pub fn stop_stage_soon(&self) -> Result<(), BenchError> {
        let (reply, _dropped) = mpsc::sync_channel(1);
        self.tx
            .send(Request {
                owner: Owner::Direct,
                command: Command::StopStage(reply),
            })
            .map_err(|_| BenchError::Stopped)
    }

    pub fn mount(
        &self,
        owner: Owner,
        label: &str,
        pattern: &SpecklePattern,
        seed: u64,
    ) -> Result<(), BenchError> {
        let cmd = |reply| Command::Mount {
            label: label.to_string(),
            pattern: Box::new(pattern.clone()),
            seed,
            reply,
        };
        self.call(owner, cmd, self.reply_timeout)
    }
}

/// Clears the alive flag when the actor thread ends, by return or by unwinding.
struct AliveFlag(Arc<AtomicBool>);

impl Drop for AliveFlag {
    fn drop(&mut self) {
        self.0.store(false, Ordering::SeqCst);
    }
}

/// The text of a panic payload (`panic!` with a literal or a formatted message).
pub fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into())
}

struct Actor {
    hw: BenchHardware,
    holder: Arc<Mutex<Option<String>>>,
    homed: bool,
    stage_link: Arc<AtomicBool>,
    target: Option<String>,
}

impl Actor {
    fn new(
        hw: BenchHardware,
        holder: Arc<Mutex<Option<String>>>,
        stage_link: Arc<AtomicBool>,
    ) -> Self {
        Self {
            hw,
            holder,
            homed: false,
            stage_link,
            target: None,
        }
    }

    fn serve(mut self, rx: mpsc::Receiver<Request>) {
        // Ends when every handle is gone: the stage is left stopped.
        while let Ok(req) = rx.recv() {
            self.run(&req.owner, req.command);
        }
        if let Some(stage) = self.hw.stage.as_mut() {
            let _ = stage.stop();
        }
    }

    /// Reads are always allowed; anything that changes the bench needs the holder's lease.
    fn admit(&self, owner: &Owner, access: Access) -> Result<(), BenchError> {
        if access == Access::Read {
            return Ok(());
        }
        let holder = self.holder.lock().expect("holder lock").clone();
        match (holder, owner) {
            (None, _) => Ok(()),
            (Some(h), Owner::Run(r)) if &h == r => Ok(()),
            (Some(_), Owner::Direct) if access == Access::Stop => Ok(()),
            (Some(h), _) => Err(BenchError::Busy { holder: h }),
        }
    }

    /// Answers on `reply` what `work` returns, once `owner` is admitted. A panic in a driver or
    /// the mock scene fails this command only; the actor, and with it the bench, stays up for
    /// the next one. The caller may have given up waiting; that is its business.
    fn answer<T>(
        &mut self,
        owner: &Owner,
        access: Access,
        reply: Reply<T>,
        work: impl FnOnce(&mut Self) -> Result<T, BenchError>,
    ) {
        let result = match self.admit(owner, access) {
            Err(e) => Err(e),
            Ok(()) => match std::panic::catch_unwind(AssertUnwindSafe(|| work(self))) {
                Ok(result) => result,
                Err(panic) => {
                    let what = panic_message(&panic);
                    tracing::error!("bench command panicked: {what}");
                    if let Some(stage) = self.hw.stage.as_mut() {
                        let _ = stage.stop();
                    }
                    Err(BenchError::Panicked(what))
                }
            },
        };
        let _ = reply.send(result);
    }

    /// One call to the stage. A `Disconnected` answer marks the stage lost and unhomed (a
    /// controller that comes back, reopened by its driver, has lost its reference: `GET /stage`
    /// kept `homed: true` for an unplugged stage); any other answer marks it there.
    fn on_stage<T>(
        &mut self,
        call: impl FnOnce(&mut dyn Stage) -> Result<T, HwError>,
    ) -> Result<T, BenchError> {
        let stage = self.hw.stage.as_mut().ok_or(BenchError::NoStage)?;
        let result = call(stage.as_mut());
        let lost = matches!(result, Err(HwError::Disconnected(_)));
        self.stage_link.store(!lost, Ordering::SeqCst);
        if lost {
            self.homed = false;
        }
        Ok(result?)
    }

    fn run(&mut self, owner: &Owner, command: Command) {
        use Access::{Change, Read, Stop};
        match command {
            Command::Status(reply) => self.answer(owner, Read, reply, |a| Ok(a.status())),
            Command::ApplyCamera(s, reply) => {
                self.answer(owner, Change, reply, |a| Ok(a.hw.camera.apply(&s)?))
            }
            Command::Capture {
                count,
                timeout,
                reply,
            } => self.answer(owner, Change, reply, |a| {
                Ok(a.hw.camera.acquire(count, timeout)?)
            }),
            Command::Home { timeout, reply } => self.answer(owner, Change, reply, |a| {
                a.on_stage(|s| s.home(timeout))?;
                a.homed = true;
                Ok(())
            }),
            Command::MoveTo {
                target,
                settle_timeout,
                reply,
            } => self.answer(owner, Change, reply, |a| {
                a.on_stage(|s| {
                    s.move_absolute(target)?;
                    s.wait_settled(settle_timeout)
                })
            }),
            Command::MoveBy {
                dx_mm,
                dy_mm,
                settle_timeout,
                reply,
            } => self.answer(owner, Change, reply, |a| {
                a.on_stage(|s| {
                    s.move_relative(dx_mm, dy_mm)?;
                    s.wait_settled(settle_timeout)
                })
            }),
            Command::StopStage(reply) => {
                self.answer(owner, Stop, reply, |a| a.on_stage(|s| s.stop()))
            }
            Command::Mount {
                label,
                pattern,
                seed,
                reply,
            } => self.answer(owner, Change, reply, |a| {
                let mount = a.hw.targets.as_mut().ok_or(BenchError::NoTargetMount)?;
                mount.mount(&label, &pattern, seed)?;
                a.target = Some(label);
                Ok(())
            }),
        }
    }

    fn status(&mut self) -> BenchStatus {
        let stage = self
            .hw
            .stage
            .as_ref()
            .map(|s| s.info().clone())
            .map(|info| {
                let (position, error) = match self.on_stage(|s| s.position()) {
                    Ok(p) => (Some(p), None),
                    Err(e) => (None, Some(e.to_string())),
                };
                StageStatus {
                    info,
                    position,
                    // Read after the position: a stage found unplugged is no longer homed.
                    homed: self.homed,
                    error,
                }
            });
        BenchStatus {
            camera: CameraStatus {
                info: self.hw.camera.info().clone(),
                settings: self.hw.camera.settings(),
                counters: self.hw.camera.counters(),
            },
            stage,
            holder: self.holder.lock().expect("holder lock").clone(),
            target: self.target.clone(),
            has_target_mount: self.hw.targets.is_some(),
        }
    }
}
