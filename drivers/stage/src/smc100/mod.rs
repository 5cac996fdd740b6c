//! Newport SMC100 / CONEX-CC driver: one controller per axis, chained on one port by address.
//! Motion commands have no reply, so every one is followed by `TE` (last command error) to learn
//! whether the controller took it; progress is polled with `TS`.

pub mod protocol;

use crate::config::Smc100Config;
use crate::open::open_port;
use crate::transport::{Deadline, Link};
use crate::travel::{check_target, narrow, stage_info, Axis};
use ffdic_hw::{HwError, HwResult, Stage, StageInfo, StagePosition};
use protocol::{ControllerState, ControllerStatus};
use serialport::{FlowControl, SerialPort};
use std::time::Duration;

/// How often `TS` is polled while waiting; short, because a settled stage should not wait long.
const POLL_INTERVAL: Duration = Duration::from_millis(5);

pub struct Smc100Stage {
    link: Link,
    info: StageInfo,
    timeout_ms: u64,
    /// Each axis with its controller address.
    axes: Vec<(Axis, u8)>,
}

impl Smc100Stage {
    /// Opens the port (8N1, XON/XOFF as the manual requires) and checks every controller answers.
    pub fn open(config: &Smc100Config) -> HwResult<Self> {
        let port = open_port(
            &config.port,
            config.baud,
            FlowControl::Software,
            config.timeout_ms,
        )?;
        Self::with_port(port, config)
    }

    /// Drives controllers on an already open port; reads their software limits (`SL?`, `SR?`)
    /// and keeps the travel inside both them and the config.
    pub fn with_port(port: Box<dyn SerialPort>, config: &Smc100Config) -> HwResult<Self> {
        let mut axes = vec![(Axis::X, config.x_address)];
        axes.extend(config.y_address.map(|a| (Axis::Y, a)));
        for &(axis, address) in &axes {
            if !(1..=31).contains(&address) {
                return Err(HwError::OutOfRange {
                    what: format!("{}_address", axis.name()),
                    value: address as f64,
                    min: 1.0,
                    max: 31.0,
                });
            }
        }
        let mut stage = Self {
            link: Link::new(port),
            info: stage_info(
                String::new(),
                config.x_travel_mm,
                None,
                protocol::RESOLUTION_MM,
            ),
            timeout_ms: config.timeout_ms,
            axes: axes.clone(),
        };
        let mut travel = Vec::new();
        for &(axis, address) in &axes {
            let configured = match axis {
                Axis::X => config.x_travel_mm,
                Axis::Y => config.y_travel_mm,
            };
            let low = protocol::parse_mm(&stage.query(address, "SL?")?)?;
            let high = protocol::parse_mm(&stage.query(address, "SR?")?)?;
            travel.push(narrow(configured, (low, high)));
        }
        let id = stage.query(config.x_address, "ID?")?;
        stage.info = stage_info(
            format!("Newport SMC100/CONEX-CC {id} on {}", stage.link.name()),
            travel[0],
            travel.get(1).copied(),
            protocol::RESOLUTION_MM,
        );
        Ok(stage)
    }

    /// Sends `<address><mnemonic>` and returns the value of the reply to it.
    fn query(&mut self, address: u8, mnemonic: &str) -> HwResult<String> {
        let what = format!("SMC100 {address}{mnemonic}");
        let deadline = Deadline::after_ms(self.timeout_ms);
        // A late reply to an earlier, timed-out query would be taken for this one's.
        self.link.discard_input();
        self.link.write(
            protocol::command(address, mnemonic).as_bytes(),
            deadline,
            &what,
        )?;
        let line = self.link.read_line(deadline, &what)?;
        let echo = mnemonic.trim_end_matches('?');
        protocol::reply_value(&line, address, echo).map(str::to_string)
    }

    fn status(&mut self, address: u8) -> HwResult<ControllerStatus> {
        protocol::parse_status(&self.query(address, "TS")?)
    }

    /// Sends a command that has no reply, then asks `TE` whether it was accepted.
    /// `target_mm` is the position a refused move would have reached, for the error.
    fn execute(
        &mut self,
        axis: Axis,
        address: u8,
        command: String,
        target_mm: f64,
    ) -> HwResult<()> {
        let what = format!("SMC100 {}", command.trim_end());
        let deadline = Deadline::after_ms(self.timeout_ms);
        self.link.write(command.as_bytes(), deadline, &what)?;
        let letter = protocol::parse_error_letter(&self.query(address, "TE")?)?;
        match letter {
            '@' => Ok(()),
            'G' => {
                let (min, max) = self.travel(axis);
                Err(HwError::OutOfRange {
                    what: format!("{}_mm (controller limit)", axis.name()),
                    value: target_mm,
                    min,
                    max,
                })
            }
            'H' => Err(not_referenced(axis, address)),
            'L' => Err(HwError::Busy(format!("{} axis is homing", axis.name()))),
            _ => Err(HwError::Protocol(format!(
                "{what} refused: {} (TE {letter})",
                protocol::error_message(letter)
            ))),
        }
    }

    fn travel(&self, axis: Axis) -> (f64, f64) {
        match axis {
            Axis::X => self.info.travel_x_mm,
            Axis::Y => self.info.travel_y_mm,
        }
    }

