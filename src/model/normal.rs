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
    let ([g0, d0, _], [g1, d1, _], f) = nodes(z);
    hermite((g0, d0), (g1, d1), f)
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
    let ([_, c0, p0], [_, c1, p1], f) = nodes(z);
    hermite((c0, p0), (c1, p1), f)
}

/// The table's rows about z and z's fraction of the way between them.
#[inline]
fn nodes(z: f64) -> ([f64; 3], [f64; 3], f64) {
    let table = table();
    let t = (z + NORMAL_RANGE) * NODES_PER_UNIT;
    let i = (t as usize).min(table.len() - 2);
    (table[i], table[i + 1], t - i as f64)
}

/// The cubic through (0, v0) and (1, v1) with slopes d0 and d1 per unit of z, at f ∈ [0, 1].
#[inline]
fn hermite((v0, d0): (f64, f64), (v1, d1): (f64, f64), f: f64) -> f64 {
    let h = 1.0 / NODES_PER_UNIT;
    let f2 = f * f;
    let f3 = f2 * f;
    (2.0 * f3 - 3.0 * f2 + 1.0) * v0
        + (f3 - 2.0 * f2 + f) * h * d0
        + (-2.0 * f3 + 3.0 * f2) * v1
        + (f3 - f2) * h * d1
}

/// (G(z), Φ(z), φ(z)) at z = −9 + k/256, k = 0..=4608.
fn table() -> &'static [[f64; 3]] {
    static TABLE: std::sync::OnceLock<Vec<[f64; 3]>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let n = (2.0 * NORMAL_RANGE * NODES_PER_UNIT) as usize;
        (0..=n)
            .map(|k| {
                let z = -NORMAL_RANGE + k as f64 / NODES_PER_UNIT;
                let (cdf, pdf) = exact(z);
                [z * cdf + pdf, cdf, pdf]
            })
            .collect()
    })
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
