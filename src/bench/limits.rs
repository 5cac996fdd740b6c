//! What the bench can physically do, as the door checks it: an experiment request that asks for
//! more is refused with the field named before a job exists, instead of failing on the bench
//! after capturing — or, worse, sizing an allocation from a number nobody checked.

use crate::model::SpecklePattern;

/// The physical and configured limits a request is held against. The service builds it once at
/// start from the configuration and the bench's own description (stage travel).
#[derive(Clone, Debug, PartialEq)]
pub struct BenchLimits {
    /// Image px per mm on the target: turns the print's mm into what the camera resolves.
    pub scale_px_per_mm: f64,
    /// The area a changeable target must cover (mm, the mock bench's field of view plus its
    /// travel); `None` on a bench whose target is mounted by hand.
    pub target_field_mm: Option<(f64, f64, f64, f64)>,
    /// The stage's travel per axis relative to the reference (home) position, mm; `None` when
    /// the bench has no stage.
    pub travel_x_mm: Option<(f64, f64)>,
    pub travel_y_mm: Option<(f64, f64)>,
    /// The stage's step, mm (`StageInfo::resolution_mm`): a requested move is rounded to it,
    /// so what the spec and the manifest state is what the stage is told.
    pub stage_resolution_mm: Option<f64>,
    /// Exposures the request may ask for, µs.
    pub exposure_us: (f64, f64),
    /// The camera's own binning and decimation (`GET /camera`): the `hw:` schemes an experiment
    /// may name.
    pub hardware_schemes: Vec<ffdic_hw::HardwareScheme>,
}

/// A stage axis, so a refusal names the request field at fault whatever the request calls it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StageAxis {
    X,
    Y,
}

impl StageAxis {
    pub fn name(self) -> &'static str {
        match self {
            Self::X => "x",
            Self::Y => "y",
        }
    }
}

/// A move the stage cannot make.
#[derive(Clone, Debug, PartialEq)]
pub struct OutOfTravel {
    pub axis: StageAxis,
    pub reason: String,
}

/// A dot spacing below one image pixel is not a speckle pattern a camera can resolve (DIC needs
/// 3–5 px speckles; Sutton, Orteu & Schreier, *Image Correlation for Shape, Motion and
/// Deformation Measurements*, 2009, §3.3), and it is what sizes the target layout.
pub const MIN_DOT_SPACING_PX: f64 = 1.0;
/// Dots smaller than a tenth of a pixel or larger than 1000 px make no speckle either.
pub const DOT_DIAMETER_PX: (f64, f64) = (0.1, 1000.0);
/// Exposures outside 1 µs … 60 s are outside every camera this daemon drives.
pub const EXPOSURE_US: (f64, f64) = (1.0, 60e6);

impl BenchLimits {
    /// Limits of a bench of this scale with no stage, no target changer and the default
    /// exposure range: what an analysis of stored frames needs.
    pub fn analysis_only(scale_px_per_mm: f64) -> Self {
        Self {
            scale_px_per_mm,
            target_field_mm: None,
            travel_x_mm: None,
            travel_y_mm: None,
            stage_resolution_mm: None,
            exposure_us: EXPOSURE_US,
            hardware_schemes: Vec::new(),
        }
    }

    pub fn has_target_mount(&self) -> bool {
        self.target_field_mm.is_some()
    }

    /// A bench with a stage knows its travel.
    pub fn has_stage(&self) -> bool {
        self.travel_x_mm.is_some()
    }

    /// Checks a custom print against what the camera resolves and what a target layout may hold.
    pub fn check_pattern(&self, p: &SpecklePattern) -> Result<(), String> {
        let s = self.scale_px_per_mm;
        let numbers = [
            p.dot_diameter_mm,
            p.dot_spacing_mm,
            p.contrast,
            p.edge_softness_mm,
        ];
        if numbers.iter().any(|v| !v.is_finite()) {
            return Err("every number must be finite".into());
        }
        let (d_lo, d_hi) = DOT_DIAMETER_PX;
        if !(d_lo..=d_hi).contains(&(p.dot_diameter_mm * s)) {
            return Err(format!(
                "dot_diameter_mm must be {:.4} to {:.1} mm ({d_lo} to {d_hi} px at {s} px/mm)",
                d_lo / s,
                d_hi / s
            ));
        }
        if p.dot_spacing_mm * s < MIN_DOT_SPACING_PX {
            return Err(format!(
                "dot_spacing_mm must be at least {:.4} mm ({MIN_DOT_SPACING_PX} px at {s} px/mm)",
                MIN_DOT_SPACING_PX / s
            ));
        }
        if !(0.0..=1.0).contains(&p.contrast) {
            return Err("contrast must lie in [0, 1]".into());
        }
        if !(0.0..=10.0).contains(&p.edge_softness_mm) {
            return Err("edge_softness_mm must lie in [0, 10] mm".into());
        }
        if let Some(field) = self.target_field_mm {
            p.dot_count(field).map_err(|e| e.to_string())?;
        }
        Ok(())
    }

