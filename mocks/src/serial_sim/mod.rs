//! Serial stage controllers simulated on a pseudo-terminal: Newport SMC100, Zaber ASCII and
//! Thorlabs APT. A client opens [`StageSim::path`] like any serial port (`/dev/pts/N`) and talks
//! the real protocol to a background thread that moves simulated axes with travel time,
//! settling, homing required after power-up, travel limits and limit switches. Faults are
//! injectable ([`SimFaults`], [`StageSim::disconnect`]). Given a [`SharedBench`], the simulator
//! keeps it up to date so a `MockCamera` sees where the stage is.
//!
//! The slave end of the pty stays open in the simulator for its whole life: a pty whose slave
//! was never opened, or was closed, makes every read on the master fail with a hang-up, and the
//! client may open the path only after `spawn` returns.

mod apt;
mod axis;
mod smc100;
mod zaber;

use crate::bench::SharedBench;
use axis::{sync_bench, Leg, SimAxis};
use serialport::{SerialPort, TTYPort};
use std::io::{self, Read, Write};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long the simulator waits for input before it looks at the clock again; sets the time
/// resolution of completion messages and unprompted updates.
const TICK: Duration = Duration::from_millis(1);

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimProtocol {
    Smc100,
    Zaber,
    Apt,
}

impl SimProtocol {
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "smc100" => Some(Self::Smc100),
            "zaber" => Some(Self::Zaber),
            "apt" => Some(Self::Apt),
            _ => None,
        }
    }
}

/// What the simulated controller is like. [`SimConfig::new`] gives each protocol the addresses
/// and units the driver configs default to.
#[derive(Clone, Debug)]
pub struct SimConfig {
    pub protocol: SimProtocol,
    pub speed_mm_per_s: f64,
    /// How long an axis stays busy after arriving (controllers report "moving" until settled).
    pub settle: Duration,
    pub x_travel_mm: (f64, f64),
    /// A second (y) axis with this travel, if any.
    pub y_travel_mm: Option<(f64, f64)>,
    /// SMC100 controller address, Zaber device address, or APT destination byte.
    pub x_address: u8,
    pub y_address: u8,
    /// Where the axes are at power-up (ignored when a bench is given: the bench says).
    pub power_up_mm: (f64, f64),
    /// Zaber: microsteps per mm; APT: encoder counts per mm; SMC100 works in mm.
    pub units_per_mm: f64,
    /// APT: period of the unprompted status updates (real controllers: 100 ms once enabled).
    pub status_interval: Option<Duration>,
}

impl SimConfig {
    pub fn new(protocol: SimProtocol) -> Self {
        let (x_travel_mm, x_address, y_address, units_per_mm) = match protocol {
            SimProtocol::Smc100 => ((-12.5, 12.5), 1, 2, 1.0),
            SimProtocol::Zaber => ((0.0, 25.0), 1, 2, 20_997.375),
            SimProtocol::Apt => ((0.0, 25.0), 0x50, 0x21, 34_304.0),
        };
        Self {
            protocol,
            speed_mm_per_s: 5.0,
            settle: Duration::from_millis(20),
            x_travel_mm,
            y_travel_mm: None,
            x_address,
            y_address,
            power_up_mm: (3.0, 3.0),
            units_per_mm,
            status_interval: (protocol == SimProtocol::Apt).then_some(Duration::from_millis(100)),
        }
    }
}

/// Faults to inject; they act from the simulator's next turn (within about a millisecond).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SimFaults {
    /// The controller neither acts on commands nor sends anything.
    pub silent: bool,
    /// Everything the controller sends is replaced by noise (as from a wrong baud rate).
    pub garbage: bool,
    /// A limit switch trips at this x position: a move across it stops there, flagged.
    pub x_limit_switch_mm: Option<f64>,
}

/// The controller side of one protocol.
pub(crate) trait Controller: Send {
    /// Consumes received bytes; appends replies to `out`.
    fn receive(&mut self, bytes: &[u8], axes: &mut [SimAxis], now: Instant, out: &mut Vec<u8>);
    /// Axis `i` has finished `leg` (arrived and settled).
    fn completed(&mut self, i: usize, leg: Leg, axes: &[SimAxis], now: Instant, out: &mut Vec<u8>);
    /// Unprompted messages, called on every turn.
    fn tick(&mut self, _axes: &[SimAxis], _now: Instant, _out: &mut Vec<u8>) {}
    fn unprompted_sent(&self) -> u64 {
        0
    }
    /// Bytes that cannot be a valid message of this protocol.
    fn garbage(&self) -> Vec<u8>;
}

struct Shared {
    axes: Vec<SimAxis>,
    controller: Box<dyn Controller>,
    faults: SimFaults,
    bench: Option<SharedBench>,
    stop: bool,
}

