//! One frame: run the command, wait for it within a limit, read and check the TIFF it wrote.

use crate::ExecCameraConfig;
use ffdic_hw::{HwError, HwResult};
use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// How often a running command is asked whether it has exited.
const POLL: Duration = Duration::from_millis(2);
/// How much of the command's stderr an error quotes, characters (its end: where a failure says
/// why).
const STDERR_TAIL_CHARS: usize = 1500;
/// The least time given to read a command's stderr after it exited.
const STDERR_GRACE: Duration = Duration::from_millis(100);

/// Runs the command with `env`, waits at most `limit`, and returns the samples of the TIFF it
/// wrote at `out` (removed afterwards), checked against the configured size and bit depth.
pub fn run_frame(
    config: &ExecCameraConfig,
    env: &[(&str, String)],
    out: &Path,
    limit: Duration,
) -> HwResult<Vec<u16>> {
    let program = &config.command[0];
    let _ = std::fs::remove_file(out);
    // Its own process group, so a timeout stops what it started too (a shell's children).
    let mut child = Command::new(program)
        .process_group(0)
        .args(&config.command[1..])
        .envs(env.iter().map(|(k, v)| (k, v)))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| HwError::Disconnected(format!("exec camera: cannot run {program}: {e}")))?;
    // Drained on a thread of its own: a chatty command must not block on a full pipe.
    let mut stderr = child.stderr.take().expect("piped");
    let (said_tx, said_rx) = std::sync::mpsc::sync_channel(1);
    std::thread::spawn(move || {
        let mut text = Vec::new();
        let _ = stderr.read_to_end(&mut text);
        let _ = said_tx.send(text);
    });
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child
            .try_wait()
            .map_err(|e| HwError::Protocol(format!("exec camera: waiting for {program}: {e}")))?
        {
            break status;
        }
        if started.elapsed() >= limit {
            kill_group(&mut child);
            // The drain ends when the last holder of the pipe is gone; it is not waited for.
            let _ = std::fs::remove_file(out);
            return Err(HwError::Timeout {
                what: format!("exec camera command {program}"),
                after_ms: limit.as_millis() as u64,
            });
        }
        std::thread::sleep(POLL);
    };
    // Its stderr ends when the last holder of the pipe exits: a child the command left running
    // may hold it, so the wait for it stays within the limit (and a moment).
    let left = limit.saturating_sub(started.elapsed()).max(STDERR_GRACE);
    let said = tail(&said_rx.recv_timeout(left).unwrap_or_default());
    if !status.success() {
        let _ = std::fs::remove_file(out);
        return Err(HwError::Protocol(format!(
            "exec camera: {program} failed ({status}){said}"
        )));
    }
    let samples = read_frame(config, out)
        .map_err(|e| HwError::Protocol(format!("exec camera: {program} exited 0 but {e}{said}")));
    let _ = std::fs::remove_file(out);
    samples
}

/// Stops the command and everything in its process group, and reaps it.
fn kill_group(child: &mut std::process::Child) {
    if let Ok(pid) = libc::pid_t::try_from(child.id()) {
        // SAFETY: kill(2) with a negative pid signals the process group the child leads
        // (`process_group(0)`); no memory is shared.
        unsafe {
            libc::kill(-pid, libc::SIGKILL);
        }
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// The last lines of a command's stderr, for an error message ("" when it said nothing).
fn tail(stderr: &[u8]) -> String {
    let text = String::from_utf8_lossy(stderr);
    let text = text.trim();
    if text.is_empty() {
        return String::new();
    }
    let start = text
        .char_indices()
        .rev()
        .nth(STDERR_TAIL_CHARS)
        .map_or(0, |(i, _)| i);
    format!("; its stderr ends: {}", &text[start..])
}

/// The TIFF at `path` as 16-bit samples, or what is wrong with it.
fn read_frame(config: &ExecCameraConfig, path: &Path) -> Result<Vec<u16>, String> {
    use tiff::decoder::{Decoder, DecodingResult};
    let file = std::fs::File::open(path)
        .map_err(|e| format!("wrote no frame at {} ({e})", path.display()))?;
    let mut decoder = Decoder::new(std::io::BufReader::new(file))
        .map_err(|e| format!("wrote no readable TIFF at {}: {e}", path.display()))?;
    let (w, h) = decoder
        .dimensions()
        .map_err(|e| format!("wrote an unreadable TIFF: {e}"))?;
    if (w, h) != (config.width, config.height) {
        return Err(format!(
            "wrote a {w}x{h} frame; the camera is configured for {}x{}",
            config.width, config.height
        ));
    }
    let colour = decoder
        .colortype()
        .map_err(|e| format!("wrote an unreadable TIFF: {e}"))?;
    let wanted = tiff::ColorType::Gray(config.bit_depth);
    if colour != wanted {
        return Err(format!(
            "wrote a {colour:?} TIFF; the camera is configured for {wanted:?} (grey, {} bit)",
            config.bit_depth
        ));
    }
    match decoder
        .read_image()
        .map_err(|e| format!("wrote an unreadable TIFF: {e}"))?
    {
        DecodingResult::U8(v) => Ok(v.into_iter().map(u16::from).collect()),
        DecodingResult::U16(v) => Ok(v),
        // Float or signed samples are not a camera's grey levels.
        _ => Err("wrote samples that are not unsigned 8- or 16-bit grey".into()),
    }
}
