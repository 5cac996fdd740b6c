//! errno from V4L2 ioctls as `HwError`s (V4L2 UAPI "Generic Error Codes").

use ffdic_hw::HwError;
use std::io;

/// Maps the failure of the operation `what`. Timeouts are not mapped here: only the caller knows
/// how long it waited.
pub(crate) fn map_io(what: &str, e: &io::Error) -> HwError {
    let message = format!("{what}: {e}");
    match e.raw_os_error() {
        // ENODEV: the device was unplugged (or the driver unbound) while open; ENXIO and ENOENT:
        // the node names no device at open.
        Some(libc::ENODEV | libc::ENXIO | libc::ENOENT) => HwError::Disconnected(message),
        // EBUSY: another file handle streams, or owns the buffers (VIDIOC_REQBUFS, S_FMT).
        Some(libc::EBUSY) => HwError::Busy(message),
        // ENOTTY: the ioctl is not implemented: not a V4L2 node, or no such feature.
        Some(libc::ENOTTY) => HwError::Unsupported(message),
        _ => HwError::Protocol(message),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errno_maps_to_hw_errors() {
        let os = io::Error::from_raw_os_error;
        assert!(matches!(
            map_io("DQBUF", &os(libc::ENODEV)),
            HwError::Disconnected(_)
        ));
        assert!(matches!(
            map_io("open", &os(libc::ENOENT)),
            HwError::Disconnected(_)
        ));
        assert!(matches!(
            map_io("REQBUFS", &os(libc::EBUSY)),
            HwError::Busy(_)
        ));
        assert!(matches!(
            map_io("QUERYCAP", &os(libc::ENOTTY)),
            HwError::Unsupported(_)
        ));
        let e = map_io("S_FMT", &os(libc::EINVAL));
        assert!(
            matches!(e, HwError::Protocol(ref m) if m.starts_with("S_FMT: ")),
            "{e:?}"
        );
    }
}
