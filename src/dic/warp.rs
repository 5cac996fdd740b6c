//! The first-order (affine) shape function and its inverse-compositional update.

/// Shape-function parameters p = (u, ∂u/∂x, ∂u/∂y, v, ∂v/∂x, ∂v/∂y): a subset point at offset
/// (dx, dy) from the centre maps to (x0 + u + (1+ux)dx + uy·dy, y0 + v + vx·dx + (1+vy)dy).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Warp {
    pub u: f64,
    pub ux: f64,
    pub uy: f64,
    pub v: f64,
    pub vx: f64,
    pub vy: f64,
}

impl Warp {
    pub const fn translation(u: f64, v: f64) -> Self {
        Self {
            u,
            ux: 0.0,
            uy: 0.0,
            v,
            vx: 0.0,
            vy: 0.0,
        }
    }

    pub fn from_array(p: [f64; 6]) -> Self {
        Self {
            u: p[0],
            ux: p[1],
            uy: p[2],
            v: p[3],
            vx: p[4],
            vy: p[5],
        }
    }

    /// Where the subset offset (dx, dy) lands, relative to the subset centre.
    #[inline]
    pub fn apply(&self, dx: f64, dy: f64) -> (f64, f64) {
        (
            self.u + (1.0 + self.ux) * dx + self.uy * dy,
            self.v + self.vx * dx + (1.0 + self.vy) * dy,
        )
    }

    /// The same affine field seen from a subset centred (sx, sy) px further on.
    pub fn moved_by(&self, sx: f64, sy: f64) -> Self {
        Self {
            u: self.u + self.ux * sx + self.uy * sy,
            v: self.v + self.vx * sx + self.vy * sy,
            ..*self
        }
    }

    /// W(self) ∘ W(dp)⁻¹: the inverse-compositional update of Baker & Matthews (IJCV 56, 2004).
    /// Returns None when W(dp) is singular.
    pub fn compose_inverse(&self, dp: &Warp) -> Option<Warp> {
        // W(dp) = [[a, b, tx], [c, d, ty]]; its inverse is [[d, -b], [-c, a]]/det with
        // translation -(A⁻¹ t).
        let (a, b, c, d) = (1.0 + dp.ux, dp.uy, dp.vx, 1.0 + dp.vy);
        let det = a * d - b * c;
        if det.abs() < 1e-12 {
            return None;
        }
        let (ia, ib, ic, id) = (d / det, -b / det, -c / det, a / det);
        let itx = -(ia * dp.u + ib * dp.v);
        let ity = -(ic * dp.u + id * dp.v);
        // self as matrix
        let (sa, sb, sc, sd) = (1.0 + self.ux, self.uy, self.vx, 1.0 + self.vy);
        let na = sa * ia + sb * ic;
        let nb = sa * ib + sb * id;
        let nc = sc * ia + sd * ic;
        let nd = sc * ib + sd * id;
        let ntx = sa * itx + sb * ity + self.u;
        let nty = sc * itx + sd * ity + self.v;
        Some(Warp {
            u: ntx,
            ux: na - 1.0,
            uy: nb,
            v: nty,
            vx: nc,
            vy: nd - 1.0,
        })
    }

    /// Largest displacement, px, an update causes anywhere in a subset of half-width `half`
    /// (translation plus gradients times the half-width): the convergence measure |Δp|.
    pub fn update_norm(&self, half: f64) -> f64 {
        (self.u * self.u
            + self.v * self.v
            + (half * self.ux).powi(2)
            + (half * self.uy).powi(2)
            + (half * self.vx).powi(2)
            + (half * self.vy).powi(2))
        .sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compose_with_own_inverse_is_identity() {
        let w = Warp::from_array([1.5, 0.01, -0.02, -3.0, 0.005, 0.03]);
        let id = w.compose_inverse(&w).unwrap();
        for v in [id.u, id.ux, id.uy, id.v, id.vx, id.vy] {
            assert!(v.abs() < 1e-12);
        }
    }

    #[test]
    fn composition_matches_point_mapping() {
        let w = Warp::from_array([1.5, 0.01, -0.02, -3.0, 0.005, 0.03]);
        let dp = Warp::from_array([0.1, 0.001, 0.002, -0.05, -0.001, 0.0005]);
        let n = w.compose_inverse(&dp).unwrap();
        // n(dp(x)) == w(x)
        let (x, y) = (7.0, -4.0);
        let (px, py) = dp.apply(x, y);
        let (a, b) = n.apply(px, py);
        let (c, d) = w.apply(x, y);
        assert!((a - c).abs() < 1e-12 && (b - d).abs() < 1e-12);
    }
}
