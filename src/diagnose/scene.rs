//! The model's frames for a dataset: a [`Scene`] holds the nominal experiment, the model's
//! effects and every pattern's dots (laid out once, from a fixed seed) and renders any exposure
//! of the experiment — a [`Shot`] — whole, as a centred crop, or read out in a hardware scheme.

use super::image_stats::STATS_CROP_PX;
use super::nominal::Nominal;
use crate::dataset::Manifest;
use crate::image::Image;
use crate::model::derive_seed;
use crate::model::effects::user::{rendered_fields, UserField};
use crate::model::normal_draws::NormalDraws;
use crate::model::{
    project_prepared, render_frame, render_frame_read_out, Effects, FrameSpec, Placement,
    Remembered, SensorReadout, TargetDot, TooManyDots,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::sync::Arc;

/// One exposure of a pattern: where the stage is commanded, whether it is the moved frame of a
/// pair (the stage's landing, misalignment and the motion effects apply), and the exposure's
/// index since the pattern was mounted, which seeds its noise (a repeat of the reference is
/// another realisation of the same light).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shot {
    pub at_mm: (f64, f64),
    pub moved: bool,
    pub exposure: u64,
}

impl Shot {
    /// The reference frame: the stage at its origin, exposure 0.
    pub const REFERENCE: Shot = Shot::still(0);
    /// The reference's static repeat: exposure 1.
    pub const REPEAT: Shot = Shot::still(1);

    /// The target at the origin, exposure `exposure`.
    pub const fn still(exposure: u64) -> Shot {
        Shot {
            at_mm: (0.0, 0.0),
            moved: false,
            exposure,
        }
    }

    /// The moved frame of a pair at the commanded position `at_mm`, exposure `exposure`.
    pub const fn moved(at_mm: (f64, f64), exposure: u64) -> Shot {
        Shot {
            at_mm,
            moved: true,
            exposure,
        }
    }

    /// Run `run`'s moved frame at `at_mm`: exposure 2 + run, after the reference and its repeat.
    pub const fn of_run(run: usize, at_mm: (f64, f64)) -> Shot {
        Shot::moved(at_mm, 2 + run as u64)
    }
}

/// The largest stage travel of `manifest`'s runs as the nominal stage makes it, mm: the target
/// a scene lays out covers the field of view plus it.
fn travel_mm(nominal: &Nominal, manifest: &Manifest) -> f64 {
    manifest
        .runs
        .iter()
        .map(|r| r.stage.dx_mm.abs().max(r.stage.dy_mm.abs()))
        .fold(0.0, f64::max)
        * nominal.travel_scale.abs().max(1.0)
}

/// Everything a pattern's reference crop is rendered from ([`reference_crop`]).
#[derive(PartialEq)]
struct CropKey {
    nominal: Nominal,
    effects: Effects,
    travel_mm_bits: u64,
    seed: u64,
    pattern: usize,
}

/// The last reference crops rendered, by what they were rendered from: a fit renders the same
/// crop again where its search comes back to a point. Of the 528 crops a round on the
/// paper-size example asks for, 87 are asked again: a print's calibration 39 of its 282 (the
/// crop its contrast was matched on is the one its size search starts from; its last is
/// recorded and its white level matched on), the aperture's fit 48 of its 180 (its simplex's
/// points clamped to the same bound). The last 24 (24 MB of 512x512) hold 71 of them.
static REFERENCE_CROPS: Remembered<CropKey, Result<Arc<Image>, TooManyDots>> = Remembered::new(24);

