//! The standard normal CDF Φ and its integral G(z) = zΦ(z) + φ(z), from one table by cubic
//! Hermite interpolation: the renderer's dots evaluate them for every pixel edge they reach
//! (a Gaussian dot's profile is a difference of Φ, a blurred disk's strip a difference of G), and
//! erfc and exp there were a sixth of a diagnosis round on Gaussian prints and half of a print's
//! calibration on disks.

/// Beyond ±9 an edge is hard to double precision (Φ(−9) ≈ 1e-19).
pub(super) const NORMAL_RANGE: f64 = 9.0;
/// Nodes of the table per unit of z.
const NODES_PER_UNIT: f64 = 256.0;

/// G(z) = zΦ(z) + φ(z), the integral of the normal CDF (error below 1e-12: h⁴/384 · max|G⁗|,
/// h = 1/256).
#[inline]
pub(super) fn integrated_cdf(z: f64) -> f64 {
    if z >= NORMAL_RANGE {
        return z;
    }
    if z <= -NORMAL_RANGE {
        return 0.0;
    }
    let (cubics, f) = interval(z);
    horner(&cubics[0], f)
}

/// Φ(z), the normal CDF (error below 1e-12, as [`integrated_cdf`]'s, one derivative down).
#[inline]
pub(super) fn cdf(z: f64) -> f64 {
    if z >= NORMAL_RANGE {
        return 1.0;
    }
    if z <= -NORMAL_RANGE {
        return 0.0;
    }
    let (cubics, f) = interval(z);
    horner(&cubics[1], f)
}

/// The table's cubics on the interval holding z, and z's fraction of the way along it.
#[inline]
fn interval(z: f64) -> (&'static [[f64; 4]; 2], f64) {
    let table = table();
    let t = (z + NORMAL_RANGE) * NODES_PER_UNIT;
    let i = (t as usize).min(table.len() - 1);
    (&table[i], t - i as f64)
}

#[inline]
fn horner(c: &[f64; 4], f: f64) -> f64 {
    c[0] + f * (c[1] + f * (c[2] + f * c[3]))
}

/// Per interval between the nodes z = −9 + k/256, k = 0..4608, the cubic Hermite interpolants
/// of G (through G and its slope Φ at both nodes) and of Φ (through Φ and φ), as polynomials in
/// the fraction f ∈ [0, 1]: evaluated by Horner's rule (three multiply-adds), they were a third
/// of a blurred disk's rendering in the Hermite basis.
fn table() -> &'static [[[f64; 4]; 2]] {
    static TABLE: std::sync::OnceLock<Vec<[[f64; 4]; 2]>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let n = (2.0 * NORMAL_RANGE * NODES_PER_UNIT) as usize;
        let node = |k: usize| {
            let z = -NORMAL_RANGE + k as f64 / NODES_PER_UNIT;
            let (cdf, pdf) = exact(z);
            [z * cdf + pdf, cdf, pdf]
        };
        let nodes: Vec<[f64; 3]> = (0..=n).map(node).collect();
        nodes
            .windows(2)
            .map(|w| {
                let ([g0, c0, p0], [g1, c1, p1]) = (w[0], w[1]);
                [
                    hermite_cubic((g0, c0), (g1, c1)),
                    hermite_cubic((c0, p0), (c1, p1)),
                ]
            })
            .collect()
    })
}

/// The cubic through (0, v0) and (1, v1) with slopes d0 and d1 per unit of z, as coefficients
/// of 1, f, f², f³.
fn hermite_cubic((v0, d0): (f64, f64), (v1, d1): (f64, f64)) -> [f64; 4] {
    let h = 1.0 / NODES_PER_UNIT;
    let (s0, s1) = (h * d0, h * d1);
    [
        v0,
        s0,
        3.0 * (v1 - v0) - 2.0 * s0 - s1,
        2.0 * (v0 - v1) + s0 + s1,
    ]
}

/// Φ(z) and φ(z) from erfc and exp: erfc keeps its relative precision in the far tail.
fn exact(z: f64) -> (f64, f64) {
    let cdf = 0.5 * libm::erfc(-z / std::f64::consts::SQRT_2);
    let pdf = (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt();
    (cdf, pdf)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// G and Φ from the table against erfc and exp directly, between and on its nodes and
    /// beyond its range.
    #[test]
    fn the_table_is_exact_to_1e_12() {
        for k in 0..20_000 {
            let z = -9.5 + 19.0 * k as f64 / 20_000.0 + 1e-4;
            let (c, p) = exact(z);
            assert!((integrated_cdf(z) - (z * c + p)).abs() < 1e-12, "G({z})");
            assert!((cdf(z) - c).abs() < 1e-12, "Φ({z})");
        }
    }
}
