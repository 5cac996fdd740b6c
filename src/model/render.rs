//! Renders the frame a camera on the bench would deliver: scene → geometry → optics → sensor.
//!
//! Geometry maps every dot centre (stage move with its misalignment; for moved frames rotation
//! and scale; lens distortion) and its size (scale px/mm, magnification, PSF added in quadrature);
//! the sensor integrates each dot exactly over its pixels' apertures; radiometry and the sensor
//! chain (vignetting, illumination change, PRNU/DSNU, shot and read noise, ADC) act per pixel.
//! Distortion moves dot centres and leaves their shape to the local similarity transform: the
//! shape change it would add is of order k1·(dot size), far below anything DIC resolves.

use super::effects::Effects;
use super::pattern::TargetDot;
use super::speckle::{render_dots, GaussianDot};
use crate::image::Image;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, Poisson};
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
    let (cx, cy) = camera.centre();
    let s = camera.scale_px_per_mm * mag;
    let (px, py) = (cx + s * x, cy + s * y);
    match effects.lens_distortion {
        Some(d) => d.distort(px, py, (cx, cy), camera.half_diagonal_px()),
        None => (px, py),
    }
}

/// Renders one frame in DN (float; the ADC rounds when `quantization` is on).
pub fn render_frame(
    camera: &Camera,
    effects: &Effects,
    dots: &[TargetDot],
    frame: &FrameSpec,
) -> Image {
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
    let margin = 6.0 * dots.iter().map(|d| d.sigma_mm).fold(0.0, f64::max) * camera.scale_px_per_mm
        + psf * 6.0
        + 2.0;
    let px_dots: Vec<GaussianDot> = dots
        .iter()
        .filter_map(|d| {
            let (x, y) = project(camera, effects, frame, d.x_mm, d.y_mm);
            let inside = x > -margin - 60.0
                && y > -margin - 60.0
                && x < w as f64 + margin + 60.0
                && y < h as f64 + margin + 60.0;
            inside.then(|| {
                let sigma =
                    ((d.sigma_mm * camera.scale_px_per_mm * mag).powi(2) + psf * psf).sqrt();
                GaussianDot {
                    x_px: x,
                    y_px: y,
                    sigma_x_px: sigma,
                    sigma_y_px: sigma,
                    depth: d.depth * background,
                }
            })
        })
        .collect();

    let mut image = match effects
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
                let shifted: Vec<GaussianDot> = px_dots
                    .iter()
                    .map(|d| GaussianDot {
                        x_px: d.x_px - t * c,
                        y_px: d.y_px - t * s,
                        ..*d
                    })
                    .collect();
                let img = render_dots(w, h, &shifted, background, aperture);
                for (a, v) in acc.iter_mut().zip(img.data()) {
                    *a += v / k as f32;
                }
            }
            Image::from_vec(w, h, acc).expect("sized")
        }
        None => render_dots(w, h, &px_dots, background, aperture),
    };
    apply_sensor(camera, effects, frame, &mut image, full_scale);
    image
}

/// Radiometry and the sensor chain, per pixel, rows in parallel with per-row seeds so the
/// result does not depend on the thread count.
fn apply_sensor(
    camera: &Camera,
    effects: &Effects,
    frame: &FrameSpec,
    image: &mut Image,
    full_scale: f64,
) {
    let w = camera.width;
    let (cx, cy) = camera.centre();
    let r0 = camera.half_diagonal_px();
    let illum = effects.illumination_change.filter(|_| frame.moved);
    image
        .data_mut()
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(row, line)| {
            let mut rng = ChaCha8Rng::seed_from_u64(
                frame.seed ^ (row as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            let mut fpn = ChaCha8Rng::seed_from_u64(
                SENSOR_SEED ^ (row as u64).wrapping_mul(0xD1B5_4A32_D192_ED03),
            );
            let std_normal = Normal::new(0.0, 1.0).expect("valid");
            for (col, px) in line.iter_mut().enumerate() {
                // Irradiance cannot be negative where dots overlap.
                let mut v = (*px as f64).max(0.0);
                if let Some(vg) = effects.vignetting {
                    let r2 = ((col as f64 - cx).powi(2) + (row as f64 - cy).powi(2)) / (r0 * r0);
                    v *= 1.0 - vg.v * r2;
                }
                if let Some(ic) = illum {
                    v = ic.gain * v + ic.offset;
                }
                if let Some(fp) = effects.fixed_pattern {
                    let (a, b): (f64, f64) =
                        (std_normal.sample(&mut fpn), std_normal.sample(&mut fpn));
                    v = v * (1.0 + fp.prnu * a) + fp.dsnu * b;
                }
                if let Some(n) = effects.sensor_noise {
                    let electrons = (v * n.gain).clamp(0.0, n.full_well_e);
                    let shot = if electrons > 0.0 {
                        Poisson::new(electrons).map_or(electrons, |p| p.sample(&mut rng))
                    } else {
                        0.0
                    };
                    let read: f64 = n.read_noise_e * std_normal.sample(&mut rng);
                    v = (shot + read) / n.gain;
                }
                if effects.quantization.is_some() {
                    v = v.round().clamp(0.0, full_scale);
                }
                *px = v as f32;
            }
        });
}
