//! `FakeGvCamera`: Aravis' GigE Vision camera simulator, in process, serving the caller's frames.
//!
//! Frames travel the real GigE Vision stack (GVCP control, GVSP stream over UDP on 127.0.0.1),
//! so a test exercises the same driver code as a lab camera. The in-process "Fake" interface is
//! not used: with a custom fill pattern it delivered 0-byte buffers (NOTES-hardware.md).
//!
//! The simulator listens on 127.0.0.1:3956, so only one runs per network namespace; run tests in
//! a namespace of their own with only loopback (Aravis discovery broadcasts on every interface).
//!
//! [`FakeGvCamera::start`] serves Aravis' own simulator as it is (binning without a mode, no
//! decimation); [`FakeGvCamera::start_sfnc`] extends its GenICam description with the SFNC
//! features many sCMOS cameras have — `DecimationHorizontal/Vertical` and
//! `BinningHorizontalMode/VerticalMode` (Sum, Average) — stored in free registers of the
//! simulator's memory. The simulator itself does not reduce anything: the fill receives the
//! binning, decimation and mode the driver set ([`FillRequest`]) and renders the frame as that
//! read-out would deliver it.

use crate::unpack::{pack_for_fake, PFNC_MONO16, PFNC_MONO8};
use aravis::glib::translate::{from_glib_full, ToGlibPtr};
use aravis::{FakeCamera, GvFakeCamera};
use std::ffi::c_void;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;

/// What the simulator asks the fill for: one frame as the camera is set to read it out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FillRequest {
    /// Output pixels (after binning and decimation): `Width` x `Height`.
    pub width: usize,
    pub height: usize,
    pub exposure_us: f64,
    /// `BinningHorizontal/Vertical` as set.
    pub binning: (u32, u32),
    /// `DecimationHorizontal/Vertical` as set; (1, 1) on the stock simulator.
    pub decimation: (u32, u32),
    /// `BinningHorizontalMode` is Average (else Sum); the stock simulator has no mode.
    pub binning_average: bool,
}

/// Renders one frame: `request.width · request.height` Mono16 samples, row-major.
pub type FillFn = Arc<dyn Fn(&FillRequest) -> Vec<u16> + Send + Sync>;

/// The address the simulator listens on.
pub const FAKE_ADDRESS: &str = "127.0.0.1";

#[derive(Debug, thiserror::Error)]
pub enum FakeCameraError {
    #[error("the GigE Vision fake camera did not start on {FAKE_ADDRESS} (port 3956 taken?)")]
    NotRunning,
    #[error("the GigE Vision fake camera has no inner fake camera")]
    NoFakeCamera,
    #[error("cannot write the fake camera's GenICam description: {0}")]
    Description(String),
}

/// The simulator's own GenICam description with the SFNC decimation and binning-mode features
/// added (registers above).
fn sfnc_genicam_xml(serial: &str) -> Result<String, FakeCameraError> {
    let serial_c =
        std::ffi::CString::new(serial).map_err(|e| FakeCameraError::Description(e.to_string()))?;
    // SAFETY: a fresh ArvFakeCamera (not on the network), read and released here; its XML is
    // copied before the release.
    let stock = unsafe {
        let camera = aravis_sys::arv_fake_camera_new(serial_c.as_ptr());
        if camera.is_null() {
            return Err(FakeCameraError::NoFakeCamera);
        }
        let mut size = 0usize;
        let xml = aravis_sys::arv_fake_camera_get_genicam_xml(camera, &mut size);
        let text = if xml.is_null() {
            None
        } else {
            let bytes = std::slice::from_raw_parts(xml as *const u8, size);
            Some(String::from_utf8_lossy(bytes).into_owned())
        };
        aravis::glib::gobject_ffi::g_object_unref(camera as *mut _);
        text
    }
    .ok_or_else(|| FakeCameraError::Description("the simulator has no description".into()))?;
    let end = stock
        .rfind("</RegisterDescription>")
        .ok_or_else(|| FakeCameraError::Description("no </RegisterDescription>".into()))?;
    let int_reg = |name: &str, address: u32| {
        format!(
            "<IntReg Name=\"{name}\" NameSpace=\"Custom\"><Address>{address:#x}</Address>\
             <Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>\
             <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess></IntReg>\n"
        )
    };
    let mut added = String::new();
    for (name, address) in [
        ("DecimationHorizontal", REG_DECIMATION_HORIZONTAL),
        ("DecimationVertical", REG_DECIMATION_VERTICAL),
    ] {
        added += &format!(
            "<Integer Name=\"{name}\" NameSpace=\"Standard\"><pValue>{name}Register</pValue>\
             <Min>1</Min><Max>{FAKE_DECIMATION_MAX}</Max></Integer>\n"
        );
        added += &int_reg(&format!("{name}Register"), address);
    }
    for (name, address) in [
        ("BinningHorizontalMode", REG_BINNING_HORIZONTAL_MODE),
        ("BinningVerticalMode", REG_BINNING_VERTICAL_MODE),
    ] {
        added += &format!(
            "<Enumeration Name=\"{name}\" NameSpace=\"Standard\">\
             <EnumEntry Name=\"Sum\" NameSpace=\"Standard\"><Value>{MODE_SUM}</Value></EnumEntry>\
             <EnumEntry Name=\"Average\" NameSpace=\"Standard\"><Value>{MODE_AVERAGE}</Value></EnumEntry>\
             <pValue>{name}Register</pValue></Enumeration>\n"
        );
        added += &int_reg(&format!("{name}Register"), address);
    }
    Ok(format!("{}{added}{}", &stock[..end], &stock[end..]))
}

