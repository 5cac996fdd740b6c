//! Renders the frame a camera on the bench would deliver: scene → geometry → optics → sensor.
//!
//! Geometry maps every dot centre (stage move with its misalignment; for moved frames rotation
//! and scale; the target's tilt through a pinhole; lens distortion) and its size (scale px/mm,
//! magnification, depth, PSF added in quadrature);
//! the sensor integrates each dot exactly over its pixels' apertures; radiometry and the sensor
//! chain (vignetting, a user's intensity effects, illumination change, PRNU/DSNU, shot and read
//! noise, ADC) act per pixel.
//! Distortion moves dot centres and leaves their shape to the local similarity transform: the
//! shape change it would add is of order k1·(dot size), far below anything DIC resolves.

use super::disk::DiskDot;
use super::effects::user::{rendered_fields, UserField, UserKind};
use super::effects::Effects;
use super::pattern::{DotShape, TargetDot};
use super::readout::{SensorChain, SensorReadout};
use super::speckle::{render_dots_until, Dot, Footprint, GaussianDot};
use crate::image::Image;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The camera looking at the target: size, scale, exposure, principal point (by default the
/// image centre ((w-1)/2, (h-1)/2)).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    pub width: usize,
    pub height: usize,
    pub scale_px_per_mm: f64,
    /// White-background level as a fraction of the ADC's full scale.
    #[serde(default = "default_exposure_level")]
    pub exposure_level: f64,
    /// Principal point (where the optical axis meets the sensor) relative to the image centre, px.
    #[serde(default)]
    pub principal_dx_px: f64,
    #[serde(default)]
    pub principal_dy_px: f64,
}

fn default_exposure_level() -> f64 {
    0.5
}

impl Camera {
    pub fn centre(&self) -> (f64, f64) {
        (
            (self.width as f64 - 1.0) / 2.0,
            (self.height as f64 - 1.0) / 2.0,
        )
    }

    pub fn half_diagonal_px(&self) -> f64 {
        0.5 * ((self.width as f64).powi(2) + (self.height as f64).powi(2)).sqrt()
    }

    /// The target area seen at the reference position plus `margin_mm` on every side, mm
    /// relative to the optical axis.
    pub fn field_mm(&self, margin_mm: f64) -> (f64, f64, f64, f64) {
        let hw = self.width as f64 / 2.0 / self.scale_px_per_mm + margin_mm;
        let hh = self.height as f64 / 2.0 / self.scale_px_per_mm + margin_mm;
        (-hw, -hh, hw, hh)
    }
}

/// One frame to render: where the stage was commanded, and the noise seed of this exposure.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameSpec {
    pub stage_dx_mm: f64,
    pub stage_dy_mm: f64,
    /// Effects acting between frames (rotation, scale, illumination change, motion blur) apply
    /// to moved frames only.
    pub moved: bool,
    pub seed: u64,
}

/// Seed of the sensor's fixed pattern: the same sensor in every frame.
const SENSOR_SEED: u64 = 0x5E75_0125;

/// Ideal image position (px) of a target point (mm, relative to the optical axis) for a frame.
pub fn project(
    camera: &Camera,
    effects: &Effects,
    frame: &FrameSpec,
    x_mm: f64,
    y_mm: f64,
) -> (f64, f64) {
    let (x, y, _) = project_with_depth(camera, effects, frame, x_mm, y_mm);
    (x, y)
}

/// [`project`], and the point's magnification from its depth relative to the axis's (1 without a
/// tilt; ≤ 0 for a point at or behind the camera's plane, which no camera sees).
pub fn project_with_depth(
    camera: &Camera,
    effects: &Effects,
    frame: &FrameSpec,
    x_mm: f64,
    y_mm: f64,
) -> (f64, f64, f64) {
    let user = rendered_fields(&effects.user);
    project_prepared(camera, effects, &user, frame, x_mm, y_mm)
}

