use serde::{Deserialize, Serialize};

/// One axis of a reduction: `active` consecutive pixels from `first` in every `block` are
/// averaged; the rest of the block is dropped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisScheme {
    pub block: usize,
    pub first: usize,
    pub active: usize,
}

impl AxisScheme {
    /// `active` pixels centred in the block (first = (block − active)/2, rounded down).
    pub fn centred(block: usize, active: usize) -> Self {
        Self {
            block,
            first: block.saturating_sub(active) / 2,
            active,
        }
    }

    pub fn linear_fill_factor(&self) -> f64 {
        self.active as f64 / self.block as f64
    }

    /// Full-resolution coordinate of reduced pixel 0's centre.
    pub fn centre_offset_px(&self) -> f64 {
        self.first as f64 + (self.active as f64 - 1.0) / 2.0
    }

    fn validate(&self, axis: &str) -> Result<(), ReduceError> {
        let end = self.first.checked_add(self.active);
        if self.block == 0
            || self.block > MAX_BLOCK_PX
            || self.active == 0
            || end.is_none_or(|e| e > self.block)
        {
            return Err(ReduceError::InvalidScheme(format!(
                "{axis}: need 1 <= block <= {MAX_BLOCK_PX}, active >= 1 and first + active <= block, got block {} first {} active {}",
                self.block, self.first, self.active
            )));
        }
        Ok(())
    }
}

/// The largest reduction block: a "pixel" of 256 sensor pixels is far beyond any fill-factor
/// question, and bounds what a request can ask of the reducer.
pub const MAX_BLOCK_PX: usize = 256;

/// A reduction scheme: a name and one [`AxisScheme`] per axis.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scheme {
    pub name: String,
    pub x: AxisScheme,
    pub y: AxisScheme,
}

#[derive(Debug, thiserror::Error)]
pub enum ReduceError {
    #[error(
        "unknown scheme '{0}' (the paper's ff100, ff50, ff25; native, every pixel; or \
         BLOCKxBLOCK/APERTURE, e.g. 2x2/1x2: 2x2 blocks, their centred 1x2 pixels light-sensitive)"
    )]
    UnknownPreset(String),
    #[error("invalid scheme {0}")]
    InvalidScheme(String),
    #[error("image of {width}x{height} px is smaller than one {block_x}x{block_y} block")]
    ImageTooSmall {
        width: usize,
        height: usize,
        block_x: usize,
        block_y: usize,
    },
    #[error("cannot parse '{0}': expected NxM, e.g. 3x3")]
    Parse(String),
}

impl Scheme {
    /// A scheme's name becomes part of file names and table columns: letters, digits, `-`,
    /// `_`, `.` and `+`, at most 64.
    pub fn new(name: &str, x: AxisScheme, y: AxisScheme) -> Result<Self, ReduceError> {
        let plain = |c: char| c.is_ascii_alphanumeric() || "-_.+".contains(c);
        if name.is_empty() || name.len() > 64 || !name.chars().all(plain) || name.starts_with('.') {
            return Err(ReduceError::InvalidScheme(format!(
                "name {name:?}: letters, digits, '-', '_', '.' and '+' only, 1 to 64, not starting with '.'"
            )));
        }
        x.validate("x")?;
        y.validate("y")?;
        Ok(Self {
            name: name.to_string(),
            x,
            y,
        })
    }

    /// A scheme by name, in any case (`FF50` is `ff50`): the paper's three and `native` (every
    /// pixel as it is: a camera's own resolution).
    pub fn preset(name: &str) -> Result<Self, ReduceError> {
        let name = name.to_ascii_lowercase();
        let name = name.as_str();
        let bin = AxisScheme {
            block: 2,
            first: 0,
            active: 2,
        };
        let sub = AxisScheme {
            block: 2,
            first: 0,
            active: 1,
        };
        let every = AxisScheme {
            block: 1,
            first: 0,
            active: 1,
        };
        match name {
            "ff100" => Self::new(name, bin, bin),
            "ff50" => Self::new(name, sub, bin),
            "ff25" => Self::new(name, sub, sub),
            "native" => Self::new(name, every, every),
            other => Err(ReduceError::UnknownPreset(other.to_string())),
        }
    }

    /// A scheme as a person writes it on a command line or in a request: a preset name
    /// ([`Self::preset`]) or `BXxBY/AXxAY` (blocks of BX by BY pixels whose centred AX by AY are
    /// light-sensitive, as `ffdic reduce --block --aperture` takes them).
    pub fn parse(spec: &str) -> Result<Self, ReduceError> {
        let spec = spec.trim();
        match spec.split_once('/') {
            Some((block, aperture)) => Self::from_block(block, aperture, None),
            None => Self::preset(spec),
        }
    }

    /// The paper's three schemes (ff100, ff50, ff25).
    pub fn presets() -> Vec<Scheme> {
        ["ff100", "ff50", "ff25"]
            .iter()
            .map(|n| Self::preset(n).expect("presets are valid"))
            .collect()
    }

