//! Zaber ASCII driver. Every command carries a message id and a checksum, so a reply is matched
//! to its command and a corrupted one is caught; progress is polled with the empty command.

pub mod protocol;

use crate::config::ZaberConfig;
use crate::open::open_port;
use crate::transport::{Deadline, Link};
use crate::travel::{check_target, narrow, stage_info, to_mm, to_units, Axis};
use ffdic_hw::{HwError, HwResult, Stage, StageInfo, StagePosition};
use protocol::{Message, Reply, WarningClass};
use serialport::{FlowControl, SerialPort};
use std::time::Duration;

const POLL_INTERVAL: Duration = Duration::from_millis(5);

/// One axis: which device and axis number on the chain.
#[derive(Clone, Copy, Debug)]
struct Address {
    axis: Axis,
    device: u8,
    number: u8,
}

pub struct ZaberStage {
    link: Link,
    info: StageInfo,
    timeout_ms: u64,
    microsteps_per_mm: f64,
    axes: Vec<Address>,
    next_id: u8,
}

impl ZaberStage {
    /// Opens the port (8N1, no flow control) and checks every axis answers.
    pub fn open(config: &ZaberConfig) -> HwResult<Self> {
        let port = open_port(
            &config.port,
            config.baud,
            FlowControl::None,
            config.timeout_ms,
        )?;
        Self::with_port(port, config)
    }

    /// Drives devices on an open port; the travel is narrowed to each axis' `limit.min` and
    /// `limit.max`.
    pub fn with_port(port: Box<dyn SerialPort>, config: &ZaberConfig) -> HwResult<Self> {
        if !(config.microsteps_per_mm.is_finite() && config.microsteps_per_mm > 0.0) {
            return Err(HwError::OutOfRange {
                what: "microsteps_per_mm".into(),
                value: config.microsteps_per_mm,
                min: f64::MIN_POSITIVE,
                max: f64::MAX,
            });
        }
        let mut axes = vec![Address {
            axis: Axis::X,
            device: config.x_address,
            number: config.x_axis,
        }];
        axes.extend(config.y_address.map(|device| Address {
            axis: Axis::Y,
            device,
            number: config.y_axis,
        }));
        let mut stage = Self {
            link: Link::new(port),
            info: stage_info(
                String::new(),
                config.x_travel_mm,
                None,
                1.0 / config.microsteps_per_mm,
            ),
            timeout_ms: config.timeout_ms,
            microsteps_per_mm: config.microsteps_per_mm,
            axes: axes.clone(),
            next_id: 0,
        };
        let mut travel = Vec::new();
        for a in &axes {
            let configured = match a.axis {
                Axis::X => config.x_travel_mm,
                Axis::Y => config.y_travel_mm,
            };
            let low = protocol::parse_integer(&stage.accepted(*a, "get limit.min")?)?;
            let high = protocol::parse_integer(&stage.accepted(*a, "get limit.max")?)?;
            let device_mm = (
                to_mm(low, config.microsteps_per_mm),
                to_mm(high, config.microsteps_per_mm),
            );
            travel.push(narrow(configured, device_mm));
        }
        stage.info = stage_info(
            format!(
                "Zaber ASCII device {} axis {} on {}",
                config.x_address,
                config.x_axis,
                stage.link.name()
            ),
            travel[0],
            travel.get(1).copied(),
            1.0 / config.microsteps_per_mm,
        );
        Ok(stage)
    }

    /// Sends `text` to one axis and returns its reply, skipping alerts, info lines and stale
    /// replies to earlier commands.
    fn command(&mut self, a: Address, text: &str) -> HwResult<Reply> {
        let id = self.next_id;
        self.next_id = (self.next_id + 1) % 100;
        let line = protocol::encode_command(a.device, a.number, Some(id), text, true);
        let what = format!("Zaber `{}`", line.trim_end());
        let deadline = Deadline::after_ms(self.timeout_ms);
        self.link.discard_input();
        self.link.write(line.as_bytes(), deadline, &what)?;
        loop {
            let received = self.link.read_line(deadline, &what)?;
            let message = protocol::parse_message(&received).inspect_err(|_| {
                self.link.discard_input();
            })?;
            if let Message::Reply(r) = message {
                let ours = r.device == a.device
                    && r.axis == a.number
                    && (r.id == Some(id) || r.id.is_none());
                if ours {
                    return Ok(r);
                }
            }
        }
    }

    /// A command whose rejection is an error.
    fn accepted(&mut self, a: Address, text: &str) -> HwResult<Reply> {
        let r = self.command(a, text)?;
        if r.ok {
            Ok(r)
        } else {
            Err(self.rejection(a, text, &r))
        }
    }

    fn rejection(&self, a: Address, text: &str, r: &Reply) -> HwError {
        if protocol::classify_warning(&r.warning) == WarningClass::NotHomed {
            return not_homed(a);
        }
        let why = format!(
            "Zaber device {} axis {} rejected `{text}`: {} (warning {})",
            a.device, a.number, r.data, r.warning
        );
        match r.data.as_str() {
            "BADCOMMAND" | "BADAXIS" | "DEVICEONLY" => HwError::Unsupported(why),
            "AGAIN" | "STATUSBUSY" | "FULL" | "LOCKSTEP" | "PARKED" => HwError::Busy(why),
            _ => HwError::Protocol(why),
        }
    }