    /// Refuses motion unless every axis is referenced and not homing.
    fn require_referenced(&mut self) -> HwResult<()> {
        for (axis, address) in self.axes.clone() {
            let s = self.status(address)?;
            match s.state {
                ControllerState::NotReferenced => return Err(not_referenced(axis, address)),
                ControllerState::Homing => {
                    return Err(HwError::Busy(format!("{} axis is homing", axis.name())))
                }
                ControllerState::Disabled | ControllerState::Configuration => {
                    return Err(HwError::Protocol(format!(
                        "{} axis (SMC100 address {address}) cannot move in state 0x{:02X}",
                        axis.name(),
                        s.code
                    )))
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// Polls `TS` on every axis until none is moving or homing.
    fn wait_stopped(&mut self, deadline: Deadline, what: &str) -> HwResult<Vec<ControllerStatus>> {
        loop {
            let mut all = Vec::with_capacity(self.axes.len());
            for (_, address) in self.axes.clone() {
                all.push(self.status(address)?);
            }
            let busy = all.iter().any(|s| {
                matches!(
                    s.state,
                    ControllerState::Moving | ControllerState::Homing | ControllerState::Jogging
                )
            });
            if !busy {
                return Ok(all);
            }
            if deadline.passed() {
                return Err(deadline.timeout(what));
            }
            std::thread::sleep(POLL_INTERVAL);
        }
    }

    /// A stopped axis with positioner errors (limit switch, following error, …) did not get
    /// where it was sent.
    fn check_faults(&mut self, statuses: &[ControllerStatus]) -> HwResult<()> {
        for (&(axis, address), s) in self.axes.clone().iter().zip(statuses) {
            if s.error_bits != 0 {
                let at = protocol::parse_mm(&self.query(address, "TP")?)?;
                let switch = if s.error_bits
                    & (protocol::NEGATIVE_END_OF_RUN | protocol::POSITIVE_END_OF_RUN)
                    != 0
                {
                    "limit switch: "
                } else {
                    ""
                };
                return Err(HwError::Protocol(format!(
                    "{} axis stopped at {at:.4} mm: {switch}{} (SMC100 address {address})",
                    axis.name(),
                    protocol::describe_error_bits(s.error_bits)
                )));
            }
        }
        Ok(())
    }
}

fn not_referenced(axis: Axis, address: u8) -> HwError {
    HwError::NotReferenced(format!(
        "{} axis (SMC100 address {address}) is not referenced: home first",
        axis.name()
    ))
}

impl Stage for Smc100Stage {
    fn info(&self) -> &StageInfo {
        &self.info
    }

    fn home(&mut self, timeout: Duration) -> HwResult<()> {
        let deadline = Deadline::after_ms(timeout.as_millis() as u64);
        for (axis, address) in self.axes.clone() {
            let s = self.status(address)?;
            match s.state {
                ControllerState::NotReferenced => {
                    self.execute(axis, address, protocol::command(address, "OR"), 0.0)?
                }
                // `OR` is refused once referenced (TE K); the reference holds until power-off,
                // so homing then means returning to the home position.
                ControllerState::Ready => {
                    self.execute(axis, address, protocol::command_mm(address, "PA", 0.0), 0.0)?
                }
                ControllerState::Homing => {}
                ControllerState::Moving | ControllerState::Jogging => {
                    return Err(HwError::Busy(format!(
                        "{} axis is moving: stop it before homing",
                        axis.name()
                    )))
                }
                ControllerState::Disabled | ControllerState::Configuration => {
                    return Err(HwError::Protocol(format!(
                        "{} axis (SMC100 address {address}) cannot home in state 0x{:02X}",
                        axis.name(),
                        s.code
                    )))
                }
            }
        }
        let statuses = self.wait_stopped(deadline, "SMC100 homing")?;
        for (&(axis, address), s) in self.axes.iter().zip(&statuses) {
            if s.state != ControllerState::Ready {
                return Err(HwError::Protocol(format!(
                    "{} axis (SMC100 address {address}) failed to home: state 0x{:02X}, {}",
                    axis.name(),
                    s.code,
                    protocol::describe_error_bits(s.error_bits)
                )));
            }
        }
        Ok(())
    }

    fn move_absolute(&mut self, target: StagePosition) -> HwResult<()> {
        check_target(&self.info, target)?;
        self.require_referenced()?;
        for (axis, address) in self.axes.clone() {
            let command = protocol::command_mm(address, "PA", axis.of(target));
            self.execute(axis, address, command, axis.of(target))?;
        }
        Ok(())
    }

    /// `PR` moves relative to where the axis is; the target is checked against travel first.
    fn move_relative(&mut self, dx_mm: f64, dy_mm: f64) -> HwResult<()> {
        let p = self.position()?;
        let target = StagePosition {
            x_mm: p.x_mm + dx_mm,
            y_mm: p.y_mm + dy_mm,
        };
        check_target(&self.info, target)?;
        self.require_referenced()?;
        for (axis, address) in self.axes.clone() {
            let d = match axis {
                Axis::X => dx_mm,
                Axis::Y => dy_mm,
            };
            let command = protocol::command_mm(address, "PR", d);
            self.execute(axis, address, command, axis.of(target))?;
        }
        Ok(())
    }

    fn position(&mut self) -> HwResult<StagePosition> {
        let mut p = StagePosition::default();
        for (axis, address) in self.axes.clone() {
            let v = protocol::parse_mm(&self.query(address, "TP")?)?;
            match axis {
                Axis::X => p.x_mm = v,
                Axis::Y => p.y_mm = v,
            }
        }
        Ok(p)
    }

    fn wait_settled(&mut self, timeout: Duration) -> HwResult<StagePosition> {
        let deadline = Deadline::after_ms(timeout.as_millis() as u64);
        let statuses = self.wait_stopped(deadline, "SMC100 settling")?;
        self.check_faults(&statuses)?;
        self.position()
    }

    fn stop(&mut self) -> HwResult<()> {
        for (axis, address) in self.axes.clone() {
            self.execute(axis, address, protocol::command(address, "ST"), f64::NAN)?;
        }
        Ok(())
    }
}
