//! The byte link to a controller: writes, and reads that always end by a deadline. I/O failures
//! become typed errors here, once: a read that runs out of time is `Timeout`, a port that hangs
//! up or fails is `Disconnected`, bytes that cannot belong to the protocol are `Protocol`.

use ffdic_hw::{HwError, HwResult};
use serialport::{ClearBuffer, SerialPort};
use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

/// Longest ASCII reply line accepted; controllers' replies are far shorter, so a longer run of
/// bytes without a terminator is noise, not a reply still arriving.
const MAX_LINE_BYTES: usize = 512;

/// The moment a read gives up, with the budget it was given (for the error message).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Deadline {
    at: Instant,
    budget_ms: u64,
}

impl Deadline {
    pub fn after_ms(budget_ms: u64) -> Self {
        Self {
            at: Instant::now() + Duration::from_millis(budget_ms),
            budget_ms,
        }
    }

    pub fn remaining(&self) -> Option<Duration> {
        self.at
            .checked_duration_since(Instant::now())
            .filter(|d| !d.is_zero())
    }

    pub fn passed(&self) -> bool {
        self.remaining().is_none()
    }

    pub fn timeout(&self, what: &str) -> HwError {
        HwError::Timeout {
            what: what.to_string(),
            after_ms: self.budget_ms,
        }
    }
}

/// A serial port plus the bytes read from it but not yet consumed.
pub(crate) struct Link {
    port: Box<dyn SerialPort>,
    name: String,
    pending: Vec<u8>,
}

impl Link {
    pub fn new(port: Box<dyn SerialPort>) -> Self {
        let name = port.name().unwrap_or_else(|| "serial port".into());
        Self {
            port,
            name,
            pending: Vec::new(),
        }
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn write(&mut self, bytes: &[u8], deadline: Deadline, what: &str) -> HwResult<()> {
        let remaining = deadline.remaining().ok_or_else(|| deadline.timeout(what))?;
        self.port
            .set_timeout(remaining)
            .map_err(|e| HwError::Disconnected(format!("{}: {e}", self.name)))?;
        self.port
            .write_all(bytes)
            .map_err(|e| self.io_error(e, deadline, what))
    }

    /// The next non-empty line ending in `\n` (a trailing `\r` is removed), printable ASCII only.
    pub fn read_line(&mut self, deadline: Deadline, what: &str) -> HwResult<String> {
        loop {
            // Anything outside printable ASCII means a wrong baud rate or line noise: fail at
            // once rather than wait for a terminator that may never come.
            if let Some(&bad) = self
                .pending
                .iter()
                .find(|b| !(b.is_ascii_graphic() || matches!(b, b' ' | b'\r' | b'\n')))
            {
                self.discard_input();
                return Err(HwError::Protocol(format!(
                    "{what}: byte 0x{bad:02x} in an ASCII reply on {} (wrong baud rate?)",
                    self.name
                )));
            }
            if let Some(end) = self.pending.iter().position(|&b| b == b'\n') {
                let line: Vec<u8> = self.pending.drain(..=end).collect();
                let text = String::from_utf8_lossy(&line)
                    .trim_end_matches(['\r', '\n'])
                    .to_string();
                if text.is_empty() {
                    continue;
                }
                return Ok(text);
            }
            if self.pending.len() > MAX_LINE_BYTES {
                self.discard_input();
                return Err(HwError::Protocol(format!(
                    "{what}: more than {MAX_LINE_BYTES} bytes without a line end on {}",
                    self.name
                )));
            }
            self.fill(deadline, what)?;
        }
    }

    /// Bytes received and not yet consumed (binary protocols parse frames from here).
    pub fn pending(&self) -> &[u8] {
        &self.pending
    }

    pub fn consume(&mut self, n: usize) {
        self.pending.drain(..n.min(self.pending.len()));
    }

    /// Reads whatever arrives next (at least one byte) into the pending buffer.
    pub fn fill(&mut self, deadline: Deadline, what: &str) -> HwResult<()> {
        let mut buf = [0u8; 256];
        loop {
            let remaining = deadline.remaining().ok_or_else(|| deadline.timeout(what))?;
            self.port
                .set_timeout(remaining)
                .map_err(|e| HwError::Disconnected(format!("{}: {e}", self.name)))?;
            match self.port.read(&mut buf) {
                Ok(0) => {
                    return Err(HwError::Disconnected(format!(
                        "{}: end of file during {what}",
                        self.name
                    )))
                }
                Ok(n) => {
                    self.pending.extend_from_slice(&buf[..n]);
                    return Ok(());
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(self.io_error(e, deadline, what)),
            }
        }
    }

    /// Forgets everything received so far, so the next reply starts on a clean slate.
    pub fn discard_input(&mut self) {
        self.pending.clear();
        // Best effort: a port that cannot clear will fail loudly on the next read anyway.
        let _ = self.port.clear(ClearBuffer::Input);
    }

    fn io_error(&self, e: io::Error, deadline: Deadline, what: &str) -> HwError {
        match e.kind() {
            io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock => deadline.timeout(what),
            // A pty whose other end closed reports a hang-up (BrokenPipe) or EIO; a USB adapter
            // pulled out reports EIO or ENXIO: all mean the controller is gone.
            _ => HwError::Disconnected(format!("{} during {what}: {e}", self.name)),
        }
    }
}
