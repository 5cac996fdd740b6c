//! The imaging model as the mock camera's scene: the mock bench's truth. The bench model (what the
//! mock hardware does) is configured apart from any analysis model, so a comparison can hold a
//! model against a bench that has effects the model lacks.

use crate::dataset::sensor_readout;
use crate::model::{
    render_frame_read_out, Camera, ModelConfig, SensorReadout, SpecklePattern, TargetDot,
    TooManyDots,
};
use ffdic_hw::{HardwareScheme, StagePosition};
use ffdic_mocks::Scene;
use std::sync::Mutex;

pub struct ModelScene {
    pub camera: Camera,
    pub bench: ModelConfig,
    pub dots: Vec<TargetDot>,
    pub seed: u64,
    /// Exposures since this target was mounted, counted per read-out mode (full resolution
    /// first, then each hardware scheme by name): the noise of exposure k is seeded by (seed,
    /// mode, k), not by the camera's lifetime frame count, so an experiment (which mounts its
    /// targets and holds the bench while it captures) gets the same frames whatever was captured
    /// before — dashboard snapshots, earlier runs — and its full-resolution frames are the same
    /// with or without hardware schemes captured between them.
    captures_since_mount: Mutex<Vec<(Option<String>, u64)>>,
}

impl ModelScene {
    /// A scene of `pattern` covering the field of view plus `travel_mm` on every side.
    pub fn new(
        camera: Camera,
        bench: ModelConfig,
        pattern: &SpecklePattern,
        travel_mm: f64,
        seed: u64,
    ) -> Result<Self, TooManyDots> {
        let dots = pattern.dots(camera.field_mm(travel_mm + 2.0), seed)?;
        Ok(Self {
            camera,
            bench,
            dots,
            seed,
            captures_since_mount: Mutex::new(Vec::new()),
        })
    }

    /// Puts a new target in front of the camera: its dots and seed; the noise stream restarts.
    pub fn mount(&mut self, dots: Vec<TargetDot>, seed: u64) {
        self.dots = dots;
        self.seed = seed;
        self.captures_since_mount
            .get_mut()
            .expect("exposure counters")
            .clear();
    }
}

impl Scene for ModelScene {
    fn size(&self) -> (usize, usize) {
        (self.camera.width, self.camera.height)
    }

    fn render(
        &self,
        p: StagePosition,
        _exposure_us: f64,
        bit_depth: u8,
        _frame_index: u64,
        readout: Option<&HardwareScheme>,
    ) -> Vec<u16> {
        let mode = readout.map(|h| h.name.clone());
        let exposure = {
            let mut counts = self.captures_since_mount.lock().expect("exposure counters");
            match counts.iter_mut().find(|(m, _)| *m == mode) {
                Some((_, n)) => {
                    *n += 1;
                    *n - 1
                }
                None => {
                    counts.push((mode.clone(), 1));
                    0
                }
            }
        };
        // Full resolution keeps the stream it always had; each hardware scheme (a camera offers
        // one per geometry) gets its own, numbered by its binning and decimation factors.
        let stream = match readout {
            None => self.seed,
            Some(h) => {
                let ((bx, by), (dx, dy)) = h.settings();
                let geometry =
                    u64::from(bx) | u64::from(by) << 16 | u64::from(dx) << 32 | u64::from(dy) << 48;
                crate::model::derive_seed(self.seed, 0x4B1D, geometry)
            }
        };
        let frame = crate::model::FrameSpec {
            stage_dx_mm: p.x_mm,
            stage_dy_mm: p.y_mm,
            moved: p.x_mm != 0.0 || p.y_mm != 0.0,
            seed: crate::model::derive_seed(stream, 0xCA3E, exposure),
        };
        let readout = readout.map_or_else(SensorReadout::default, sensor_readout);
        let img = render_frame_read_out(
            &self.camera,
            &self.bench.effects,
            &self.dots,
            &frame,
            &readout,
        );
        // The model renders on a 16-bit scale; narrower formats keep the top bits.
        let shift = 16 - bit_depth.min(16) as u32;
        img.data()
            .iter()
            .map(|&v| (v.round().clamp(0.0, 65535.0) as u32 >> shift) as u16)
            .collect()
    }
}