/// A running simulator. Dropping it closes the pty.
pub struct StageSim {
    path: String,
    shared: Arc<Mutex<Shared>>,
    thread: Option<JoinHandle<()>>,
}

impl StageSim {
    /// Opens a pty pair and starts serving it. With a bench, the axes start where the bench
    /// rests and the bench follows them.
    pub fn spawn(config: SimConfig, bench: Option<SharedBench>) -> io::Result<Self> {
        let (mut master, slave) = TTYPort::pair().map_err(io::Error::from)?;
        let path = slave
            .name()
            .ok_or_else(|| io::Error::other("the pty slave has no path"))?;
        master.set_timeout(TICK).map_err(io::Error::from)?;
        let start = match &bench {
            Some(b) => {
                let p = b.lock().expect("bench lock").position_at(Instant::now());
                (p.x_mm, p.y_mm)
            }
            None => config.power_up_mm,
        };
        let mut axes = vec![SimAxis::new(
            config.x_address,
            config.x_travel_mm,
            config.speed_mm_per_s,
            config.settle,
            start.0,
        )];
        if let Some(travel) = config.y_travel_mm {
            axes.push(SimAxis::new(
                config.y_address,
                travel,
                config.speed_mm_per_s,
                config.settle,
                start.1,
            ));
        }
        let controller: Box<dyn Controller> = match config.protocol {
            SimProtocol::Smc100 => Box::<smc100::Smc100Sim>::default(),
            SimProtocol::Zaber => Box::new(zaber::ZaberSim::new(config.units_per_mm)),
            SimProtocol::Apt => Box::new(apt::AptSim::new(
                config.units_per_mm,
                config.status_interval,
            )),
        };
        let shared = Arc::new(Mutex::new(Shared {
            axes,
            controller,
            faults: SimFaults::default(),
            bench,
            stop: false,
        }));
        let for_thread = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name(format!("stage-sim {path}"))
            .spawn(move || serve(master, slave, for_thread))?;
        Ok(Self {
            path,
            shared,
            thread: Some(thread),
        })
    }

    /// The device path a client opens (`/dev/pts/N`).
    pub fn path(&self) -> &str {
        &self.path
    }

    pub fn set_faults(&self, faults: SimFaults) {
        self.lock().faults = faults;
    }

    pub fn faults(&self) -> SimFaults {
        self.lock().faults
    }

    /// Closes the pty as if the cable were pulled; the client sees a hang-up. Returns once the
    /// pty is closed.
    pub fn disconnect(&mut self) {
        self.lock().stop = true;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }

    /// Where the axes really are, mm (y = 0 without a y axis).
    pub fn position_mm(&self) -> (f64, f64) {
        let s = self.lock();
        let now = Instant::now();
        let x = s.axes[0].position_mm(now);
        let y = s.axes.get(1).map_or(0.0, |a| a.position_mm(now));
        (x, y)
    }

    /// Whether every axis is homed.
    pub fn homed(&self) -> bool {
        self.lock().axes.iter().all(|a| a.homed)
    }

    /// Whether any axis is moving or settling.
    pub fn busy(&self) -> bool {
        self.lock().axes.iter().any(|a| a.leg().is_some())
    }

    /// How many unprompted messages (APT status updates) have been sent.
    pub fn unprompted_sent(&self) -> u64 {
        self.lock().controller.unprompted_sent()
    }

    fn lock(&self) -> MutexGuard<'_, Shared> {
        self.shared.lock().expect("stage sim lock")
    }
}

impl Drop for StageSim {
    fn drop(&mut self) {
        self.disconnect();
    }
}

/// The simulator's loop: read what arrived, let the controller act, send its replies.
fn serve(mut master: TTYPort, slave: TTYPort, shared: Arc<Mutex<Shared>>) {
    let mut buf = [0u8; 512];
    loop {
        let received = match master.read(&mut buf) {
            Ok(n) => &buf[..n],
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
                ) =>
            {
                &buf[..0]
            }
            Err(_) => break,
        };
        let mut out = Vec::new();
        {
            let mut s = shared.lock().expect("stage sim lock");
            if s.stop {
                break;
            }
            let now = Instant::now();
            let Shared {
                axes,
                controller,
                faults,
                bench,
                ..
            } = &mut *s;
            axes[0].switch_mm = faults.x_limit_switch_mm;
            if !faults.silent {
                controller.receive(received, axes, now, &mut out);
                for i in 0..axes.len() {
                    if let Some(leg) = axes[i].finish(now) {
                        controller.completed(i, leg, axes, now, &mut out);
                    }
                }
                controller.tick(axes, now, &mut out);
            }
            if let Some(b) = bench {
                sync_bench(b, axes, now);
            }
            if faults.garbage && !out.is_empty() {
                out = controller.garbage();
            }
        }
        if !out.is_empty() && master.write_all(&out).is_err() {
            break;
        }
    }
    drop(slave);
    drop(master);
}