/// Pattern `pattern`'s centred reference crop ([`STATS_CROP_PX`]) under `nominal`, `effects` and
/// model seed `seed`, as [`Scene::render`] gives it; remembered ([`REFERENCE_CROPS`]).
pub fn reference_crop(
    nominal: &Nominal,
    effects: &Effects,
    manifest: &Manifest,
    seed: u64,
    pattern: usize,
) -> Result<Arc<Image>, TooManyDots> {
    let key = CropKey {
        nominal: nominal.clone(),
        effects: effects.clone(),
        travel_mm_bits: travel_mm(nominal, manifest).to_bits(),
        seed,
        pattern,
    };
    REFERENCE_CROPS.get_or(key, || {
        let scene = Scene::of_patterns(
            nominal,
            effects,
            manifest,
            seed,
            (&|i| i == pattern, Some(STATS_CROP_PX)),
        )?;
        Ok(Arc::new(scene.render(
            pattern,
            Shot::REFERENCE,
            Some(STATS_CROP_PX),
        )))
    })
}

/// The model's frames for a dataset: the nominal experiment, the model's effects, the dots of
/// every pattern (fixed seed).
pub struct Scene {
    pub nominal: Nominal,
    pub effects: Effects,
    /// The model's user effects bound once ([`rendered_fields`]): a geometric displacement
    /// projects each point several times.
    user: Vec<(UserField, Vec<f64>)>,
    dots: Vec<Vec<TargetDot>>,
    seed: u64,
}

impl Scene {
    /// Errs when the target the runs need (field of view plus the largest move) would hold more
    /// dots than a layout may: a manifest's moves are input, and size this allocation.
    pub fn new(
        nominal: &Nominal,
        model: &Effects,
        manifest: &Manifest,
        seed: u64,
    ) -> Result<Self, TooManyDots> {
        Self::of_patterns(nominal, model, manifest, seed, (&|_| true, None))
    }

    /// [`Scene::new`] holding the dots of the patterns `wanted` names only: a print's
    /// calibration renders one pattern some fifty times, and laying out the others each time
    /// was a fifth of a comparison. With `crop` (a centred crop's side, px, for its reference
    /// shot only), a hard-core print is laid out over that crop alone: its sequential
    /// adsorption costs more the nearer the print is to jamming, and over the whole target
    /// (the paper's field plus a 5 mm move: some 76,000 dots of print b) at each of the
    /// calibration's trial sizes and gaps it was 8.7 % of a diagnosis round's profile. The
    /// crop's dots are another realisation of the same print, as every seed's are.
    pub fn of_patterns(
        nominal: &Nominal,
        model: &Effects,
        manifest: &Manifest,
        seed: u64,
        (wanted, crop): (&dyn Fn(usize) -> bool, Option<usize>),
    ) -> Result<Self, TooManyDots> {
        let travel = travel_mm(nominal, manifest);
        let camera = nominal.camera(0);
        let whole = camera.field_mm(travel + 2.0);
        // The crop's field with room for a dot's reach and as much again (the render keeps the
        // dots within 2 mm, their reach and 5 % of the crop of it).
        let crop_camera = crop.map(|side| nominal.crop_camera(0, side));
        let dots = nominal
            .patterns
            .iter()
            .enumerate()
            .map(|(i, p)| {
                if !wanted(i) {
                    return Ok(Vec::new());
                }
                let field = match (&crop_camera, p.pattern.placement) {
                    (Some(c), Placement::HardCore) => {
                        let reach = p.pattern.shape().reach_mm();
                        let (x0, y0, x1, y1) = c.field_mm(2.0 + reach);
                        // Sides of whole spacings: a layout holds one dot per spacing² of
                        // its field rounded up, which on a crop's field would add 1–2 % of dots.
                        let s = p.pattern.dot_spacing_mm;
                        let in_whole_spacings = |lo: f64, hi: f64| {
                            let pad = 0.1 * (hi - lo);
                            let n = ((hi - lo + 2.0 * pad) / s).ceil();
                            // A hair under n spacings, so rounding up gives n.
                            let half = 0.5 * n * s * (1.0 - 1e-9);
                            let mid = 0.5 * (lo + hi);
                            (mid - half, mid + half)
                        };
                        let ((x0, x1), (y0, y1)) =
                            (in_whole_spacings(x0, x1), in_whole_spacings(y0, y1));
                        (x0, y0, x1, y1)
                    }
                    (_, Placement::HardCore | Placement::JitteredGrid | Placement::Poisson) => {
                        whole
                    }
                };
                p.pattern.dots(field, derive_seed(seed, i as u64, 0xD075))
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            nominal: nominal.clone(),
            effects: nominal.render_effects(model),
            user: rendered_fields(&model.user),
            dots,
            seed,
        })
    }