/// [`project_with_depth`] with the model's user effects bound once (`user`, from
/// [`rendered_fields`]): a user effect's field is a function of where the point is seen in the
/// reference frame (rendered at the stage's origin) and of the move, added to moved frames.
pub fn project_prepared(
    camera: &Camera,
    effects: &Effects,
    user: &[(UserField, Vec<f64>)],
    frame: &FrameSpec,
    x_mm: f64,
    y_mm: f64,
) -> (f64, f64, f64) {
    let (mx, my) = match effects.stage_misalignment {
        Some(m) => m.actual_move(frame.stage_dx_mm, frame.stage_dy_mm),
        None => (frame.stage_dx_mm, frame.stage_dy_mm),
    };
    let (mut x, mut y) = (x_mm + mx, y_mm + my);
    let mut mag = 1.0;
    if frame.moved {
        if let Some(r) = effects.rotation {
            (x, y) = r.apply(x, y);
        }
        if let Some(s) = effects.scale {
            mag += s.ds;
        }
    }
    let mut depth = 1.0;
    if let Some(t) = effects.target_tilt {
        (x, y, depth) = t.apply(x * mag, y * mag);
        mag = 1.0;
    }
    let (cx, cy) = camera.centre();
    let s = camera.scale_px_per_mm * mag;
    let (px, py) = (cx + s * x, cy + s * y);
    let (mut px, mut py) = match effects.lens_distortion {
        Some(d) => d.distort(px, py, (cx, cy), camera.half_diagonal_px()),
        None => (px, py),
    };
    if frame.moved && !user.is_empty() {
        let reference = FrameSpec {
            stage_dx_mm: 0.0,
            stage_dy_mm: 0.0,
            moved: false,
            ..*frame
        };
        let (rx, ry, _) = project_prepared(camera, effects, &[], &reference, x_mm, y_mm);
        let k = camera.scale_px_per_mm;
        for (field, values) in user {
            let (u, v) = field.displacement((rx - cx, ry - cy), (k * mx, k * my), values);
            px += u;
            py += v;
        }
    }
    (px, py, depth)
}

/// Renders one frame in DN (float; the ADC rounds when `quantization` is on).
pub fn render_frame(
    camera: &Camera,
    effects: &Effects,
    dots: &[TargetDot],
    frame: &FrameSpec,
) -> Image {
    render_frame_until(camera, effects, dots, frame, &|| false).expect("never asked to stop")
}

/// [`render_frame`], asking `stop` as it goes (before each band of rows and each step of the
/// chain): `None` once it said so.
pub fn render_frame_until(
    camera: &Camera,
    effects: &Effects,
    dots: &[TargetDot],
    frame: &FrameSpec,
    stop: &(dyn Fn() -> bool + Sync),
) -> Option<Image> {
    let mut image = render_irradiance(camera, effects, dots, frame, stop)?;
    apply_sensor(camera, effects, frame, &mut image, stop);
    (!stop()).then_some(image)
}

/// The optical image on the sensor, DN per pixel (each pixel's aperture integrated exactly),
/// before radiometry and noise.
fn render_irradiance(
    camera: &Camera,
    effects: &Effects,
    dots: &[TargetDot],
    frame: &FrameSpec,
    stop: &(dyn Fn() -> bool + Sync),
) -> Option<Image> {
    let full_scale = effects.quantization.map_or(65535.0, |q| q.max_dn());
    let background = camera.exposure_level * full_scale;
    let mag = if frame.moved {
        1.0 + effects.scale.map_or(0.0, |s| s.ds)
    } else {
        1.0
    };
    let psf = effects.psf_blur.map_or(0.0, |p| p.sigma_px);
    let aperture = effects.fill_factor.map_or((1.0, 1.0), |f| (f.fx, f.fy));
    let (w, h) = (camera.width, camera.height);
    let margin = dots.iter().map(|d| d.shape.reach_mm()).fold(0.0, f64::max)
        * camera.scale_px_per_mm
        + psf * 6.0
        + 2.0;
    let user = rendered_fields(&effects.user);
    let px_dots: Vec<ImagedDot> = dots
        .iter()
        .filter_map(|d| {
            let (x, y, depth) = project_prepared(camera, effects, &user, frame, d.x_mm, d.y_mm);
            // A tilted target's dots shrink with their depth (isotropically here: the
            // anisotropy is of the order of the angle times the dot size over the distance);
            // one at or behind the camera's plane is not seen.
            if !(depth > 0.0) {
                return None;
            }
            let inside = x > -margin - 60.0
                && y > -margin - 60.0
                && x < w as f64 + margin + 60.0
                && y < h as f64 + margin + 60.0;
            let px_per_mm = camera.scale_px_per_mm * mag * depth;
            inside.then(|| ImagedDot::of(d, (x, y), px_per_mm, psf, background))
        })
        .collect();

    match effects
        .motion_blur
        .filter(|m| frame.moved && m.length_px > 0.0)
    {
        // The mean over the exposure path, by quadrature at ≥2 positions per px of path.
        Some(m) => {
            let k = ((2.0 * m.length_px).ceil() as usize + 1).max(2);
            let (s, c) = m.angle_rad.sin_cos();
            let mut acc = vec![0.0f32; w * h];
            for i in 0..k {
                let t = (i as f64 / (k - 1) as f64 - 0.5) * m.length_px;
                let shifted: Vec<ImagedDot> =
                    px_dots.iter().map(|d| d.shifted(-t * c, -t * s)).collect();
                let img = render_dots_until(w, h, &shifted, background, aperture, stop)?;
                for (a, v) in acc.iter_mut().zip(img.data()) {
                    *a += v / k as f32;
                }
            }
            Some(Image::from_vec(w, h, acc).expect("sized"))
        }
        None => render_dots_until(w, h, &px_dots, background, aperture, stop),
    }
}

