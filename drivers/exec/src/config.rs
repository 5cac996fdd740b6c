use serde::{Deserialize, Serialize};

/// `[camera]` with `kind = "exec"`: what to run and what it must deliver.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExecCameraConfig {
    /// The program and its arguments (no shell: write `["sh", "-c", "…"]` for one).
    pub command: Vec<String>,
    pub width: u32,
    pub height: u32,
    /// 8 or 16: the TIFF's samples (16-bit frames may hold 10 or 12 significant bits).
    #[serde(default = "default_bit_depth")]
    pub bit_depth: u8,
    /// How long one frame's command may run, ms.
    #[serde(default = "default_timeout_ms")]
    pub timeout_ms: u64,
}

fn default_bit_depth() -> u8 {
    16
}

fn default_timeout_ms() -> u64 {
    60_000
}

impl ExecCameraConfig {
    /// What the types cannot say, each mistake named.
    pub fn validate(&self) -> Result<(), String> {
        if self.command.first().is_none_or(|p| p.trim().is_empty()) {
            return Err("camera.command needs a program: [\"program\", \"arg\", …]".into());
        }
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "camera.width and camera.height must be positive (got {}x{})",
                self.width, self.height
            ));
        }
        if !matches!(self.bit_depth, 8 | 16) {
            return Err(format!(
                "camera.bit_depth must be 8 or 16 (got {})",
                self.bit_depth
            ));
        }
        if self.timeout_ms == 0 {
            return Err("camera.timeout_ms must be positive".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_config_is_read_with_defaults_and_its_mistakes_named() {
        let c: ExecCameraConfig =
            toml::from_str("command = [\"render\", \"--fast\"]\nwidth = 64\nheight = 48\n")
                .unwrap();
        assert_eq!((c.bit_depth, c.timeout_ms), (16, 60_000));
        assert!(c.validate().is_ok());
        let bad = ExecCameraConfig {
            bit_depth: 12,
            ..c.clone()
        };
        assert!(bad.validate().unwrap_err().contains("bit_depth"));
        let bad = ExecCameraConfig {
            command: vec![],
            ..c.clone()
        };
        assert!(bad.validate().unwrap_err().contains("program"));
        assert!(toml::from_str::<ExecCameraConfig>(
            "command = [\"x\"]\nwidth = 1\nheight = 1\nwidht = 2\n"
        )
        .is_err());
    }
}