    /// A scene for geometry only (no dots: [`Scene::geometric_displacement`], not rendering).
    pub fn geometry_only(nominal: &Nominal, model: &Effects) -> Self {
        Self {
            nominal: nominal.clone(),
            effects: nominal.render_effects(model),
            user: rendered_fields(&model.user),
            dots: Vec::new(),
            seed: 0,
        }
    }

    /// Renders `shot` of pattern `pattern`; `crop` renders only the centred window of that size.
    pub fn render(&self, pattern: usize, shot: Shot, crop: Option<usize>) -> Image {
        self.render_in(pattern, shot, crop, None)
    }

    /// [`Scene::render`] of the whole frame as the camera reads it out in `readout` (its own
    /// binning or decimation; see [`super::floor_read_out`] for where the noise goes).
    pub fn render_read_out(&self, pattern: usize, shot: Shot, readout: &SensorReadout) -> Image {
        self.render_in(pattern, shot, None, Some(readout))
    }

    fn render_in(
        &self,
        pattern: usize,
        shot: Shot,
        crop: Option<usize>,
        readout: Option<&SensorReadout>,
    ) -> Image {
        let Shot {
            at_mm: (dx_mm, dy_mm),
            moved,
            exposure: frame,
        } = shot;
        let n = &self.nominal;
        let mut camera = n.camera(pattern);
        let mut effects = self.effects.clone();
        if let Some(side) = crop {
            let full_r0 = camera.half_diagonal_px();
            camera = n.crop_camera(pattern, side);
            let crop_r0 = camera.half_diagonal_px();
            if let Some(d) = effects.lens_distortion.as_mut() {
                if d.norm_radius_px <= 0.0 {
                    d.norm_radius_px = full_r0;
                }
            }
            if let Some(v) = effects.vignetting.as_mut() {
                v.v *= (crop_r0 / full_r0).powi(2);
            }
        }
        let (sx, sy) = n.scaled_move(dx_mm, dy_mm);
        let seed = derive_seed(self.seed, 0xF7A3 + pattern as u64, frame);
        let spec = FrameSpec {
            stage_dx_mm: sx,
            stage_dy_mm: sy,
            moved,
            seed,
        };
        let all = &self.dots[pattern];
        // A crop sees a small part of the target: hand the renderer only the dots near it (in mm,
        // with room for the move, the dots' reach and a generous allowance for distortion).
        let near: Vec<TargetDot>;
        let dots: &[TargetDot] = if crop.is_some() {
            let reach = all.iter().map(|d| d.shape.reach_mm()).fold(0.0, f64::max);
            let (x0, y0, x1, y1) = camera.field_mm(2.0 + reach);
            let (pad_x, pad_y) = (0.05 * (x1 - x0), 0.05 * (y1 - y0));
            let (mx, my) = (sx, sy);
            near = all
                .iter()
                .filter(|d| {
                    let (x, y) = (d.x_mm + mx, d.y_mm + my);
                    x > x0 - pad_x && x < x1 + pad_x && y > y0 - pad_y && y < y1 + pad_y
                })
                .copied()
                .collect();
            &near
        } else {
            all
        };
        let readout = readout.filter(|r| !r.is_full_resolution());
        if effects.sensor_noise.is_some() || n.noise_floor_dn <= 0.0 {
            return match readout {
                Some(r) => render_frame_read_out(&camera, &effects, dots, &spec, r),
                None => render_frame(&camera, &effects, dots, &spec),
            };
        }
        // The dataset's own sensor: signal-independent noise, then the ADC.
        let full = effects.quantization.take().map_or(65535.0, |q| q.max_dn());
        camera.exposure_level *= n.full_scale_dn() / 65535.0;
        let mut img = render_frame(&camera, &effects, dots, &spec);
        let sigma = n.noise_floor_dn;
        if let Some(r) = readout {
            return super::floor_read_out::read_out_with_floor(&img, r, sigma, full, seed);
        }
        let w = img.width();
        img.data_mut()
            .par_chunks_mut(w)
            .enumerate()
            .for_each(|(row, line)| {
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("sse4.1") {
                    // SAFETY: the CPU has SSE4.1, just checked.
                    unsafe { floor_noise_row_sse41(line, seed, row, sigma, full) };
                    return;
                }
                floor_noise_row(line, seed, row, sigma, full);
            });
        img
    }

