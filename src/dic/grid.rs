//! The grid of points of interest (subset centres).
//!
//! The ROI holds the POI centres: along x they sit at `roi.x, roi.x + step, ...` up to and
//! including `roi.x + roi.width` — the ROI is the span of centres, as in MatchID and the paper,
//! so an 800 px ROI at step 5 has 161 points per axis. Points whose subset would not lie wholly
//! inside the image are dropped, so the default ROI clipped to a small image still works.

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
            (0..=span / settings.step_px)
                .map(|k| start + k * settings.step_px)
                .filter(|&c| c >= half && c + half < size)
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
        assert_eq!(g.xs.first(), Some(&20));
        assert_eq!(g.xs.last(), Some(&480));
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
