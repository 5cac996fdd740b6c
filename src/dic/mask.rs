//! Which points of interest are analysed: polygons in the settings and, optionally, a raster
//! mask (an image whose non-zero pixels are analysed). A point whose subset centre lies outside
//! gets the `masked` status and is never correlated, so a hole, an edge of the specimen or a
//! label on it cannot produce a displacement.

use super::{DicError, PoiGrid};
use crate::image::Image;
use serde::{Deserialize, Serialize};

/// A closed polygon, vertices in px (image coordinates, pixel centres at integers).
pub type Polygon = Vec<[f64; 2]>;

/// Polygons that bound the analysed region: a point is analysed when it lies inside some
/// `include` polygon (or `include` is empty) and inside no `exclude` polygon.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PolygonMask {
    pub include: Vec<Polygon>,
    pub exclude: Vec<Polygon>,
}

/// Upper bound on the vertices of all polygons together (a request cannot make every point
/// test walk millions of edges).
pub const MAX_MASK_VERTICES: usize = 10_000;

impl PolygonMask {
    pub fn validate(&self) -> Result<(), DicError> {
        let polygons = self.include.iter().chain(&self.exclude);
        let mut vertices = 0usize;
        for polygon in polygons {
            if polygon.len() < 3 {
                return Err(DicError::Setting {
                    field: "mask",
                    reason: "every polygon needs at least 3 vertices".into(),
                });
            }
            if polygon.iter().flatten().any(|c| !c.is_finite()) {
                return Err(DicError::Setting {
                    field: "mask",
                    reason: "polygon vertices must be finite".into(),
                });
            }
            vertices += polygon.len();
        }
        if vertices > MAX_MASK_VERTICES {
            return Err(DicError::Setting {
                field: "mask",
                reason: format!("at most {MAX_MASK_VERTICES} vertices in all"),
            });
        }
        Ok(())
    }

    pub fn contains(&self, x: f64, y: f64) -> bool {
        let included = self.include.is_empty() || self.include.iter().any(|p| inside(p, x, y));
        included && !self.exclude.iter().any(|p| inside(p, x, y))
    }
}

/// Even-odd rule (ray casting along +x).
fn inside(polygon: &[[f64; 2]], x: f64, y: f64) -> bool {
    let mut odd = false;
    let mut j = polygon.len() - 1;
    for i in 0..polygon.len() {
        let ([xi, yi], [xj, yj]) = (polygon[i], polygon[j]);
        if (yi > y) != (yj > y) && x < xj + (y - yj) * (xi - xj) / (yi - yj) {
            odd = !odd;
        }
        j = i;
    }
    odd
}

/// A raster mask: non-zero pixels are analysed.
#[derive(Clone, Debug, PartialEq)]
pub struct RasterMask {
    width: usize,
    height: usize,
    analysed: Vec<bool>,
}

impl RasterMask {
    pub fn from_image(image: &Image) -> Self {
        Self {
            width: image.width(),
            height: image.height(),
            analysed: image.data().iter().map(|&v| v != 0.0).collect(),
        }
    }

    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    fn contains(&self, x: usize, y: usize) -> bool {
        x < self.width && y < self.height && self.analysed[y * self.width + x]
    }
}

/// For every point of the grid (row-major), whether it is analysed.
pub fn analysed_points(
    grid: &PoiGrid,
    polygons: Option<&PolygonMask>,
    raster: Option<&RasterMask>,
) -> Vec<bool> {
    let mut out = Vec::with_capacity(grid.len());
    for &y in &grid.ys {
        for &x in &grid.xs {
            let by_polygons = polygons.is_none_or(|m| m.contains(x as f64, y as f64));
            let by_raster = raster.is_none_or(|m| m.contains(x, y));
            out.push(by_polygons && by_raster);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_with_a_hole() {
        let m = PolygonMask {
            include: vec![vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]],
            exclude: vec![vec![[4.0, 4.0], [6.0, 4.0], [6.0, 6.0], [4.0, 6.0]]],
        };
        assert!(m.validate().is_ok());
        assert!(m.contains(1.0, 1.0));
        assert!(!m.contains(5.0, 5.0));
        assert!(!m.contains(11.0, 5.0));
        assert!(PolygonMask::default().contains(-3.0, 1e6));
    }

    #[test]
    fn degenerate_polygons_are_refused() {
        let m = PolygonMask {
            include: vec![vec![[0.0, 0.0], [1.0, 1.0]]],
            exclude: vec![],
        };
        assert!(m.validate().is_err());
    }
}
