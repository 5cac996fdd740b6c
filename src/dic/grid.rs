//! The grid of points of interest (subset centres).
//!
//! The ROI holds the POI centres — the ROI is the span of centres, as in MatchID and the paper,
//! so an 800 px ROI at step 5 has 161 points per axis, from `roi.x` to `roi.x + roi.width`.
//! Only centres whose subset lies wholly inside the image are used: the span is first narrowed
//! to those, and the points are centred in what remains, so a default ROI clipped to a small
//! image gives a grid with equal margins rather than one pushed against a border.

use super::{DicError, DicSettings};
use crate::image::Roi;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoiGrid {
    pub roi: Roi,
    pub step_px: usize,
    /// Column positions of the POIs, px.
    pub xs: Vec<usize>,
    /// Row positions of the POIs, px.
    pub ys: Vec<usize>,
}

impl PoiGrid {
    pub fn new(settings: &DicSettings, width: usize, height: usize) -> Result<Self, DicError> {
        let roi = settings.roi_for(width, height)?;
        if settings.subset_px > roi.width.min(roi.height) {
            return Err(DicError::SubsetLargerThanRoi {
                subset_px: settings.subset_px,
                roi,
            });
        }
        let half = settings.half_subset();
        let axis = |start: usize, span: usize, size: usize| -> Vec<usize> {
            let first = start.max(half);
            let last = (start + span).min(size.saturating_sub(half + 1));
            if size < 2 * half + 1 || first > last {
                return Vec::new();
            }
            let usable = last - first;
            let count = usable / settings.step_px + 1;
            let margin = (usable - (count - 1) * settings.step_px) / 2;
            (0..count)
                .map(|k| first + margin + k * settings.step_px)
                .collect()
        };
        let xs = axis(roi.x, roi.width, width);
        let ys = axis(roi.y, roi.height, height);
        if xs.is_empty() || ys.is_empty() {
            return Err(DicError::NoPointFits {
                subset_px: settings.subset_px,
                roi,
                width,
                height,
            });
        }
        Ok(Self {
            roi,
            step_px: settings.step_px,
            xs,
            ys,
        })
    }

    pub fn nx(&self) -> usize {
        self.xs.len()
    }

    pub fn ny(&self) -> usize {
        self.ys.len()
    }

    pub fn len(&self) -> usize {
        self.nx() * self.ny()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dense_grid_on_the_paper_roi_has_161_points_per_axis() {
        let s = DicSettings {
            step_px: 5,
            ..DicSettings::default()
        };
        let g = PoiGrid::new(&s, 1280, 1080).unwrap();
        assert_eq!((g.nx(), g.ny()), (161, 161));
        assert_eq!(g.len(), 25_921);
        assert_eq!(g.xs[0], 240);
        assert_eq!(*g.xs.last().unwrap(), 1040);
    }

    #[test]
    fn default_roi_on_a_small_image_keeps_subsets_inside() {
        let g = PoiGrid::new(&DicSettings::default(), 512, 512).unwrap();
        // Centres 20..=491 fit; 24 points at step 20 span 460 px, centred: 25..=485.
        assert_eq!(g.xs.first(), Some(&25));
        assert_eq!(g.xs.last(), Some(&485));
        assert_eq!(g.xs.len(), 24);
    }

    #[test]
    fn subset_larger_than_roi_is_an_error() {
        let s = DicSettings {
            roi: Some(Roi::new(100, 100, 30, 30)),
            ..DicSettings::default()
        };
        assert!(matches!(
            PoiGrid::new(&s, 512, 512),
            Err(DicError::SubsetLargerThanRoi { .. })
        ));
    }

    #[test]
    fn roi_outside_the_image_is_an_error() {
        let s = DicSettings {
            roi: Some(Roi::new(600, 10, 50, 50)),
            ..DicSettings::default()
        };
        assert!(matches!(
            PoiGrid::new(&s, 512, 512),
            Err(DicError::RoiOutside { .. })
        ));
    }
}
