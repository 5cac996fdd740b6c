//! Thorlabs APT DC servo controllers as simulated (APT Communications Protocol, section 2
//! "Message structure" and the MGMSG_MOT_* messages). Written apart from the driver's codec on
//! purpose: the two meet only on the wire. Besides replies, the controller sends status updates
//! on its own, and completion messages when a move or homing run ends.

use super::axis::{Leg, LimitSide, Refusal, SimAxis};
use super::Controller;
use std::time::{Duration, Instant};

const HOST: u8 = 0x01;
const DATA_FOLLOWS: u8 = 0x80;

const HW_RICHRESPONSE: u16 = 0x0081;
const REQ_POSCOUNTER: u16 = 0x0411;
const GET_POSCOUNTER: u16 = 0x0412;
const HOME: u16 = 0x0443;
const HOMED: u16 = 0x0444;
const MOVE_RELATIVE: u16 = 0x0448;
const MOVE_ABSOLUTE: u16 = 0x0453;
const MOVE_COMPLETED: u16 = 0x0464;
const MOVE_STOP: u16 = 0x0465;
const MOVE_STOPPED: u16 = 0x0466;
const REQ_STATUSUPDATE: u16 = 0x0480;
const GET_STATUSUPDATE: u16 = 0x0481;
const REQ_DCSTATUSUPDATE: u16 = 0x0490;
const GET_DCSTATUSUPDATE: u16 = 0x0491;

/// The completion message an axis owes for its last command.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Owed {
    MoveCompleted,
    Homed,
}

pub(crate) struct AptSim {
    rx: Vec<u8>,
    counts_per_mm: f64,
    owed: Vec<Option<Owed>>,
    status_interval: Option<Duration>,
    next_status: Option<Instant>,
    /// Alternates stepper (0x0481) and DC servo (0x0491) updates so both layouts are exercised.
    dc_layout_next: bool,
    unprompted_sent: u64,
}

fn frame_short(id: u16, p1: u8, p2: u8, source: u8) -> Vec<u8> {
    let [a, b] = id.to_le_bytes();
    vec![a, b, p1, p2, HOST, source]
}

fn frame_long(id: u16, data: &[u8], source: u8) -> Vec<u8> {
    let [a, b] = id.to_le_bytes();
    let [l0, l1] = (data.len() as u16).to_le_bytes();
    let mut f = vec![a, b, l0, l1, HOST | DATA_FOLLOWS, source];
    f.extend_from_slice(data);
    f
}

impl AptSim {
    pub fn new(counts_per_mm: f64, status_interval: Option<Duration>) -> Self {
        Self {
            rx: Vec::new(),
            counts_per_mm,
            owed: Vec::new(),
            status_interval,
            next_status: None,
            dc_layout_next: true,
            unprompted_sent: 0,
        }
    }

    fn counts(&self, mm: f64) -> i32 {
        (mm * self.counts_per_mm).round() as i32
    }

    /// Status bits (manual, MGMSG_MOT_GET_STATUSUPDATE): limits, motion, homing, homed, enabled.
    fn status_bits(axis: &SimAxis) -> u32 {
        let mut bits = 0x8000_0000; // channel enabled
        match axis.at_limit {
            Some(LimitSide::Positive) => bits |= 0x01,
            Some(LimitSide::Negative) => bits |= 0x02,
            None => {}
        }
        if let Some(l) = axis.leg() {
            if l.homing {
                bits |= 0x200;
            } else if l.to_mm >= l.from_mm {
                bits |= 0x10;
            } else {
                bits |= 0x20;
            }
        }
        if axis.homed {
            bits |= 0x400;
        }
        bits
    }

    /// The 14-byte status structure: channel, position, velocity/encoder word, status bits.
    fn status_data(&self, axis: &SimAxis, now: Instant) -> Vec<u8> {
        let mut d = 1u16.to_le_bytes().to_vec();
        d.extend_from_slice(&self.counts(axis.position_mm(now)).to_le_bytes());
        d.extend_from_slice(&[0; 4]);
        d.extend_from_slice(&Self::status_bits(axis).to_le_bytes());
        d
    }

    fn refuse(&self, about: u16, code: u16, text: &str, source: u8) -> Vec<u8> {
        let mut d = about.to_le_bytes().to_vec();
        d.extend_from_slice(&code.to_le_bytes());
        let mut notes = text.as_bytes().to_vec();
        notes.resize(64, 0);
        d.extend_from_slice(&notes);
        frame_long(HW_RICHRESPONSE, &d, source)
    }

