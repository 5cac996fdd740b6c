//! `FakeGvCamera`: Aravis' GigE Vision camera simulator, in process, serving the caller's frames.
//!
//! Frames travel the real GigE Vision stack (GVCP control, GVSP stream over UDP on 127.0.0.1),
//! so a test exercises the same driver code as a lab camera. The in-process "Fake" interface is
//! not used: with a custom fill pattern it delivered 0-byte buffers (NOTES-hardware.md).
//!
//! The simulator listens on 127.0.0.1:3956, so only one runs per network namespace; run tests in
//! a namespace of their own with only loopback (Aravis discovery broadcasts on every interface).

use crate::unpack::{pack_for_fake, PFNC_MONO16, PFNC_MONO8};
use aravis::glib::translate::ToGlibPtr;
use aravis::{FakeCamera, GvFakeCamera};
use std::ffi::c_void;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// Renders one frame: `(width, height, exposure_us) -> width·height` Mono16 samples, row-major.
pub type FillFn = Arc<dyn Fn(usize, usize, f64) -> Vec<u16> + Send + Sync>;

/// The address the simulator listens on.
pub const FAKE_ADDRESS: &str = "127.0.0.1";

#[derive(Debug, thiserror::Error)]
pub enum FakeCameraError {
    #[error("the GigE Vision fake camera did not start on {FAKE_ADDRESS} (port 3956 taken?)")]
    NotRunning,
    #[error("the GigE Vision fake camera has no inner fake camera")]
    NoFakeCamera,
}

/// What the fill callback reads; owned by `FakeGvCamera`, borrowed by the simulator's thread.
struct FillState {
    fill: FillFn,
    served: AtomicU64,
}

pub struct FakeGvCamera {
    gv: Option<GvFakeCamera>,
    fake: Option<FakeCamera>,
    state: *mut FillState,
    serial: String,
}

// SAFETY: `state` is only dereferenced by the simulator's fill callback (as `&FillState`, whose
// contents are Send + Sync) and freed in `Drop` after the callback has been uninstalled; the
// GObjects are Send.
unsafe impl Send for FakeGvCamera {}

impl FakeGvCamera {
    /// Starts a simulated GigE Vision camera with serial number `serial` on 127.0.0.1 whose
    /// frames `fill` renders (Mono16 samples; a Mono8 stream gets their top bytes).
    pub fn start(serial: &str, fill: FillFn) -> Result<Self, FakeCameraError> {
        let gv = GvFakeCamera::new(Some(FAKE_ADDRESS), Some(serial));
        if !gv.is_running() {
            return Err(FakeCameraError::NotRunning);
        }
        let fake = gv.fake_camera().ok_or(FakeCameraError::NoFakeCamera)?;
        let state = Box::into_raw(Box::new(FillState {
            fill,
            served: AtomicU64::new(0),
        }));
        // SAFETY: `fake` is a live ArvFakeCamera; `state` stays valid until `Drop` has put the
        // default pattern back (which takes the same mutex the fill runs under).
        unsafe {
            aravis_sys::arv_fake_camera_set_fill_pattern(
                fake.to_glib_none().0,
                Some(fill_trampoline),
                state as *mut c_void,
            );
        }
        Ok(Self {
            gv: Some(gv),
            fake: Some(fake),
            state,
            serial: serial.to_string(),
        })
    }

    /// Where to open it: `AravisCamera::open(fake.address())`.
    pub fn address(&self) -> &'static str {
        FAKE_ADDRESS
    }

    pub fn serial(&self) -> &str {
        &self.serial
    }

    /// Frames rendered so far.
    pub fn frames_served(&self) -> u64 {
        // SAFETY: `state` lives as long as `self`.
        unsafe { (*self.state).served.load(Ordering::SeqCst) }
    }

    /// Stops the simulator: the camera vanishes from the network (no more GVCP answers or
    /// stream packets), as if unplugged.
    pub fn stop(self) {
        drop(self)
    }
}

impl Drop for FakeGvCamera {
    fn drop(&mut self) {
        if let Some(fake) = self.fake.take() {
            // SAFETY: back to the built-in pattern; returns once no fill is running, so the
            // simulator never sees `state` again.
            unsafe {
                aravis_sys::arv_fake_camera_set_fill_pattern(
                    fake.to_glib_none().0,
                    None,
                    std::ptr::null_mut(),
                );
            }
        }
        // The last reference: finalising stops the simulator's thread and closes its sockets.
        self.gv.take();
        // SAFETY: allocated by `Box::into_raw` in `start`, no longer reachable by the callback.
        unsafe { drop(Box::from_raw(self.state)) };
    }
}

/// Writes one rendered frame into the simulator's buffer. Runs on the simulator's thread.
unsafe extern "C" fn fill_trampoline(
    buffer: *mut aravis_sys::ArvBuffer,
    data: *mut c_void,
    exposure_time_us: u32,
    _gain: u32,
    pixel_format: aravis_sys::ArvPixelFormat,
) {
    if buffer.is_null() || data.is_null() {
        return;
    }
    let state = &*(data as *const FillState);
    let width = aravis_sys::arv_buffer_get_image_width(buffer).max(0) as usize;
    let height = aravis_sys::arv_buffer_get_image_height(buffer).max(0) as usize;
    let bytes_per_sample = match pixel_format {
        PFNC_MONO8 => 1,
        PFNC_MONO16 => 2,
        _ => return, // the simulator's other formats (RGB, Bayer) are not served
    };
    let need_bytes = width * height * bytes_per_sample;
    let mut size = 0usize;
    let ptr = aravis_sys::arv_buffer_get_data(buffer, &mut size);
    // Aravis 0.8.26 reports the received size (0 before a fill) rather than the allocation, and
    // the fill cannot set it; `arv_fake_camera_fill_buffer` has already checked that the
    // allocation holds the payload (Width x Height x bytes per pixel) and the simulator sends the
    // payload from the data pointer. A non-zero size shorter than the frame is inconsistent.
    if ptr.is_null() || (size != 0 && size < need_bytes) {
        return;
    }
    let out = std::slice::from_raw_parts_mut(ptr, need_bytes);
    // A panic must not unwind into C; a frame the caller failed to render goes out black.
    let samples = catch_unwind(AssertUnwindSafe(|| {
        (state.fill)(width, height, exposure_time_us as f64)
    }));
    match samples {
        Ok(s) if s.len() == width * height => {
            if pack_for_fake(&s, pixel_format, out).is_err() {
                out.fill(0);
            }
        }
        _ => out.fill(0),
    }
    state.served.fetch_add(1, Ordering::SeqCst);
}
