//! Thorlabs APT driver (DC servo controllers: KDC101, TDC001, and the bays of benchtop units).
//! Replies are not tied to requests and status updates arrive unprompted at any time, so every
//! frame read is first absorbed into per-axis state (position, homed, motion under way) and
//! only then offered to whoever waits for a particular message.

pub mod protocol;

use crate::config::AptConfig;
use crate::open::open_port;
use crate::transport::{Deadline, Link};
use crate::travel::{check_target, stage_info, to_mm, to_units, Axis};
use ffdic_hw::{HwError, HwResult, Stage, StageInfo, StagePosition};
use protocol::{id, status, Frame};
use serialport::{FlowControl, SerialPort};
use std::time::Duration;

const POLL_INTERVAL: Duration = Duration::from_millis(5);

/// The completion message an axis still owes for the last command it was given.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Awaiting {
    MoveCompleted,
    Homed,
    MoveStopped,
}

struct AxisState {
    axis: Axis,
    address: u8,
    homed: bool,
    moving: bool,
    awaiting: Option<Awaiting>,
    /// A stop the controller reported on its own (limit switch), kept for `wait_settled`.
    fault: Option<String>,
}

pub struct AptStage {
    link: Link,
    info: StageInfo,
    timeout_ms: u64,
    counts_per_mm: f64,
    channel: u16,
    axes: Vec<AxisState>,
}

impl AptStage {
    /// Opens the port (8N1, RTS/CTS as the FTDI bridge of these controllers needs) and reads each
    /// axis' status.
    pub fn open(config: &AptConfig) -> HwResult<Self> {
        let port = open_port(
            &config.port,
            config.baud,
            FlowControl::Hardware,
            config.timeout_ms,
        )?;
        Self::with_port(port, config)
    }

    pub fn with_port(port: Box<dyn SerialPort>, config: &AptConfig) -> HwResult<Self> {
        if !(config.counts_per_mm.is_finite() && config.counts_per_mm > 0.0) {
            return Err(HwError::OutOfRange {
                what: "counts_per_mm".into(),
                value: config.counts_per_mm,
                min: f64::MIN_POSITIVE,
                max: f64::MAX,
            });
        }
        let mut addresses = vec![(Axis::X, config.x_address)];
        addresses.extend(config.y_address.map(|a| (Axis::Y, a)));
        let link = Link::new(port);
        let y_travel = config.y_address.map(|_| config.y_travel_mm);
        let model = format!("Thorlabs APT controller on {}", link.name());
        let mut stage = Self {
            link,
            info: stage_info(
                model,
                config.x_travel_mm,
                y_travel,
                1.0 / config.counts_per_mm,
            ),
            timeout_ms: config.timeout_ms,
            counts_per_mm: config.counts_per_mm,
            channel: config.channel,
            axes: addresses
                .into_iter()
                .map(|(axis, address)| AxisState {
                    axis,
                    address,
                    homed: false,
                    moving: false,
                    awaiting: None,
                    fault: None,
                })
                .collect(),
        };
        stage.link.discard_input();
        stage.refresh_status()?;
        Ok(stage)
    }

    fn send(&mut self, frame: Frame, what: &str) -> HwResult<()> {
        let deadline = Deadline::after_ms(self.timeout_ms);
        self.link.write(&frame.encode(), deadline, what)
    }

    /// The next whole frame addressed to the host.
    fn next_frame(&mut self, deadline: Deadline, what: &str) -> HwResult<Frame> {
        loop {
            match protocol::decode(self.link.pending()) {
                Ok(Some((frame, used))) => {
                    self.link.consume(used);
                    if frame.dest != protocol::HOST {
                        self.link.discard_input();
                        return Err(HwError::Protocol(format!(
                            "{what}: APT message 0x{:04x} addressed to 0x{:02x}, not the host",
                            frame.id, frame.dest
                        )));
                    }
                    return Ok(frame);
                }
                Ok(None) => self.link.fill(deadline, what)?,
                Err(e) => {
                    self.link.discard_input();
                    return Err(e);
                }
            }
        }
    }

    /// Updates the state of the axis a frame comes from. A controller error report is an error.
    fn absorb(&mut self, frame: &Frame) -> HwResult<()> {
        let Some(i) = self.axes.iter().position(|a| a.address == frame.source) else {
            return Ok(()); // Another module on the same port: not ours.
        };
        let counts_per_mm = self.counts_per_mm;
        let a = &mut self.axes[i];
        match frame.id {
            id::GET_STATUSUPDATE | id::GET_DCSTATUSUPDATE => {
                let s = protocol::parse_status(frame)?;
                a.homed = s.bits & status::HOMED != 0;
                a.moving = s.bits & status::MOVING != 0;
            }
            id::MOVE_COMPLETED | id::MOVE_STOPPED => {
                let s = protocol::parse_status(frame)?;
                a.homed = s.bits & status::HOMED != 0;
                a.moving = false;
                if s.bits & status::HARD_LIMIT != 0 {
                    let side = if s.bits & status::CW_HARD_LIMIT != 0 {
                        "forward (CW)"
                    } else {
                        "reverse (CCW)"
                    };
                    a.fault = Some(format!(
                        "{} axis stopped at {:.4} mm: {side} limit switch (APT status 0x{:08x})",
                        a.axis.name(),
                        to_mm(s.position_counts as i64, counts_per_mm),
                        s.bits
                    ));
                }
                let done =
                    frame.id == id::MOVE_STOPPED || a.awaiting == Some(Awaiting::MoveCompleted);
                if done {
                    a.awaiting = None;
                }
            }
            id::HOMED => {
                a.homed = true;
                a.moving = false;
                if a.awaiting == Some(Awaiting::Homed) {
                    a.awaiting = None;
                }
            }
            id::HW_RICHRESPONSE | id::HW_RESPONSE => {
                a.awaiting = None;
                return Err(HwError::Protocol(format!(
                    "{} axis (APT 0x{:02x}): {}",
                    a.axis.name(),
                    a.address,
                    protocol::describe_rich_response(frame)
                )));
            }
            _ => {}
        }
        Ok(())
    }