    /// The model's geometric displacement (full-resolution px) at a reference-image position for
    /// a commanded move: the target point seen at `p` in the reference, projected in the moved
    /// frame. Exact for every geometric effect of the model (no rendering, no DIC).
    pub fn geometric_displacement(&self, (dx_mm, dy_mm): (f64, f64), p: (f64, f64)) -> (f64, f64) {
        let camera = self.nominal.camera(0);
        let (sx, sy) = self.nominal.scaled_move(dx_mm, dy_mm);
        let reference = FrameSpec {
            stage_dx_mm: 0.0,
            stage_dy_mm: 0.0,
            moved: false,
            seed: 0,
        };
        let moved = FrameSpec {
            stage_dx_mm: sx,
            stage_dy_mm: sy,
            moved: true,
            seed: 0,
        };
        let (cx, cy) = camera.centre();
        let s = camera.scale_px_per_mm;
        // Invert the reference projection by fixed-point iteration (distortion is small).
        let (mut x, mut y) = ((p.0 - cx) / s, (p.1 - cy) / s);
        for _ in 0..6 {
            let (qx, qy, _) =
                project_prepared(&camera, &self.effects, &self.user, &reference, x, y);
            x += (p.0 - qx) / s;
            y += (p.1 - qy) / s;
        }
        let (qx, qy, _) = project_prepared(&camera, &self.effects, &self.user, &moved, x, y);
        (qx - p.0, qy - p.1)
    }
}

/// One row of a frame read out by the dataset's own sensor: signal-independent noise of σ
/// `sigma` DN (its stream seeded by `seed` and the row), then the ADC's rounding and clipping
/// to 0..=`full`.
#[inline(always)]
fn floor_noise_row(line: &mut [f32], seed: u64, row: usize, sigma: f64, full: f64) {
    let mut noise = NormalDraws::new(ChaCha8Rng::seed_from_u64(
        seed ^ (row as u64 + 1).wrapping_mul(0xA24B_AED4_963E_E407),
    ));
    for v in line.iter_mut() {
        let x = *v as f64 + sigma * noise.standard();
        *v = x.round().clamp(0.0, full) as f32;
    }
}