    /// A general scheme from `--block BXxBY --aperture AXxAY` with the aperture centred, or at
    /// `offset` (first column x first row) when given.
    pub fn from_block(
        block: &str,
        aperture: &str,
        offset: Option<&str>,
    ) -> Result<Self, ReduceError> {
        let (bx, by) = parse_pair(block)?;
        let (ax, ay) = parse_pair(aperture)?;
        let (x, y) = match offset {
            Some(o) => {
                let (fx, fy) = parse_pair(o)?;
                (
                    AxisScheme {
                        block: bx,
                        first: fx,
                        active: ax,
                    },
                    AxisScheme {
                        block: by,
                        first: fy,
                        active: ay,
                    },
                )
            }
            None => (AxisScheme::centred(bx, ax), AxisScheme::centred(by, ay)),
        };
        Self::new(
            &format!("b{bx}x{by}a{ax}x{ay}o{}x{}", x.first, y.first),
            x,
            y,
        )
    }

    /// Linear fill factors (x, y).
    pub fn linear_fill_factor(&self) -> (f64, f64) {
        (self.x.linear_fill_factor(), self.y.linear_fill_factor())
    }

    pub fn area_fill_factor(&self) -> f64 {
        self.x.linear_fill_factor() * self.y.linear_fill_factor()
    }

    /// Full-resolution position of reduced pixel 0's centre.
    pub fn centre_offset_px(&self) -> (f64, f64) {
        (self.x.centre_offset_px(), self.y.centre_offset_px())
    }

    /// Full-resolution position of a reduced-image position.
    pub fn to_full(&self, x_red: f64, y_red: f64) -> (f64, f64) {
        let (ox, oy) = self.centre_offset_px();
        (
            self.x.block as f64 * x_red + ox,
            self.y.block as f64 * y_red + oy,
        )
    }

    /// Reduced-image position of a full-resolution position.
    pub fn to_reduced(&self, x_full: f64, y_full: f64) -> (f64, f64) {
        let (ox, oy) = self.centre_offset_px();
        (
            (x_full - ox) / self.x.block as f64,
            (y_full - oy) / self.y.block as f64,
        )
    }

    /// Output size for an input of `width x height` (partial trailing blocks are dropped).
    pub fn output_size(&self, width: usize, height: usize) -> Result<(usize, usize), ReduceError> {
        let (w, h) = (width / self.x.block, height / self.y.block);
        if w == 0 || h == 0 {
            return Err(ReduceError::ImageTooSmall {
                width,
                height,
                block_x: self.x.block,
                block_y: self.y.block,
            });
        }
        Ok((w, h))
    }
}

fn parse_pair(s: &str) -> Result<(usize, usize), ReduceError> {
    let (a, b) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| ReduceError::Parse(s.into()))?;
    let p = |t: &str| {
        t.trim()
            .parse::<usize>()
            .map_err(|_| ReduceError::Parse(s.into()))
    };
    Ok((p(a)?, p(b)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scheme_is_a_preset_native_or_block_over_aperture() {
        let native = Scheme::parse(" Native ").unwrap();
        assert_eq!(
            (native.name.as_str(), native.area_fill_factor()),
            ("native", 1.0)
        );
        assert_eq!(native.output_size(7, 5).unwrap(), (7, 5));
        // 2x2/1x2 is the paper's ff50 (rows binned, columns subsampled) by another name.
        let half = Scheme::parse("2x2/1x2").unwrap();
        let ff50 = Scheme::preset("ff50").unwrap();
        assert_eq!((half.x, half.y), (ff50.x, ff50.y));
        assert_eq!(
            Scheme::parse("3x3/1x1").unwrap().centre_offset_px(),
            (1.0, 1.0)
        );
        for bad in ["ff75", "2x2", "2x2/3x2", "2x/1x1", ""] {
            assert!(Scheme::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn preset_centres_and_fill_factors() {
        let f = Scheme::preset("ff100").unwrap();
        assert_eq!(f.centre_offset_px(), (0.5, 0.5));
        assert_eq!(f.area_fill_factor(), 1.0);
        let f = Scheme::preset("ff50").unwrap();
        assert_eq!(f.centre_offset_px(), (0.0, 0.5));
        assert_eq!(f.linear_fill_factor(), (0.5, 1.0));
        let f = Scheme::preset("ff25").unwrap();
        assert_eq!(f.centre_offset_px(), (0.0, 0.0));
        assert_eq!(f.area_fill_factor(), 0.25);
        assert_eq!(
            f.to_reduced(f.to_full(3.25, 7.5).0, f.to_full(3.25, 7.5).1),
            (3.25, 7.5)
        );
    }

    #[test]
    fn general_schemes_and_errors() {
        let s = Scheme::from_block("3x3", "1x3", None).unwrap();
        assert_eq!(
            s.x,
            AxisScheme {
                block: 3,
                first: 1,
                active: 1
            }
        );
        assert_eq!(
            s.y,
            AxisScheme {
                block: 3,
                first: 0,
                active: 3
            }
        );
        assert_eq!(s.centre_offset_px(), (1.0, 1.0));
        let s = Scheme::from_block("3x3", "2x3", Some("0x0")).unwrap();
        assert_eq!(s.centre_offset_px(), (0.5, 1.0));
        assert!(matches!(
            Scheme::from_block("3x3", "4x1", None),
            Err(ReduceError::InvalidScheme(_))
        ));
        assert!(matches!(
            Scheme::from_block("3x3", "1x1", Some("3x0")),
            Err(ReduceError::InvalidScheme(_))
        ));
        assert!(matches!(
            Scheme::from_block("3", "1x1", None),
            Err(ReduceError::Parse(_))
        ));
        assert!(matches!(
            Scheme::preset("ff75"),
            Err(ReduceError::UnknownPreset(_))
        ));
        assert!(Scheme::preset("ff25").unwrap().output_size(1, 9).is_err());
    }
}
