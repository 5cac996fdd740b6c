use serde::{Deserialize, Serialize};

/// The ADC: values rounded to whole DN and clipped to 0..2^bits - 1.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Quantization {
    pub bits: u32,
}

impl Quantization {
    pub fn max_dn(&self) -> f64 {
        (2f64).powi(self.bits as i32) - 1.0
    }
}