    /// `mm` rounded to the stage's step (unchanged without a stage or a stated step), as the
    /// stage itself rounds it (`ffdic_hw::on_grid`), and then in the step's decimals.
    pub fn on_stage_grid(&self, mm: f64) -> f64 {
        match self.stage_resolution_mm {
            Some(step) if step > 0.0 && mm.is_finite() => {
                // Rounded in the step's decimals too, so 0.7692 is not printed 0.7692000000000001.
                let decimals = (-step.log10()).ceil().clamp(0.0, 15.0) as i32 + 1;
                let scale = 10f64.powi(decimals);
                (ffdic_hw::on_grid(mm, step) * scale).round() / scale
            }
            _ => mm,
        }
    }

    /// Checks a position relative to the reference (home) against the stage's travel, naming
    /// the axis at fault.
    pub fn check_move(&self, dx_mm: f64, dy_mm: f64) -> Result<(), OutOfTravel> {
        for (axis, d, travel) in [
            (StageAxis::X, dx_mm, self.travel_x_mm),
            (StageAxis::Y, dy_mm, self.travel_y_mm),
        ] {
            let name = axis.name();
            if !d.is_finite() {
                let reason = format!("the {name} move must be a finite number of mm");
                return Err(OutOfTravel { axis, reason });
            }
            if let Some((lo, hi)) = travel {
                if !(lo..=hi).contains(&d) {
                    let reason =
                        format!("{d} mm in {name} is outside the stage's travel [{lo}, {hi}] mm");
                    return Err(OutOfTravel { axis, reason });
                }
            }
        }
        Ok(())
    }

    pub fn check_exposure(&self, exposure_us: f64) -> Result<(), String> {
        let (lo, hi) = self.exposure_us;
        if !(lo..=hi).contains(&exposure_us) {
            return Err(format!("must lie in [{lo}, {hi}] µs"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mock() -> BenchLimits {
        BenchLimits {
            scale_px_per_mm: 26.0,
            target_field_mm: Some((-75.0, -68.0, 75.0, 68.0)),
            travel_x_mm: Some((-25.0, 25.0)),
            travel_y_mm: Some((-25.0, 25.0)),
            stage_resolution_mm: None,
            exposure_us: EXPOSURE_US,
            hardware_schemes: Vec::new(),
        }
    }

    fn pattern(d: f64, s: f64) -> SpecklePattern {
        SpecklePattern {
            label: "p".into(),
            dot_diameter_mm: d,
            dot_spacing_mm: s,
            contrast: 0.8,
            edge_softness_mm: 0.0,
            placement: Default::default(),
            profile: Default::default(),
            min_gap_mm: 0.0,
        }
    }

    #[test]
    fn the_papers_prints_pass_and_sub_pixel_or_huge_layouts_do_not() {
        let l = mock();
        for label in ["a", "b", "c"] {
            l.check_pattern(&SpecklePattern::preset(label).unwrap())
                .unwrap();
        }
        // The reproducers: a 288 GB layout and a capacity overflow.
        assert!(l.check_pattern(&pattern(0.0005, 0.001)).is_err());
        assert!(l.check_pattern(&pattern(0.5, 1e-9)).is_err());
        // One pixel of spacing is resolvable but over 150 x 136 mm it is 20 M dots: refused by
        // the layout cap, naming the smallest spacing that fits.
        let e = l.check_pattern(&pattern(0.1, 0.04)).unwrap_err();
        assert!(e.contains("dot_spacing_mm must be at least"), "{e}");
        assert!(l.check_pattern(&pattern(f64::NAN, 0.5)).is_err());
    }

    #[test]
    fn moves_stay_within_the_travel() {
        let l = mock();
        assert!(l.check_move(5.0, 0.013).is_ok());
        assert_eq!(l.on_stage_grid(0.7692307692307693), 0.7692307692307693);
        let stepped = BenchLimits {
            stage_resolution_mm: Some(1e-4),
            ..mock()
        };
        assert_eq!(stepped.on_stage_grid(0.7692307692307693), 0.7692);
        assert_eq!(stepped.on_stage_grid(-0.03846153846), -0.0385);
        assert_eq!(format!("{}", stepped.on_stage_grid(20.0 / 26.0)), "0.7692");
        assert_eq!(l.check_move(25.5, 0.0).unwrap_err().axis, StageAxis::X);
        assert_eq!(l.check_move(0.0, -1e7).unwrap_err().axis, StageAxis::Y);
        assert_eq!(l.check_move(0.0, f64::NAN).unwrap_err().axis, StageAxis::Y);
        assert!(l.check_move(f64::INFINITY, 0.0).is_err());
    }
}
