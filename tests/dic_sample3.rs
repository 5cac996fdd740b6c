//! DIC Challenge 1.0 Sample 3: Fourier-shifted 8-bit speckle with σ ≈ 1.1 grey-level noise, true
//! shifts (0.1k, 0.1k) px. Acceptance of the DIC engine issue: subset 41, step 20, ROI inside the
//! 512x512 image.

use crate::common;

use ffdic::dic::{analyze, DicSettings};
use ffdic::image::read_tiff;

#[test]
fn sample3_shifts_are_recovered_within_the_bounds() {
    let dir = common::shared_data().join("dic-challenge-1/sample3");
    let (reference, _) = read_tiff(&dir.join("reference.tif")).expect("shared Sample 3 data");
    let settings = DicSettings::default();
    assert_eq!((settings.subset_px, settings.step_px), (41, 20));
    for k in 1..=10 {
        let (deformed, _) = read_tiff(&dir.join(format!("shift_{k:02}.tif"))).unwrap();
        let r = analyze(&reference, &deformed, &settings, None).unwrap();
        let s = r.summary;
        let truth = 0.1 * k as f64;
        println!(
            "k={k}: u {:.5}±{:.5} v {:.5}±{:.5} exx std {:.1} µε eyy std {:.1} µε ({} of {})",
            s.u.mean,
            s.u.std,
            s.v.mean,
            s.v.std,
            s.exx.std * 1e6,
            s.eyy.std * 1e6,
            s.valid,
            s.points
        );
        assert_eq!(s.valid, s.points, "every point converges on Sample 3");
        assert!(
            (s.u.mean - truth).abs() <= 0.002,
            "k={k}: mean u {}",
            s.u.mean
        );
        assert!(
            (s.v.mean - truth).abs() <= 0.002,
            "k={k}: mean v {}",
            s.v.mean
        );
        assert!(s.u.std <= 0.004, "k={k}: std u {}", s.u.std);
        assert!(s.v.std <= 0.004, "k={k}: std v {}", s.v.std);
        assert!(s.exx.std <= 40e-6, "k={k}: std exx {}", s.exx.std);
        assert!(s.eyy.std <= 40e-6, "k={k}: std eyy {}", s.eyy.std);
    }
}

#[test]
fn sample3_noise_floor_pair_is_near_zero() {
    let dir = common::shared_data().join("dic-challenge-1/sample3");
    let (reference, _) = read_tiff(&dir.join("reference.tif")).unwrap();
    let (second, _) = read_tiff(&dir.join("shift_00.tif")).unwrap();
    let r = analyze(&reference, &second, &DicSettings::default(), None).unwrap();
    assert_eq!(r.summary.valid, r.summary.points);
    assert!(r.summary.u.mean.abs() <= 0.002 && r.summary.v.mean.abs() <= 0.002);
    assert!(r.summary.u.std <= 0.004 && r.summary.v.std <= 0.004);
}
