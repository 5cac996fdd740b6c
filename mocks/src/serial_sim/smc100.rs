//! The Newport SMC100 / CONEX-CC command set, as the simulated controllers answer it (SMC100
//! user's manual, section 2). Each axis is one controller with its own address on the chain.
//! Motion commands have no reply; errors wait to be read with `TE`.

use super::axis::{Leg, LimitSide, Refusal, SimAxis};
use super::Controller;
use std::time::Instant;

#[derive(Default)]
pub(crate) struct Smc100Sim {
    rx: Vec<u8>,
    /// Per axis: the last command error letter (`@` = none), read and cleared by `TE`.
    error: Vec<char>,
    /// Per axis: the state code reported when at rest, which says how the state was entered.
    rest_code: Vec<u8>,
}

const NOT_REFERENCED_FROM_RESET: u8 = 0x0A;
const NOT_REFERENCED_FROM_HOMING: u8 = 0x0B;
const HOMING_RS232: u8 = 0x1E;
const MOVING: u8 = 0x28;
const READY_FROM_HOMING: u8 = 0x32;
const READY_FROM_MOVING: u8 = 0x33;

impl Smc100Sim {
    /// Grows the per-axis state to cover `n` axes.
    fn ensure(&mut self, n: usize) {
        if self.error.len() < n {
            self.error.resize(n, '@');
            self.rest_code.resize(n, NOT_REFERENCED_FROM_RESET);
        }
    }

    fn state_code(&self, axis: &SimAxis, i: usize) -> u8 {
        match axis.leg() {
            Some(l) if l.homing => HOMING_RS232,
            Some(_) => MOVING,
            None => self.rest_code[i],
        }
    }

    fn handle(&mut self, line: &str, axes: &mut [SimAxis], now: Instant, out: &mut Vec<u8>) {
        let digits = line.bytes().take_while(u8::is_ascii_digit).count();
        let Ok(address) = line[..digits].parse::<u8>() else {
            return; // Not addressed: no controller answers.
        };
        let Some(i) = axes.iter().position(|a| a.address == address) else {
            return;
        };
        let rest = &line[digits..];
        if rest.len() < 2 || !rest.is_char_boundary(2) {
            self.error[i] = 'A';
            return;
        }
        let (mnemonic, arg) = rest.split_at(2);
        let query = arg.starts_with('?');
        let mut reply =
            |text: String| out.extend_from_slice(format!("{address}{text}\r\n").as_bytes());
        let axis = &mut axes[i];
        match (mnemonic, query) {
            ("TS", _) => {
                let bits = match axis.at_limit {
                    Some(LimitSide::Negative) => 0x0001,
                    Some(LimitSide::Positive) => 0x0002,
                    None => 0,
                };
                reply(format!("TS{bits:04X}{:02X}", self.state_code(axis, i)));
            }
            ("TP", _) => reply(format!("TP{:.6}", axis.position_mm(now))),
            ("TE", _) => {
                reply(format!("TE{}", self.error[i]));
                self.error[i] = '@';
            }
            ("SL", true) => reply(format!("SL{:.6}", axis.travel_mm.0)),
            ("SR", true) => reply(format!("SR{:.6}", axis.travel_mm.1)),
            ("ID", true) => reply("IDffdic SMC100CC simulator".to_string()),
            ("VA", true) => reply(format!("VA{:.6}", axis.speed_mm_per_s)),
            ("VA", false) => match arg.trim().parse::<f64>() {
                Ok(v) if v > 0.0 && v.is_finite() => axis.speed_mm_per_s = v,
                _ => self.error[i] = 'C',
            },
            ("OR", false) => match axis.leg() {
                Some(l) if l.homing => self.error[i] = 'E',
                Some(_) => self.error[i] = 'M',
                None if axis.homed => self.error[i] = 'K',
                None => axis.start_home(now),
            },
            ("PA" | "PR", false) => {
                let Ok(v) = arg.trim().parse::<f64>() else {
                    self.error[i] = 'C';
                    return;
                };
                let target = if mnemonic == "PA" {
                    v
                } else {
                    axis.position_mm(now) + v
                };
                match axis.start_move(target, now) {
                    Ok(()) => {}
                    Err(Refusal::NotHomed) if axis.leg().is_some_and(|l| l.homing) => {
                        self.error[i] = 'L'
                    }
                    Err(Refusal::NotHomed) => self.error[i] = 'H',
                    Err(Refusal::OutOfTravel) => self.error[i] = 'G',
                }
            }
            ("ST", false) => {
                let homing = axis.leg().is_some_and(|l| l.homing);
                if axis.stop(now) {
                    self.rest_code[i] = if homing {
                        NOT_REFERENCED_FROM_HOMING
                    } else {
                        READY_FROM_MOVING
                    };
                }
            }
            ("RS", false) => {
                axis.stop(now);
                axis.homed = false;
                self.rest_code[i] = NOT_REFERENCED_FROM_RESET;
            }
            _ => self.error[i] = 'A',
        }
    }
}

impl Controller for Smc100Sim {
    fn receive(&mut self, bytes: &[u8], axes: &mut [SimAxis], now: Instant, out: &mut Vec<u8>) {
        self.ensure(axes.len());
        self.rx.extend_from_slice(bytes);
        while let Some(end) = self.rx.iter().position(|&b| b == b'\n') {
            let raw: Vec<u8> = self.rx.drain(..=end).collect();
            let line = String::from_utf8_lossy(&raw);
            let line = line.trim_end_matches(['\r', '\n']);
            if !line.is_empty() {
                self.handle(line, axes, now, out);
            }
        }
    }

    fn completed(&mut self, i: usize, leg: Leg, _: &[SimAxis], _: Instant, _: &mut Vec<u8>) {
        self.ensure(i + 1);
        self.rest_code[i] = if leg.homing {
            READY_FROM_HOMING
        } else {
            READY_FROM_MOVING
        };
    }

    fn garbage(&self) -> Vec<u8> {
        // High bytes as from a wrong baud rate; no XON/XOFF (0x11/0x13), which would stall the
        // client's port.
        vec![0xF0, 0x8C, 0xE3, 0x9A, 0xFF, 0xC1, b'\r', b'\n']
    }
}