/// [`floor_noise_row`] compiled for SSE4.1, whose rounding instruction makes the ADC's `round` a
/// few instructions where x86-64's baseline calls `compiler_builtins`' software `round` (2.7 %
/// of a paper-size round's profile, as the sensor's row was before `render::sense_row_sse41`).
/// `round` is exact either way: the row is the same to the bit (a test below compares them).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "sse4.1")]
fn floor_noise_row_sse41(line: &mut [f32], seed: u64, row: usize, sigma: f64, full: f64) {
    floor_noise_row(line, seed, row, sigma, full);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::nominal::PatternEstimate;
    use crate::diagnose::print::PrintKnowledge;
    use crate::diagnose::stage_landing::StageLanding;
    use crate::diagnose::test_fields::{manifest, PrintStated};
    use crate::model::SpecklePattern;

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_floor_noise_row_is_the_same_to_the_bit_with_sse41() {
        if !std::arch::is_x86_feature_detected!("sse4.1") {
            return;
        }
        // Levels across the ADC's range and beyond both ends, with halves where rounding ties
        // would show a difference, under noise of 50 DN.
        let levels: Vec<f32> = (0..4096)
            .map(|i| -300.0 + i as f32 * 16.5 + if i % 3 == 0 { 0.5 } else { 0.0 })
            .collect();
        let full = 65535.0;
        for row in 0..64 {
            let (mut baseline, mut sse41) = (levels.clone(), levels.clone());
            floor_noise_row(&mut baseline, 0x5EED, row, 50.0, full);
            // SAFETY: the CPU has SSE4.1, checked above.
            unsafe { floor_noise_row_sse41(&mut sse41, 0x5EED, row, 50.0, full) };
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&baseline), bits(&sse41), "row {row}");
            assert!(baseline.contains(&65535.0) && baseline.contains(&0.0));
        }
    }

    /// The paper's print a on a 256x256 sensor at 26 px/mm, white at 30,000 DN, a noise floor of
    /// 50 DN.
    fn scene() -> Scene {
        let nominal = Nominal {
            width: 256,
            height: 256,
            bit_depth: 16,
            scale_px_per_mm: 26.0,
            noise_floor_dn: 50.0,
            misalignment_rad: 0.0,
            travel_scale: 1.0,
            stage: StageLanding::default(),
            patterns: vec![PatternEstimate {
                pattern: SpecklePattern::preset("a").unwrap(),
                white_level_dn: 30_000.0,
                source: "test".into(),
                print: PrintKnowledge::Characterised,
                calibration: None,
                placement_stated: true,
                placement_chi2: None,
                profile_stated: true,
                profile_chi2: None,
            }],
        };
        let m = manifest(
            &[(1.0, 0.0), (2.0, 0.0)],
            &["a"],
            PrintStated::Characterised,
        );
        Scene::new(&nominal, &Effects::default(), &m, 7).unwrap()
    }

    #[test]
    fn a_repeat_is_the_same_light_with_other_noise() {
        let s = scene();
        let (a, b) = (
            s.render(0, Shot::REFERENCE, None),
            s.render(0, Shot::REPEAT, None),
        );
        // The difference of two exposures of one scene is noise alone: var = 2σ².
        let diff: Vec<f64> = a
            .data()
            .iter()
            .zip(b.data())
            .map(|(x, y)| (x - y) as f64)
            .collect();
        let n = diff.len() as f64;
        let mean = diff.iter().sum::<f64>() / n;
        let var = diff.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / n;
        assert!((var / (2.0 * 50f64.powi(2)) - 1.0).abs() < 0.05, "{var}");
        // The same exposure twice is the same frame.
        assert_eq!(s.render(0, Shot::REFERENCE, None).data(), a.data());
        // Each run's moved frame has its own exposure, after the reference and its repeat.
        let exposures: Vec<u64> = (0..50)
            .map(|r| Shot::of_run(r, (0.0, 0.0)).exposure)
            .collect();
        assert!(exposures.iter().all(|e| *e >= 2));
        assert!(exposures.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn a_moved_shot_moves_the_print_by_the_commanded_step() {
        // 1/26 mm is one pixel: the moved frame is the reference shifted one column, away from
        // the borders (no new dots come in there) and noise apart.
        let s = scene();
        let a = s.render(0, Shot::still(5), None);
        let b = s.render(0, Shot::moved((1.0 / 26.0, 0.0), 5), None);
        let (mut sq, mut k) = (0.0, 0.0);
        for r in 20..236 {
            for c in 20..236 {
                sq += (b.get(c + 1, r) as f64 - a.get(c, r) as f64).powi(2);
                k += 1.0;
            }
        }
        // Same exposure index, so same noise draw per pixel; the shifted comparison leaves the
        // noise of two pixels (2σ²) and nothing of the print's contrast (thousands of DN).
        assert!(sq / k < 3.0 * 50f64.powi(2), "{}", sq / k);
    }
}
