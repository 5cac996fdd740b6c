/// What can go wrong talking to hardware. The daemon maps these to HTTP statuses (Timeout → 504,
/// Disconnected → 503, Busy → 409, OutOfRange → 422).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HwError {
    #[error("{what} timed out after {after_ms} ms")]
    Timeout { what: String, after_ms: u64 },
    #[error("device disconnected: {0}")]
    Disconnected(String),
    #[error("{what} = {value} is outside [{min}, {max}]")]
    OutOfRange {
        what: String,
        value: f64,
        min: f64,
        max: f64,
    },
    #[error("protocol error: {0}")]
    Protocol(String),
    #[error("device busy: {0}")]
    Busy(String),
    #[error("not supported by this device: {0}")]
    Unsupported(String),
    /// The stage has no reference position (power-up, after a fault): a client's fault to fix
    /// by homing, not a protocol failure.
    #[error("{0}")]
    NotReferenced(String),
}
