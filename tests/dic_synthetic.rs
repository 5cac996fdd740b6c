//! DIC on speckle rendered analytically (Gaussian dots integrated exactly over every pixel): the
//! truth has no interpolation in it, so what the engine reports beyond the commanded motion is
//! the engine's own error.

use crate::common;

use ffdic::dic::{analyze, DicSettings, PoiStatus};
use ffdic::image::{Image, Roi};

const W: usize = 480;
const H: usize = 400;

fn settings() -> DicSettings {
    DicSettings {
        roi: Some(Roi::new(140, 100, 200, 200)),
        ..DicSettings::default()
    }
}

fn shifted_pair(dx: f64, dy: f64, seed: u64) -> (Image, Image) {
    let layout = common::layout(W, H, seed);
    let moved = layout.mapped(|x, y| (x + dx, y + dy), (1.0, 1.0));
    (common::render(&layout, W, H), common::render(&moved, W, H))
}

#[test]
fn sub_pixel_shifts_have_small_bias() {
    // With the default pre-filter and without it: the bound holds for the engine itself.
    for sigma in [settings().prefilter_sigma_px, 0.0] {
        let s = DicSettings {
            prefilter_sigma_px: sigma,
            ..settings()
        };
        let mut worst: f64 = 0.0;
        for k in 0..=10 {
            let f = k as f64 / 10.0;
            for (dx, dy) in [(f, 0.0), (0.0, f), (f, f)] {
                let (r, d) = shifted_pair(dx, dy, 11);
                let sm = analyze(&r, &d, &s, None).unwrap().summary;
                assert_eq!(sm.valid, sm.points);
                let (bu, bv) = (sm.u.mean - dx, sm.v.mean - dy);
                worst = worst.max(bu.abs()).max(bv.abs());
                assert!(
                    bu.abs() <= 0.005 && bv.abs() <= 0.005,
                    "σ {sigma}: shift ({dx},{dy}): bias ({bu},{bv})"
                );
            }
        }
        println!("pre-filter σ {sigma} px: worst sub-pixel bias {worst:.5} px");
    }
}

#[test]
fn large_motion_with_sub_pixel_cross_component() {
    let (dx, dy) = (64.3, 0.4);
    let (r, d) = shifted_pair(dx, dy, 12);
    let res = analyze(&r, &d, &settings(), None).unwrap();
    assert_eq!(res.global_offset_px, (64, 0));
    let sm = res.summary;
    println!(
        "(64.3, 0.4): u {:.5} v {:.5} px, std {:.5} {:.5}",
        sm.u.mean, sm.v.mean, sm.u.std, sm.v.std
    );
    assert_eq!(sm.valid, sm.points);
    assert!((sm.u.mean - dx).abs() <= 0.005, "u {}", sm.u.mean);
    assert!((sm.v.mean - dy).abs() <= 0.005, "v {}", sm.v.mean);
}

#[test]
fn large_motions_in_every_direction_are_found() {
    // 150 px in any direction: the global phase correlation must find the integer offset.
    for (dx, dy) in [(150.2, 0.0), (-150.0, 0.3), (0.0, -149.6), (-106.4, 106.1)] {
        let (r, d) = shifted_pair(dx, dy, 13);
        let s = DicSettings {
            // Every subset stays inside the 480x400 image after a 150 px motion.
            roi: Some(Roi::new(175, 172, 120, 55)),
            step_px: 35,
            ..DicSettings::default()
        };
        let res = analyze(&r, &d, &s, None).unwrap();
        let sm = res.summary;
        let st: Vec<_> = res
            .points
            .iter()
            .map(|p| (p.status, p.iterations, p.zncc))
            .collect();
        assert_eq!(
            sm.valid, sm.points,
            "({dx},{dy}) offset {:?} {st:?}",
            res.global_offset_px
        );
        assert!(
            (sm.u.mean - dx).abs() < 0.01 && (sm.v.mean - dy).abs() < 0.01,
            "({dx},{dy}): {sm:?}"
        );
    }
}

#[test]
fn uniform_stretch_is_recovered() {
    let layout = common::layout(W, H, 14);
    let (cx, cy) = (W as f64 / 2.0, H as f64 / 2.0);
    let e = 0.005;
    let stretched = layout.mapped(|x, y| (cx + (1.0 + e) * (x - cx), y), (1.0 + e, 1.0));
    let _ = cy;
    let r = common::render(&layout, W, H);
    let d = common::render(&stretched, W, H);
    let res = analyze(&r, &d, &settings(), None).unwrap();
    let sm = res.summary;
    println!(
        "stretch 0.005: exx {:.7} eyy {:.7} exy {:.7}",
        sm.exx.mean, sm.eyy.mean, sm.exy.mean
    );
    assert_eq!(sm.valid, sm.points);
    assert!((sm.exx.mean - e).abs() <= 2e-5, "exx {}", sm.exx.mean);
    assert!(sm.eyy.mean.abs() <= 2e-5, "eyy {}", sm.eyy.mean);
    assert!(sm.exy.mean.abs() <= 2e-5, "exy {}", sm.exy.mean);
}

#[test]
fn result_does_not_depend_on_thread_count() {
    let (r, d) = shifted_pair(3.37, -1.21, 15);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| analyze(&r, &d, &settings(), None).unwrap())
    };
    let (one, two) = (run(1), run(2));
    for (a, b) in one.points.iter().zip(&two.points) {
        assert_eq!(a.u.to_bits(), b.u.to_bits());
        assert_eq!(a.v.to_bits(), b.v.to_bits());
        assert_eq!(a.iterations, b.iterations);
    }
}

#[test]
fn flat_patch_gets_no_contrast_and_the_run_goes_on() {
    let (mut r, d) = shifted_pair(0.25, 0.0, 16);
    // Blank a 60x60 patch of the reference around (240, 200).
    for y in 170..230 {
        for x in 210..270 {
            r.set(x, y, 200.0);
        }
    }
    let s = DicSettings {
        prefilter_sigma_px: 0.0,
        ..settings()
    };
    let res = analyze(&r, &d, &s, None).unwrap();
    let centre = res
        .points
        .iter()
        .find(|p| p.x == 240.0 && p.y == 200.0)
        .unwrap();
    assert_eq!(centre.status, PoiStatus::NoContrast);
    assert!(centre.u.is_nan());
    assert!(res.summary.valid > res.summary.points / 2);
}

#[test]
fn subset_leaving_the_image_is_flagged() {
    let (r, d) = shifted_pair(30.0, 0.0, 17);
    let s = DicSettings {
        roi: Some(Roi::new(400, 100, 59, 100)),
        ..DicSettings::default()
    };
    let res = analyze(&r, &d, &s, None).unwrap();
    assert!(res.points.iter().any(|p| p.status == PoiStatus::LeftImage));
    assert!(res.points.iter().any(|p| p.status == PoiStatus::Converged));
}