/// A target dot as the sensor sees it, px.
#[derive(Clone, Copy, Debug)]
enum ImagedDot {
    Gaussian(GaussianDot),
    Disk(DiskDot),
}

impl ImagedDot {
    /// Dot `d` imaged at (x, y) px with `px_per_mm` of magnification and a Gaussian lens blur of
    /// σ `psf` px, on a background of `background` DN.
    fn of(d: &TargetDot, (x, y): (f64, f64), px_per_mm: f64, psf: f64, background: f64) -> Self {
        match d.shape {
            DotShape::Gaussian { sigma_mm } => {
                let sigma_print = sigma_mm * px_per_mm;
                let sigma = sigma_print.hypot(psf);
                // The lens spreads a dot's darkening, it does not add to it: the convolution
                // keeps the dot's volume depth·2πσ², so the depth falls as σ² grows.
                let spread = if sigma > 0.0 {
                    (sigma_print / sigma).powi(2)
                } else {
                    1.0
                };
                ImagedDot::Gaussian(GaussianDot {
                    x_px: x,
                    y_px: y,
                    sigma_x_px: sigma,
                    sigma_y_px: sigma,
                    depth: d.depth * background * spread,
                })
            }
            // A disk keeps its depth under blur: the blur is normalised, and spreads the edge.
            DotShape::Disk { radius_mm, blur_mm } => {
                let blur = (blur_mm * px_per_mm).hypot(psf);
                ImagedDot::Disk(DiskDot {
                    x_px: x,
                    y_px: y,
                    radius_x_px: radius_mm * px_per_mm,
                    radius_y_px: radius_mm * px_per_mm,
                    blur_x_px: blur,
                    blur_y_px: blur,
                    depth: d.depth * background,
                })
            }
        }
    }

    fn shifted(&self, dx: f64, dy: f64) -> Self {
        match *self {
            ImagedDot::Gaussian(g) => ImagedDot::Gaussian(GaussianDot {
                x_px: g.x_px + dx,
                y_px: g.y_px + dy,
                ..g
            }),
            ImagedDot::Disk(k) => ImagedDot::Disk(DiskDot {
                x_px: k.x_px + dx,
                y_px: k.y_px + dy,
                ..k
            }),
        }
    }
}

impl Dot for ImagedDot {
    fn x_px(&self) -> f64 {
        match self {
            ImagedDot::Gaussian(g) => g.x_px,
            ImagedDot::Disk(k) => k.x_px,
        }
    }

    fn y_px(&self) -> f64 {
        match self {
            ImagedDot::Gaussian(g) => g.y_px,
            ImagedDot::Disk(k) => k.y_px,
        }
    }

    fn reach_px(&self, aperture: (f64, f64)) -> (f64, f64) {
        match self {
            ImagedDot::Gaussian(g) => g.reach_px(aperture),
            ImagedDot::Disk(k) => k.reach_px(aperture),
        }
    }

    fn footprint(&self, size: (usize, usize), aperture: (f64, f64)) -> Option<Footprint> {
        match self {
            ImagedDot::Gaussian(g) => g.footprint(size, aperture),
            ImagedDot::Disk(k) => k.footprint(size, aperture),
        }
    }
}

