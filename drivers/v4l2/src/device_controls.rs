//! The device side of the controls (`controls` maps their values): which exposure and gain
//! controls a node has, with their ranges, and reading and setting them through ioctls.

use crate::controls::{
    ControlRange, CID_ANALOGUE_GAIN, CID_EXPOSURE_ABSOLUTE, CID_EXPOSURE_AUTO, CID_GAIN,
};
use std::io;
use v4l::control::{Control, Value};
use v4l::Device;

/// The settable exposure and gain controls one device has.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Controls {
    pub exposure_auto: Option<ControlRange>,
    pub exposure: Option<ControlRange>,
    /// The gain control used (ANALOGUE_GAIN if present, else GAIN) and its range.
    pub gain: Option<(u32, ControlRange)>,
}

impl Controls {
    /// Asks the device. Ranges can change with the format (sensor modes), so call again after
    /// VIDIOC_S_FMT.
    pub fn discover(device: &Device) -> io::Result<Self> {
        let gain = match query_range(device, CID_ANALOGUE_GAIN)? {
            Some(r) => Some((CID_ANALOGUE_GAIN, r)),
            None => query_range(device, CID_GAIN)?.map(|r| (CID_GAIN, r)),
        };
        Ok(Self {
            exposure_auto: query_range(device, CID_EXPOSURE_AUTO)?,
            exposure: query_range(device, CID_EXPOSURE_ABSOLUTE)?,
            gain,
        })
    }
}

/// VIDIOC_QUERY_EXT_CTRL for one id: `None` when the device lacks the control, or has it disabled
/// or read-only (nothing this driver could set).
pub fn query_range(device: &Device, id: u32) -> io::Result<Option<ControlRange>> {
    use v4l::v4l_sys::v4l2_query_ext_ctrl;
    const FLAG_DISABLED: u32 = 0x0001;
    const FLAG_READ_ONLY: u32 = 0x0004;
    // SAFETY: v4l2_query_ext_ctrl holds only integers and arrays of them, so all-zero is a valid
    // value; the ioctl writes at most size_of::<v4l2_query_ext_ctrl>() bytes (encoded in the
    // request number) into it, and the fd stays open while `device` is borrowed. v4l's own
    // `query_controls` is avoided: it panics on control types newer than its bindings.
    let mut q: v4l2_query_ext_ctrl = unsafe { std::mem::zeroed() };
    q.id = id;
    let r = unsafe {
        v4l::v4l2::ioctl(
            device.handle().fd(),
            v4l::v4l2::vidioc::VIDIOC_QUERY_EXT_CTRL,
            &mut q as *mut _ as *mut std::os::raw::c_void,
        )
    };
    match r {
        Ok(()) if q.flags & (FLAG_DISABLED | FLAG_READ_ONLY) != 0 => Ok(None),
        Ok(()) => Ok(Some(ControlRange {
            min: q.minimum,
            max: q.maximum,
            step: q.step,
            default: q.default_value,
        })),
        // EINVAL: "The struct v4l2_query_ext_ctrl id is invalid" (VIDIOC_QUERYCTRL, Return Value).
        Err(e) if e.raw_os_error() == Some(libc::EINVAL) => Ok(None),
        Err(e) => Err(e),
    }
}

/// Sets an integer or menu control and reads back what the driver kept (drivers clamp and round).
pub fn set_and_read(device: &Device, id: u32, value: i64) -> io::Result<i64> {
    device.set_control(Control {
        id,
        value: Value::Integer(value),
    })?;
    read(device, id)
}

pub fn read(device: &Device, id: u32) -> io::Result<i64> {
    match device.control(id)?.value {
        Value::Integer(v) => Ok(v),
        Value::Boolean(b) => Ok(i64::from(b)),
        other => Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("control 0x{id:08x} is not an integer: {other:?}"),
        )),
    }
}