/// Registers of the SFNC extension ([`FakeGvCamera::start_sfnc`]): above the GigE Vision
/// bootstrap registers (which end at 0xc10c) and inside the simulator's 64 KiB memory.
const REG_DECIMATION_HORIZONTAL: u32 = 0xf000;
const REG_DECIMATION_VERTICAL: u32 = 0xf004;
const REG_BINNING_HORIZONTAL_MODE: u32 = 0xf008;
const REG_BINNING_VERTICAL_MODE: u32 = 0xf00c;
/// Values of the mode enumeration.
const MODE_SUM: u32 = 0;
const MODE_AVERAGE: u32 = 1;
/// The largest decimation the extension offers per axis.
pub const FAKE_DECIMATION_MAX: u32 = 4;

/// What the fill callback reads; owned by `FakeGvCamera`, borrowed by the simulator's thread.
struct FillState {
    fill: FillFn,
    /// The simulator whose registers the fill reads (alive as long as `FakeGvCamera::fake`).
    camera: *mut aravis_sys::ArvFakeCamera,
    /// Whether the SFNC extension's registers exist.
    sfnc: bool,
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
        Self::serve(gv, serial, fill, false)
    }

    /// [`FakeGvCamera::start`] with the SFNC decimation and binning-mode features (module doc):
    /// decimation 1 to [`FAKE_DECIMATION_MAX`] per axis, binning Average (set) or Sum.
    pub fn start_sfnc(serial: &str, fill: FillFn) -> Result<Self, FakeCameraError> {
        let xml = sfnc_genicam_xml(serial)?;
        // The simulator reads its description from a file once, while it is being made.
        let path = std::env::temp_dir().join(format!(
            "ffdic-fake-{}-{}.xml",
            std::process::id(),
            serial.replace(|c: char| !c.is_ascii_alphanumeric(), "_")
        ));
        std::fs::write(&path, xml).map_err(|e| FakeCameraError::Description(e.to_string()))?;
        let c = |s: &str| {
            std::ffi::CString::new(s).map_err(|e| FakeCameraError::Description(e.to_string()))
        };
        let (interface, serial_c, file) =
            (c(FAKE_ADDRESS)?, c(serial)?, c(&path.to_string_lossy())?);
        // SAFETY: three valid C strings; the result is a new full reference (or null).
        let raw = unsafe {
            aravis_sys::arv_gv_fake_camera_new_full(
                interface.as_ptr(),
                serial_c.as_ptr(),
                file.as_ptr(),
            )
        };
        let _ = std::fs::remove_file(&path);
        if raw.is_null() {
            return Err(FakeCameraError::NotRunning);
        }
        // SAFETY: `raw` is a non-null, owned ArvGvFakeCamera.
        let gv: GvFakeCamera = unsafe { from_glib_full(raw) };
        Self::serve(gv, serial, fill, true)
    }

    fn serve(
        gv: GvFakeCamera,
        serial: &str,
        fill: FillFn,
        sfnc: bool,
    ) -> Result<Self, FakeCameraError> {
        if !gv.is_running() {
            return Err(FakeCameraError::NotRunning);
        }
        let fake = gv.fake_camera().ok_or(FakeCameraError::NoFakeCamera)?;
        let camera: *mut aravis_sys::ArvFakeCamera = fake.to_glib_none().0;
        if sfnc {
            for (register, value) in [
                (REG_DECIMATION_HORIZONTAL, 1),
                (REG_DECIMATION_VERTICAL, 1),
                (REG_BINNING_HORIZONTAL_MODE, MODE_AVERAGE),
                (REG_BINNING_VERTICAL_MODE, MODE_AVERAGE),
            ] {
                // SAFETY: a live ArvFakeCamera; the address lies inside its memory.
                unsafe { aravis_sys::arv_fake_camera_write_register(camera, register, value) };
            }
        }
        let state = Box::into_raw(Box::new(FillState { fill, camera, sfnc }));
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
    let register = |address: i32| -> u32 {
        let mut value = 0u32;
        aravis_sys::arv_fake_camera_read_register(state.camera, address as u32, &mut value);
        value
    };
    let (decimation, binning_average) = if state.sfnc {
        (
            (
                register(REG_DECIMATION_HORIZONTAL as i32).max(1),
                register(REG_DECIMATION_VERTICAL as i32).max(1),
            ),
            register(REG_BINNING_HORIZONTAL_MODE as i32) == MODE_AVERAGE,
        )
    } else {
        ((1, 1), false)
    };
    let request = FillRequest {
        width,
        height,
        exposure_us: exposure_time_us as f64,
        binning: (
            register(aravis_sys::ARV_FAKE_CAMERA_REGISTER_BINNING_HORIZONTAL).max(1),
            register(aravis_sys::ARV_FAKE_CAMERA_REGISTER_BINNING_VERTICAL).max(1),
        ),
        decimation,
        binning_average,
    };
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
    let samples = catch_unwind(AssertUnwindSafe(|| (state.fill)(&request)));
    match samples {
        Ok(s) if s.len() == width * height => {
            if pack_for_fake(&s, pixel_format, out).is_err() {
                out.fill(0);
            }
        }
        _ => out.fill(0),
    }
}