/// Radiometry per pixel (vignetting, illumination change, PRNU/DSNU): the irradiance in DN
/// before the sensor's noise.
struct Radiometry<'a> {
    effects: &'a Effects,
    centre: (f64, f64),
    r0: f64,
    illumination: Option<super::effects::IlluminationChange>,
    /// The model's user intensity effects on a moved frame, bound and valued, and the move they
    /// read (px, as the camera sees it).
    user_intensity: Vec<(UserField, Vec<f64>)>,
    move_px: (f64, f64),
}

impl<'a> Radiometry<'a> {
    fn new(camera: &Camera, effects: &'a Effects, frame: &FrameSpec) -> Self {
        let user_intensity = if frame.moved {
            rendered_fields(&effects.user)
                .into_iter()
                .filter(|(f, _)| f.kind() == UserKind::Intensity)
                .collect()
        } else {
            Vec::new()
        };
        let (mx, my) = match effects.stage_misalignment {
            Some(m) => m.actual_move(frame.stage_dx_mm, frame.stage_dy_mm),
            None => (frame.stage_dx_mm, frame.stage_dy_mm),
        };
        let k = camera.scale_px_per_mm;
        Self {
            effects,
            centre: camera.centre(),
            r0: camera.half_diagonal_px(),
            illumination: effects.illumination_change.filter(|_| frame.moved),
            user_intensity,
            move_px: (k * mx, k * my),
        }
    }

    /// The fixed-pattern noise of one sensor row: the same sensor in every frame.
    fn fixed_pattern_rng(row: usize) -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(SENSOR_SEED ^ (row as u64).wrapping_mul(0xD1B5_4A32_D192_ED03))
    }

    /// Pixel (`col`, `row`) of irradiance `px`; `fpn` is its row's fixed-pattern stream, read
    /// left to right.
    #[inline]
    fn pixel(&self, col: usize, row: usize, px: f32, fpn: &mut ChaCha8Rng) -> f64 {
        // Irradiance cannot be negative where dots overlap.
        let mut v = (px as f64).max(0.0);
        if let Some(vg) = self.effects.vignetting {
            let (cx, cy) = self.centre;
            let r2 = ((col as f64 - cx).powi(2) + (row as f64 - cy).powi(2)) / (self.r0 * self.r0);
            v *= 1.0 - vg.v * r2;
        }
        if !self.user_intensity.is_empty() {
            let p = (col as f64 - self.centre.0, row as f64 - self.centre.1);
            let change: f64 = self
                .user_intensity
                .iter()
                .map(|(f, values)| f.relative_intensity(p, self.move_px, values))
                .sum();
            v *= 1.0 + change;
        }
        if let Some(ic) = self.illumination {
            v = ic.gain * v + ic.offset;
        }
        if let Some(fp) = self.effects.fixed_pattern {
            let std_normal = Normal::new(0.0, 1.0).expect("valid");
            let (a, b): (f64, f64) = (std_normal.sample(fpn), std_normal.sample(fpn));
            v = v * (1.0 + fp.prnu * a) + fp.dsnu * b;
        }
        v
    }
}

/// Radiometry and the sensor chain, per pixel at full resolution, rows in parallel with per-row
/// seeds so the result does not depend on the thread count.
/// Radiometry, noise and the ADC on every pixel; rows left as they are once `stop` says so (the
/// caller then discards the frame). Per-row seeds: the rows are the same whatever the threads.
fn apply_sensor(
    camera: &Camera,
    effects: &Effects,
    frame: &FrameSpec,
    image: &mut Image,
    stop: &(dyn Fn() -> bool + Sync),
) {
    let radiometry = Radiometry::new(camera, effects, frame);
    let chain = SensorChain::new(effects);
    image
        .data_mut()
        .par_chunks_mut(camera.width)
        .enumerate()
        .for_each(|(row, line)| {
            if stop() {
                return;
            }
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("sse4.1") {
                // SAFETY: the CPU has SSE4.1, just checked.
                unsafe { sense_row_sse41(&radiometry, &chain, frame.seed, row, line) };
                return;
            }
            sense_row(&radiometry, &chain, frame.seed, row, line);
        });
}

/// One row of irradiance through radiometry, the sensor's noise (its stream seeded by `seed` and
/// the row) and the ADC.
#[inline(always)]
fn sense_row(
    radiometry: &Radiometry,
    chain: &SensorChain,
    seed: u64,
    row: usize,
    line: &mut [f32],
) {
    let mut rng = SensorChain::row_noise(seed, row);
    let mut fpn = Radiometry::fixed_pattern_rng(row);
    for (col, px) in line.iter_mut().enumerate() {
        let v = radiometry.pixel(col, row, *px, &mut fpn);
        *px = chain.quantise(chain.read_pixel(v, &mut rng)) as f32;
    }
}

