use std::time::SystemTime;

/// One image as the camera delivered it: 16-bit samples (8/10/12-bit data keep their values),
/// row-major, no padding.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub width: usize,
    pub height: usize,
    /// Significant bits per sample (8, 10, 12, 16).
    pub bit_depth: u8,
    pub data: Vec<u16>,
    /// The device's frame counter (GigE Vision block id, V4L2 sequence).
    pub frame_id: u64,
    pub device_timestamp_ns: Option<u64>,
    pub host_timestamp: SystemTime,
}

impl Frame {
    pub fn mean(&self) -> f64 {
        self.data.iter().map(|&v| v as f64).sum::<f64>() / self.data.len().max(1) as f64
    }
}