    fn handle(
        &mut self,
        id: u16,
        dest: u8,
        data: &[u8],
        axes: &mut [SimAxis],
        now: Instant,
        out: &mut Vec<u8>,
    ) {
        let Some(i) = axes.iter().position(|a| a.address == dest) else {
            return;
        };
        let source = dest;
        match id {
            HOME => {
                axes[i].start_home(now);
                self.owed[i] = Some(Owed::Homed);
            }
            MOVE_ABSOLUTE | MOVE_RELATIVE => {
                let Some(raw) = data.get(2..6) else {
                    return;
                };
                let counts = i32::from_le_bytes([raw[0], raw[1], raw[2], raw[3]]);
                let mm = counts as f64 / self.counts_per_mm;
                let target = if id == MOVE_ABSOLUTE {
                    mm
                } else {
                    axes[i].position_mm(now) + mm
                };
                match axes[i].start_move(target, now) {
                    Ok(()) => self.owed[i] = Some(Owed::MoveCompleted),
                    Err(Refusal::NotHomed) => {
                        out.extend(self.refuse(id, 1, "axis not homed: home first", source))
                    }
                    Err(Refusal::OutOfTravel) => {
                        out.extend(self.refuse(id, 2, "position outside travel", source))
                    }
                }
            }
            MOVE_STOP => {
                axes[i].stop(now);
                self.owed[i] = None;
                let d = self.status_data(&axes[i], now);
                out.extend(frame_long(MOVE_STOPPED, &d, source));
            }
            REQ_POSCOUNTER => {
                let mut d = 1u16.to_le_bytes().to_vec();
                d.extend_from_slice(&self.counts(axes[i].position_mm(now)).to_le_bytes());
                out.extend(frame_long(GET_POSCOUNTER, &d, source));
            }
            REQ_DCSTATUSUPDATE | REQ_STATUSUPDATE => {
                let reply = if id == REQ_DCSTATUSUPDATE {
                    GET_DCSTATUSUPDATE
                } else {
                    GET_STATUSUPDATE
                };
                let d = self.status_data(&axes[i], now);
                out.extend(frame_long(reply, &d, source));
            }
            _ => {} // Messages the simulator does not model are ignored, as unknown ids are.
        }
    }
}

impl Controller for AptSim {
    fn receive(&mut self, bytes: &[u8], axes: &mut [SimAxis], now: Instant, out: &mut Vec<u8>) {
        self.owed.resize(axes.len(), None);
        self.rx.extend_from_slice(bytes);
        loop {
            if self.rx.len() < 6 {
                return;
            }
            let id = u16::from_le_bytes([self.rx[0], self.rx[1]]);
            let long = self.rx[4] & DATA_FOLLOWS != 0;
            let dest = self.rx[4] & !DATA_FOLLOWS;
            let len = if long {
                u16::from_le_bytes([self.rx[2], self.rx[3]]) as usize
            } else {
                0
            };
            if self.rx[5] != HOST || len > 128 {
                self.rx.clear(); // Noise: resynchronise on the next message.
                return;
            }
            if self.rx.len() < 6 + len {
                return;
            }
            let frame: Vec<u8> = self.rx.drain(..6 + len).collect();
            self.handle(id, dest, &frame[6..], axes, now, out);
        }
    }

    fn completed(&mut self, i: usize, leg: Leg, axes: &[SimAxis], now: Instant, out: &mut Vec<u8>) {
        self.owed.resize(axes.len(), None);
        let source = axes[i].address;
        match (self.owed[i], leg.homing) {
            (Some(Owed::Homed), true) => out.extend(frame_short(HOMED, 1, 0, source)),
            (Some(Owed::MoveCompleted), false) => {
                let d = self.status_data(&axes[i], now);
                // A run into a limit switch ends with MOVE_STOPPED, its status showing the switch.
                let id = if leg.hits.is_some() {
                    MOVE_STOPPED
                } else {
                    MOVE_COMPLETED
                };
                out.extend(frame_long(id, &d, source));
            }
            _ => return,
        }
        self.owed[i] = None;
    }

    fn tick(&mut self, axes: &[SimAxis], now: Instant, out: &mut Vec<u8>) {
        let Some(interval) = self.status_interval else {
            return;
        };
        let due = *self.next_status.get_or_insert(now + interval);
        if now < due {
            return;
        }
        self.next_status = Some(now + interval);
        let id = if self.dc_layout_next {
            GET_DCSTATUSUPDATE
        } else {
            GET_STATUSUPDATE
        };
        self.dc_layout_next = !self.dc_layout_next;
        for axis in axes {
            let d = self.status_data(axis, now);
            out.extend(frame_long(id, &d, axis.address));
            self.unprompted_sent += 1;
        }
    }

    fn unprompted_sent(&self) -> u64 {
        self.unprompted_sent
    }

    fn garbage(&self) -> Vec<u8> {
        vec![0xFF, 0xFE, 0xFD, 0x80, 0xAA, 0x55, 0xC3, 0x3C]
    }
}