    /// Reads frames until one satisfies `wanted`, absorbing all of them on the way.
    fn await_frame(
        &mut self,
        deadline: Deadline,
        what: &str,
        wanted: impl Fn(&Frame) -> bool,
    ) -> HwResult<Frame> {
        loop {
            let frame = self.next_frame(deadline, what)?;
            self.absorb(&frame)?;
            if wanted(&frame) {
                return Ok(frame);
            }
        }
    }

    /// Reads frames until no axis owes a completion message.
    fn await_completions(&mut self, deadline: Deadline, what: &str) -> HwResult<()> {
        while self.axes.iter().any(|a| a.awaiting.is_some()) {
            let frame = self.next_frame(deadline, what)?;
            self.absorb(&frame)?;
        }
        Ok(())
    }

    /// Asks every axis for its status (homed, moving).
    fn refresh_status(&mut self) -> HwResult<()> {
        for i in 0..self.axes.len() {
            let address = self.axes[i].address;
            let what = format!("APT status of 0x{address:02x}");
            let request = protocol::request(id::REQ_DCSTATUSUPDATE, address, self.channel);
            self.send(request, &what)?;
            let deadline = Deadline::after_ms(self.timeout_ms);
            self.await_frame(deadline, &what, |f| {
                f.source == address && matches!(f.id, id::GET_DCSTATUSUPDATE | id::GET_STATUSUPDATE)
            })?;
        }
        Ok(())
    }

    fn position_of(&mut self, address: u8) -> HwResult<f64> {
        let what = format!("APT position of 0x{address:02x}");
        let request = protocol::request(id::REQ_POSCOUNTER, address, self.channel);
        self.send(request, &what)?;
        let deadline = Deadline::after_ms(self.timeout_ms);
        let frame = self.await_frame(deadline, &what, |f| {
            f.source == address && f.id == id::GET_POSCOUNTER
        })?;
        let (_, counts) = protocol::parse_poscounter(&frame)?;
        Ok(to_mm(counts as i64, self.counts_per_mm))
    }
}

impl Stage for AptStage {
    fn info(&self) -> &StageInfo {
        &self.info
    }

    fn home(&mut self, timeout: Duration) -> HwResult<()> {
        let deadline = Deadline::after_ms(timeout.as_millis() as u64);
        for i in 0..self.axes.len() {
            let address = self.axes[i].address;
            self.axes[i].fault = None;
            self.axes[i].awaiting = Some(Awaiting::Homed);
            self.send(
                protocol::request(id::HOME, address, self.channel),
                "APT home",
            )?;
        }
        self.await_completions(deadline, "APT homing")?;
        if let Some(a) = self.axes.iter().find(|a| !a.homed) {
            return Err(HwError::Protocol(format!(
                "{} axis (APT 0x{:02x}) stopped before it was homed",
                a.axis.name(),
                a.address
            )));
        }
        Ok(())
    }

    fn move_absolute(&mut self, target: StagePosition) -> HwResult<()> {
        check_target(&self.info, target)?;
        self.refresh_status()?;
        if let Some(a) = self.axes.iter().find(|a| !a.homed) {
            return Err(HwError::NotReferenced(format!(
                "{} axis (APT 0x{:02x}) is not homed: home first",
                a.axis.name(),
                a.address
            )));
        }
        for i in 0..self.axes.len() {
            let (axis, address) = (self.axes[i].axis, self.axes[i].address);
            let counts = to_units(axis.of(target), self.counts_per_mm)? as i32;
            self.axes[i].fault = None;
            self.axes[i].awaiting = Some(Awaiting::MoveCompleted);
            let frame = protocol::move_absolute(address, self.channel, counts);
            self.send(frame, "APT move absolute")?;
        }
        Ok(())
    }

    fn position(&mut self) -> HwResult<StagePosition> {
        let mut p = StagePosition::default();
        for i in 0..self.axes.len() {
            let (axis, address) = (self.axes[i].axis, self.axes[i].address);
            let v = self.position_of(address)?;
            match axis {
                Axis::X => p.x_mm = v,
                Axis::Y => p.y_mm = v,
            }
        }
        Ok(p)
    }

    fn wait_settled(&mut self, timeout: Duration) -> HwResult<StagePosition> {
        let deadline = Deadline::after_ms(timeout.as_millis() as u64);
        self.await_completions(deadline, "APT settling")?;
        // A move started by someone else owes us no completion: poll until nothing moves.
        loop {
            self.refresh_status()?;
            if !self.axes.iter().any(|a| a.moving) {
                break;
            }
            if deadline.passed() {
                return Err(deadline.timeout("APT settling"));
            }
            std::thread::sleep(POLL_INTERVAL);
        }
        if let Some(fault) = self.axes.iter_mut().find_map(|a| a.fault.take()) {
            return Err(HwError::Protocol(fault));
        }
        self.position()
    }

    fn stop(&mut self) -> HwResult<()> {
        for i in 0..self.axes.len() {
            let address = self.axes[i].address;
            self.axes[i].awaiting = Some(Awaiting::MoveStopped);
            let frame = protocol::move_stop(address, self.channel, true);
            self.send(frame, "APT stop")?;
        }
        let deadline = Deadline::after_ms(self.timeout_ms);
        self.await_completions(deadline, "APT stop")
    }
}