    /// A move: a `BADDATA` rejection means the device's own limits refused the target.
    fn move_axis(&mut self, a: Address, text: &str, target_mm: f64) -> HwResult<()> {
        let r = self.command(a, text)?;
        if r.ok {
            return Ok(());
        }
        if r.data == "BADDATA" && protocol::classify_warning(&r.warning) != WarningClass::NotHomed {
            let (min, max) = self.travel(a.axis);
            return Err(HwError::OutOfRange {
                what: format!("{}_mm (device limit)", a.axis.name()),
                value: target_mm,
                min,
                max,
            });
        }
        Err(self.rejection(a, text, &r))
    }

    fn travel(&self, axis: Axis) -> (f64, f64) {
        match axis {
            Axis::X => self.info.travel_x_mm,
            Axis::Y => self.info.travel_y_mm,
        }
    }

    /// Refuses motion on an axis that reports no reference position.
    fn require_homed(&mut self) -> HwResult<()> {
        for a in self.axes.clone() {
            let r = self.accepted(a, "")?;
            if protocol::classify_warning(&r.warning) == WarningClass::NotHomed {
                return Err(not_homed(a));
            }
        }
        Ok(())
    }

    /// Polls every axis until all are idle; returns their last replies.
    fn wait_idle(&mut self, deadline: Deadline, what: &str) -> HwResult<Vec<Reply>> {
        loop {
            let mut replies = Vec::with_capacity(self.axes.len());
            for a in self.axes.clone() {
                replies.push(self.accepted(a, "")?);
            }
            if replies.iter().all(|r| !r.busy) {
                return Ok(replies);
            }
            if deadline.passed() {
                return Err(deadline.timeout(what));
            }
            std::thread::sleep(POLL_INTERVAL);
        }
    }

    fn position_of(&mut self, a: Address) -> HwResult<f64> {
        let r = self.accepted(a, "get pos")?;
        Ok(to_mm(protocol::parse_integer(&r)?, self.microsteps_per_mm))
    }
}

fn not_homed(a: Address) -> HwError {
    HwError::NotReferenced(format!(
        "{} axis (Zaber device {} axis {}) has no reference position (WR): home first",
        a.axis.name(),
        a.device,
        a.number
    ))
}

impl Stage for ZaberStage {
    fn info(&self) -> &StageInfo {
        &self.info
    }

    fn home(&mut self, timeout: Duration) -> HwResult<()> {
        let deadline = Deadline::after_ms(timeout.as_millis() as u64);
        for a in self.axes.clone() {
            self.accepted(a, "home")?;
        }
        let replies = self.wait_idle(deadline, "Zaber homing")?;
        for (a, r) in self.axes.iter().zip(&replies) {
            if protocol::classify_warning(&r.warning) != WarningClass::None
                && protocol::classify_warning(&r.warning) != WarningClass::Notice
            {
                return Err(HwError::Protocol(format!(
                    "{} axis (Zaber device {}) failed to home: warning {}",
                    a.axis.name(),
                    a.device,
                    r.warning
                )));
            }
        }
        Ok(())
    }

    fn move_absolute(&mut self, target: StagePosition) -> HwResult<()> {
        check_target(&self.info, target)?;
        self.require_homed()?;
        for a in self.axes.clone() {
            let mm = a.axis.of(target);
            let steps = to_units(mm, self.microsteps_per_mm)?;
            self.move_axis(a, &format!("move abs {steps}"), mm)?;
        }
        Ok(())
    }

    fn move_relative(&mut self, dx_mm: f64, dy_mm: f64) -> HwResult<()> {
        let p = self.position()?;
        let target = StagePosition {
            x_mm: p.x_mm + dx_mm,
            y_mm: p.y_mm + dy_mm,
        };
        check_target(&self.info, target)?;
        self.require_homed()?;
        for a in self.axes.clone() {
            let d_mm = match a.axis {
                Axis::X => dx_mm,
                Axis::Y => dy_mm,
            };
            let steps = to_units(d_mm, self.microsteps_per_mm)?;
            self.move_axis(a, &format!("move rel {steps}"), a.axis.of(target))?;
        }
        Ok(())
    }

    fn position(&mut self) -> HwResult<StagePosition> {
        let mut p = StagePosition::default();
        for a in self.axes.clone() {
            let v = self.position_of(a)?;
            match a.axis {
                Axis::X => p.x_mm = v,
                Axis::Y => p.y_mm = v,
            }
        }
        Ok(p)
    }

    fn wait_settled(&mut self, timeout: Duration) -> HwResult<StagePosition> {
        let deadline = Deadline::after_ms(timeout.as_millis() as u64);
        let replies = self.wait_idle(deadline, "Zaber settling")?;
        for (a, r) in self.axes.clone().iter().zip(&replies) {
            let class = protocol::classify_warning(&r.warning);
            if matches!(class, WarningClass::LimitSwitch | WarningClass::Fault) {
                let at = self.position_of(*a)?;
                // The flag stays until cleared; clear it so the next move is judged afresh.
                self.accepted(*a, "warnings clear")?;
                let kind = if class == WarningClass::LimitSwitch {
                    "limit switch"
                } else {
                    "fault"
                };
                return Err(HwError::Protocol(format!(
                    "{} axis (Zaber device {}) stopped at {at:.4} mm: {kind} (warning {})",
                    a.axis.name(),
                    a.device,
                    r.warning
                )));
            }
        }
        self.position()
    }

    fn stop(&mut self) -> HwResult<()> {
        for a in self.axes.clone() {
            self.accepted(a, "stop")?;
        }
        Ok(())
    }
}