/// [`sense_row`] compiled for SSE4.1, whose rounding instruction makes the ADC's `round` and
/// the Poisson sampler's `floor` a few instructions where x86-64's baseline calls a software
/// rounding (`compiler_builtins`' `round` and `floor` were 3.1 % and 1.3 % of a diagnosis
/// round's profile). Both round exactly either way: the frame is the same to the bit (a test
/// below compares the two rows).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "sse4.1")]
fn sense_row_sse41(
    radiometry: &Radiometry,
    chain: &SensorChain,
    seed: u64,
    row: usize,
    line: &mut [f32],
) {
    sense_row(radiometry, chain, seed, row, line);
}

/// Renders one frame as the sensor reads it out in `readout` (hardware binning or decimation):
/// the same scene, optics and radiometry as [`render_frame`], then the noise and the ADC per
/// output pixel as `readout` combines the sensor's pixels.
pub fn render_frame_read_out(
    camera: &Camera,
    effects: &Effects,
    dots: &[TargetDot],
    frame: &FrameSpec,
    readout: &SensorReadout,
) -> Image {
    if readout.is_full_resolution() {
        return render_frame(camera, effects, dots, frame);
    }
    let image =
        render_irradiance(camera, effects, dots, frame, &|| false).expect("never asked to stop");
    let radiometry = Radiometry::new(camera, effects, frame);
    let w = camera.width;
    let mut irradiance = vec![0.0f64; image.data().len()];
    irradiance
        .par_chunks_mut(w)
        .zip(image.data().par_chunks(w))
        .enumerate()
        .for_each(|(row, (out, line))| {
            let mut fpn = Radiometry::fixed_pattern_rng(row);
            for (col, (o, &px)) in out.iter_mut().zip(line).enumerate() {
                *o = radiometry.pixel(col, row, px, &mut fpn);
            }
        });
    readout.read(
        &irradiance,
        (w, camera.height),
        &SensorChain::new(effects),
        frame.seed,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::effects::{FixedPattern, Quantization, SensorNoise, Vignetting};

    /// The row compiled for SSE4.1 reads out the same bits as the baseline's, over irradiances
    /// from the dark (the Poisson sampler's inversion below a mean of 10 electrons) through PTRS
    /// and the Cornish–Fisher draw (from 100 electrons) to the clipped full well, with every
    /// per-pixel effect of the chain on.
    #[test]
    fn the_sse41_row_reads_out_the_same_bits() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("sse4.1") {
            let camera = Camera {
                width: 4096,
                height: 3,
                scale_px_per_mm: 20.0,
                exposure_level: 0.5,
                principal_dx_px: 0.0,
                principal_dy_px: 0.0,
            };
            let effects = Effects {
                sensor_noise: Some(SensorNoise {
                    full_well_e: 30_000.0,
                    read_noise_e: 3.5,
                    gain: 0.4,
                }),
                quantization: Some(Quantization { bits: 16 }),
                fixed_pattern: Some(FixedPattern {
                    prnu: 0.01,
                    dsnu: 2.0,
                }),
                vignetting: Some(Vignetting { v: 0.2 }),
                ..Effects::default()
            };
            let frame = FrameSpec {
                stage_dx_mm: 0.0,
                stage_dy_mm: 0.0,
                moved: false,
                seed: 97,
            };
            let radiometry = Radiometry::new(&camera, &effects, &frame);
            let chain = SensorChain::new(&effects);
            let irradiance: Vec<f32> = (0..camera.width)
                .map(|c| (c as f32 * 0.37).powf(1.6) - 5.0)
                .collect();
            for row in 0..camera.height {
                let mut baseline = irradiance.clone();
                let mut sse41 = irradiance.clone();
                sense_row(&radiometry, &chain, frame.seed, row, &mut baseline);
                // SAFETY: the CPU has SSE4.1, checked above.
                unsafe { sense_row_sse41(&radiometry, &chain, frame.seed, row, &mut sse41) };
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&baseline), bits(&sse41), "row {row}");
                assert!(baseline.contains(&65535.0) && baseline.contains(&0.0));
            }
        }
    }
}
