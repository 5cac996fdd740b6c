//! Zaber ASCII protocol devices as simulated (Zaber ASCII Protocol Manual, "Message format",
//! "Replies", "Warning flags"). Each axis is axis 1 of its own device address. Message ids are
//! echoed; a checksummed command gets a checksummed reply.

use super::axis::{Leg, Refusal, SimAxis};
use super::Controller;
use std::time::Instant;

#[derive(Default)]
pub(crate) struct ZaberSim {
    rx: Vec<u8>,
    /// Per axis: `WL` (unexpected limit trigger) latched until `warnings clear` or `home`.
    limit_warning: Vec<bool>,
    pub units_per_mm: f64,
}

/// 256 − (sum of the bytes between the start character and the colon) mod 256.
fn checksum(content: &[u8]) -> u8 {
    content
        .iter()
        .fold(0u8, |s, &b| s.wrapping_add(b))
        .wrapping_neg()
}

struct Reply {
    ok: bool,
    data: String,
}

impl ZaberSim {
    pub fn new(units_per_mm: f64) -> Self {
        Self {
            units_per_mm,
            ..Self::default()
        }
    }

    fn warning(&self, axis: &SimAxis, i: usize) -> &'static str {
        if self.limit_warning[i] {
            "WL"
        } else if !axis.homed {
            "WR"
        } else {
            "--"
        }
    }

    fn handle(&mut self, line: &str, axes: &mut [SimAxis], now: Instant, out: &mut Vec<u8>) {
        let Some(body) = line.strip_prefix('/') else {
            return; // Not a command: devices ignore it.
        };
        let (content, checked) = match body.rsplit_once(':') {
            Some((content, sum)) => {
                let good = u8::from_str_radix(sum.trim(), 16)
                    .is_ok_and(|s| s == checksum(content.as_bytes()));
                if !good {
                    return; // A corrupted command is dropped, as by the device.
                }
                (content, true)
            }
            None => (body, false),
        };
        let mut words = content.split_whitespace().peekable();
        let mut numbers = Vec::new();
        while let Some(w) = words.peek() {
            if numbers.len() < 3 && w.bytes().all(|b| b.is_ascii_digit()) {
                numbers.push(words.next().unwrap_or_default().to_string());
            } else {
                break;
            }
        }
        let text: Vec<&str> = words.collect();
        let device: u8 = numbers.first().and_then(|d| d.parse().ok()).unwrap_or(0);
        let axis_number: u8 = numbers.get(1).and_then(|d| d.parse().ok()).unwrap_or(0);
        let id = numbers.get(2).cloned();
        for (i, axis) in axes.iter_mut().enumerate() {
            let address = axis.address;
            if device != 0 && device != address {
                continue;
            }
            let reply = if axis_number > 1 {
                Reply {
                    ok: false,
                    data: "BADAXIS".into(),
                }
            } else {
                self.execute(&text, axis, i, now)
            };
            let busy = if axis.leg().is_some() { "BUSY" } else { "IDLE" };
            let mut content = format!("{address:02} {axis_number}");
            if let Some(id) = &id {
                content.push_str(&format!(" {id}"));
            }
            content.push_str(&format!(
                " {} {busy} {} {}",
                if reply.ok { "OK" } else { "RJ" },
                self.warning(axis, i),
                reply.data
            ));
            out.push(b'@');
            out.extend_from_slice(content.as_bytes());
            if checked {
                out.extend_from_slice(format!(":{:02X}", checksum(content.as_bytes())).as_bytes());
            }
            out.extend_from_slice(b"\r\n");
        }
    }

    fn execute(&mut self, text: &[&str], axis: &mut SimAxis, i: usize, now: Instant) -> Reply {
        let ok = |data: String| Reply { ok: true, data };
        let rj = |why: &str| Reply {
            ok: false,
            data: why.into(),
        };
        let units = self.units_per_mm;
        let steps = |mm: f64| format!("{}", (mm * units).round() as i64);
        match text {
            [] => ok("0".into()),
            ["home"] => {
                self.limit_warning[i] = false;
                axis.start_home(now);
                ok("0".into())
            }
            ["move", kind @ ("abs" | "rel"), n] => {
                let Ok(n) = n.parse::<i64>() else {
                    return rj("BADDATA");
                };
                let mm = n as f64 / units;
                let target = if *kind == "abs" {
                    mm
                } else {
                    axis.position_mm(now) + mm
                };
                match axis.start_move(target, now) {
                    Ok(()) => ok("0".into()),
                    // The `WR` flag in the reply says why.
                    Err(Refusal::NotHomed | Refusal::OutOfTravel) => rj("BADDATA"),
                }
            }
            ["stop"] => {
                axis.stop(now);
                ok("0".into())
            }
            ["get", "pos"] => ok(steps(axis.position_mm(now))),
            ["get", "limit.min"] => ok(steps(axis.travel_mm.0)),
            ["get", "limit.max"] => ok(steps(axis.travel_mm.1)),
            ["get", "maxspeed"] => ok(steps(axis.speed_mm_per_s)),
            ["warnings"] | ["warnings", "clear"] => {
                let flags = self.warning(axis, i);
                let listed = if flags == "--" {
                    "00".to_string()
                } else {
                    format!("01 {flags}")
                };
                if text.len() == 2 {
                    self.limit_warning[i] = false;
                }
                ok(listed)
            }
            _ => rj("BADCOMMAND"),
        }
    }
}

impl Controller for ZaberSim {
    fn receive(&mut self, bytes: &[u8], axes: &mut [SimAxis], now: Instant, out: &mut Vec<u8>) {
        self.limit_warning.resize(axes.len(), false);
        self.rx.extend_from_slice(bytes);
        while let Some(end) = self.rx.iter().position(|&b| b == b'\n') {
            let raw: Vec<u8> = self.rx.drain(..=end).collect();
            let line = String::from_utf8_lossy(&raw);
            let line = line.trim_end_matches(['\r', '\n']);
            self.handle(line, axes, now, out);
        }
    }

    fn completed(&mut self, i: usize, leg: Leg, _: &[SimAxis], _: Instant, _: &mut Vec<u8>) {
        if self.limit_warning.len() <= i {
            self.limit_warning.resize(i + 1, false);
        }
        if leg.hits.is_some() {
            self.limit_warning[i] = true;
        }
    }

    fn garbage(&self) -> Vec<u8> {
        vec![0xF0, 0x8C, 0xE3, 0x9A, 0xFF, 0xC1, b'\r', b'\n']
    }
}
