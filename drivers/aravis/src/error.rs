//! Aravis' GLib errors as `HwError`s.

use aravis::glib;
use aravis::{DeviceError, GcError};
use ffdic_hw::HwError;
use std::time::Instant;

/// Maps an error of the operation `what`, which started at `started` (so a control-channel
/// timeout reports how long it really waited: Aravis retries internally).
pub(crate) fn map_error(what: &str, started: Instant, e: &glib::Error) -> HwError {
    if let Some(kind) = e.kind::<DeviceError>() {
        return match kind {
            DeviceError::Timeout => HwError::Timeout {
                what: format!("{what} ({})", e.message()),
                after_ms: started.elapsed().as_millis() as u64,
            },
            DeviceError::NotConnected | DeviceError::NotFound => {
                HwError::Disconnected(format!("{what}: {}", e.message()))
            }
            DeviceError::ProtocolErrorBusy | DeviceError::NotController => {
                HwError::Busy(format!("{what}: {}", e.message()))
            }
            DeviceError::FeatureNotFound | DeviceError::ProtocolErrorNotImplemented => {
                HwError::Unsupported(format!("{what}: {}", e.message()))
            }
            _ => HwError::Protocol(format!("{what}: {}", e.message())),
        };
    }
    if let Some(kind) = e.kind::<GcError>() {
        return match kind {
            GcError::NodeNotFound
            | GcError::PropertyNotDefined
            | GcError::EnumEntryNotFound
            | GcError::ReadOnly => HwError::Unsupported(format!("{what}: {}", e.message())),
            _ => HwError::Protocol(format!("{what}: {}", e.message())),
        };
    }
    HwError::Protocol(format!("{what}: {}", e.message()))
}

/// Runs one control-channel call and maps its error.
pub(crate) fn ctl<T>(what: &str, f: impl FnOnce() -> Result<T, glib::Error>) -> Result<T, HwError> {
    let started = Instant::now();
    f().map_err(|e| map_error(what, started, &e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_errors_map_to_their_hw_errors() {
        let t0 = Instant::now();
        let e = glib::Error::new(DeviceError::Timeout, "no answer");
        assert!(matches!(
            map_error("read Width", t0, &e),
            HwError::Timeout { .. }
        ));
        let e = glib::Error::new(DeviceError::NotConnected, "gone");
        assert!(matches!(map_error("x", t0, &e), HwError::Disconnected(_)));
        let e = glib::Error::new(DeviceError::ProtocolErrorBusy, "busy");
        assert!(matches!(map_error("x", t0, &e), HwError::Busy(_)));
        let e = glib::Error::new(GcError::NodeNotFound, "no Gain");
        assert!(matches!(map_error("x", t0, &e), HwError::Unsupported(_)));
        let e = glib::Error::new(GcError::OutOfRange, "too big");
        assert!(matches!(map_error("x", t0, &e), HwError::Protocol(_)));
    }
}
