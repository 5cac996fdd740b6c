use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// An axis-aligned pixel rectangle: columns `x..x+width`, rows `y..y+height`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Roi {
    pub x: usize,
    pub y: usize,
    pub width: usize,
    pub height: usize,
}

impl Roi {
    pub const fn new(x: usize, y: usize, width: usize, height: usize) -> Self {
        Self {
            x,
            y,
            width,
            height,
        }
    }

    /// The `width x height` rectangle centred in an image of `image_width x image_height`,
    /// clipped to the image.
    pub fn centred(image_width: usize, image_height: usize, width: usize, height: usize) -> Self {
        let w = width.min(image_width);
        let h = height.min(image_height);
        Self::new((image_width - w) / 2, (image_height - h) / 2, w, h)
    }

    /// The part of `self` inside an image of the given size, or `None` when nothing is left.
    pub fn clip(&self, image_width: usize, image_height: usize) -> Option<Roi> {
        if self.x >= image_width || self.y >= image_height || self.width == 0 || self.height == 0 {
            return None;
        }
        Some(Roi::new(
            self.x,
            self.y,
            self.width.min(image_width - self.x),
            self.height.min(image_height - self.y),
        ))
    }
}

impl fmt::Display for Roi {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{},{},{}", self.x, self.y, self.width, self.height)
    }
}

/// Parses `X,Y,W,H`.
impl FromStr for Roi {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let parts: Vec<&str> = s.split(',').map(str::trim).collect();
        if parts.len() != 4 {
            return Err(format!("ROI '{s}' must be X,Y,W,H"));
        }
        let mut v = [0usize; 4];
        for (slot, part) in v.iter_mut().zip(&parts) {
            *slot = part
                .parse()
                .map_err(|_| format!("ROI '{s}': '{part}' is not a non-negative integer"))?;
        }
        if v[2] == 0 || v[3] == 0 {
            return Err(format!("ROI '{s}' has zero width or height"));
        }
        Ok(Roi::new(v[0], v[1], v[2], v[3]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centred_roi_is_clipped_to_small_images() {
        assert_eq!(Roi::centred(512, 512, 800, 800), Roi::new(0, 0, 512, 512));
        assert_eq!(
            Roi::centred(1280, 1080, 800, 800),
            Roi::new(240, 140, 800, 800)
        );
    }

    #[test]
    fn parses_and_rejects() {
        assert_eq!("1, 2,3,4".parse::<Roi>().unwrap(), Roi::new(1, 2, 3, 4));
        assert!("1,2,3".parse::<Roi>().is_err());
        assert!("1,2,-3,4".parse::<Roi>().is_err());
        assert!("1,2,0,4".parse::<Roi>().is_err());
    }

    #[test]
    fn clip_keeps_the_inside() {
        assert_eq!(
            Roi::new(10, 10, 100, 100).clip(50, 60),
            Some(Roi::new(10, 10, 40, 50))
        );
        assert_eq!(Roi::new(60, 10, 10, 10).clip(50, 60), None);
    }
}
