//! An experiment as a client asks for it (`POST /experiments`, `ffdic reproduce`): every field
//! defaults to the paper's study, so `{}` runs it. Validation names the offending field, so the
//! API can answer 422 with it.

use super::spec::{ExperimentSpec, MoveSpec, PatternSpec, StepSeries};
use crate::bench::BenchLimits;
use crate::dic::DicSettings;
use crate::model::SpecklePattern;
use crate::reduce::Scheme;
use ffdic_hw::{HardwareScheme, HARDWARE_SCHEME_PREFIX};
use serde::{Deserialize, Serialize};

/// A reduction scheme by name (`ff100`, `ff50`, `ff25`, `native`, or `BXxBY/AXxAY`; see
/// `Scheme::parse`) or spelled out per axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum SchemeSpec {
    Preset(String),
    Custom(Scheme),
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ExperimentRequest {
    /// Shown in lists and written into manifests: 1 to 128 printable characters, not only
    /// spaces.
    pub name: String,
    /// Speckle targets: presets `a`, `b`, `c` or full descriptions. A bench without a target
    /// changer (real hardware) takes exactly one: the target mounted by hand.
    #[schema(value_type = Vec<Object>)]
    pub patterns: Vec<PatternSpec>,
    /// The mounted prints are characterised: their dots' profile, diameter, spacing, contrast and
    /// edge softness are as `patterns` describe them (a print measured, or the mock bench's,
    /// which renders its presets exactly). The dataset then states each print whole
    /// (`profile`), and a diagnosis takes it as stated instead of calibrating it to the frames,
    /// which is what lets it fit the lens blur and the pixel aperture at all. False: the prints
    /// are nominal, as a print on a real bench is unless measured.
    pub print_characterised: bool,
    /// Stage moves from the reference position, mm.
    #[schema(value_type = Vec<Object>)]
    pub moves: Vec<MoveSpec>,
    /// Sub-pixel step series: `count` moves of k·step for k = 1..=count.
    #[schema(value_type = Vec<Object>)]
    pub step_series: Vec<StepSeries>,
    /// Static frames of the reference position per pattern and capture (noise floor).
    pub static_frames: usize,
    /// Independent captures of every reference/deformed pair (new noise each): the study reports
    /// the mean over captures and its 95 % interval (Student t). 1 = a single capture. At most
    /// 2000 frames in all: patterns × repeats × (1 + static frames + moves).
    pub repeats: usize,
    /// With `repeats` > 1, a new speckle layout for every capture (a bench with a target changer,
    /// such as the mock bench, only): the interval then holds the layout-to-layout spread too.
    pub new_layout_per_repeat: bool,
    /// Frames averaged into each stored frame.
    pub frames_averaged: usize,
    /// Extra wait after the stage reports settled, ms.
    pub settle_ms: u64,
    /// Camera exposure for the experiment, µs (null: keep the camera's); within the camera's
    /// range (`GET /camera`).
    pub exposure_us: Option<f64>,
    /// Reduction schemes (fill factors): presets and custom schemes are synthesised from the
    /// full-resolution frames; `hw:` names (`GET /camera` lists the camera's) are captured in the
    /// camera's own binning or decimation at every position, beside the full-resolution frame.
    #[schema(value_type = Vec<Object>)]
    pub schemes: Vec<SchemeSpec>,
    /// 2D DIC settings.
    #[schema(value_type = Object)]
    pub dic: DicSettings,
    /// Seed of the mock bench's speckle layouts and of its noise (per target and exposure):
    /// the same request and seed give the same frames.
    pub seed: u64,
}

impl Default for ExperimentRequest {
    fn default() -> Self {
        let paper = ExperimentSpec::paper();
        Self {
            name: paper.name,
            patterns: paper.patterns,
            print_characterised: false,
            moves: paper.moves,
            step_series: paper.step_series,
            static_frames: paper.static_frames,
            repeats: paper.repeats,
            new_layout_per_repeat: paper.new_layout_per_repeat,
            frames_averaged: 1,
            settle_ms: 50,
            exposure_us: None,
            schemes: paper.schemes.into_iter().map(SchemeSpec::Preset).collect(),
            dic: paper.dic,
            seed: paper.seed,
        }
    }
}

/// A request that cannot run, with the field to blame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {reason}")]
pub struct FieldError {
    pub field: String,
    pub reason: String,
}

/// A [`FieldError`] naming `field`.
pub(crate) fn field_error(field: impl Into<String>, reason: impl Into<String>) -> FieldError {
    FieldError {
        field: field.into(),
        reason: reason.into(),
    }
}

/// A checked request: what the runner executes.
#[derive(Clone, Debug)]
pub struct ExperimentPlan {
    pub name: String,
    pub patterns: Vec<SpecklePattern>,
    /// The dataset states the prints as characterised ([`ExperimentRequest::print_characterised`]).
    pub print_characterised: bool,
    pub moves: Vec<MoveSpec>,
    pub static_frames: usize,
    pub repeats: usize,
    pub new_layout_per_repeat: bool,
    pub frames_averaged: usize,
    pub settle_ms: u64,
    pub exposure_us: Option<f64>,
    /// The synthesised schemes.
    pub schemes: Vec<Scheme>,
    /// The camera's own schemes, captured beside the full-resolution frames.
    pub hardware_schemes: Vec<HardwareScheme>,
    pub dic: DicSettings,
    pub seed: u64,
}

impl ExperimentPlan {
    /// Frames the plan captures: each pattern and repeat takes a reference, its static frames
    /// and one frame per move, at full resolution and in each hardware scheme.
    pub fn frame_count(&self) -> usize {
        frame_count(
            self.static_frames,
            self.moves.len(),
            self.patterns.len(),
            self.repeats,
            self.hardware_schemes.len(),
        )
    }
}

fn frame_count(
    static_frames: usize,
    moves: usize,
    patterns: usize,
    repeats: usize,
    hardware_schemes: usize,
) -> usize {
    (1 + static_frames + moves) * patterns * repeats * (1 + hardware_schemes)
}

/// Limits that keep one request from occupying the bench for days.
pub const MAX_MOVES: usize = 200;
/// Frames one experiment may capture (patterns × repeats × (reference, static frames, moves)).
pub const MAX_FRAMES: usize = 2000;
pub const MAX_FRAMES_AVERAGED: usize = 64;
pub const MAX_STATIC_FRAMES: usize = 32;
pub const MAX_REPEATS: usize = 32;
pub const MAX_PATTERNS: usize = 16;
pub const MAX_SCHEMES: usize = 16;
pub const MAX_SETTLE_MS: u64 = 60_000;

impl ExperimentRequest {
    /// Checks everything that does not need the hardware, against what the bench can do.
    pub fn plan(&self, limits: &BenchLimits) -> Result<ExperimentPlan, FieldError> {
        check_run_name(&self.name)?;
        let patterns = self.check_patterns(limits)?;
        let moves = self.check_moves(limits)?;
        if !(1..=MAX_FRAMES_AVERAGED).contains(&self.frames_averaged) {
            return Err(field_error(
                "frames_averaged",
                format!("1 to {MAX_FRAMES_AVERAGED}"),
            ));
        }
        if self.static_frames > MAX_STATIC_FRAMES {
            return Err(field_error(
                "static_frames",
                format!("at most {MAX_STATIC_FRAMES}"),
            ));
        }
        if !(1..=MAX_REPEATS).contains(&self.repeats) {
            return Err(field_error("repeats", format!("1 to {MAX_REPEATS}")));
        }
        if self.new_layout_per_repeat && !limits.has_target_mount() {
            return Err(field_error(
                "new_layout_per_repeat",
                "this bench has no target changer: the mounted target's layout cannot change",
            ));
        }
        let (schemes, hardware_schemes) = self.check_schemes(limits)?;
        let frames = frame_count(
            self.static_frames,
            moves.len(),
            patterns.len(),
            self.repeats,
            hardware_schemes.len(),
        );
        if frames > MAX_FRAMES {
            return Err(field_error(
                // The hardware schemes are to blame when the frames would fit without them.
                if frames / (1 + hardware_schemes.len()) <= MAX_FRAMES {
                    "schemes"
                } else {
                    "repeats"
                },
                format!("{frames} frames in all; at most {MAX_FRAMES}"),
            ));
        }
        if self.settle_ms > MAX_SETTLE_MS {
            return Err(field_error("settle_ms", format!("at most {MAX_SETTLE_MS}")));
        }
        if let Some(e) = self.exposure_us {
            limits
                .check_exposure(e)
                .map_err(|r| field_error("exposure_us", r))?;
        }
        Ok(ExperimentPlan {
            name: self.name.clone(),
            patterns,
            print_characterised: self.print_characterised,
            moves,
            static_frames: self.static_frames,
            repeats: self.repeats,
            new_layout_per_repeat: self.new_layout_per_repeat,
            frames_averaged: self.frames_averaged,
            settle_ms: self.settle_ms,
            exposure_us: self.exposure_us,
            schemes,
            hardware_schemes,
            dic: check_dic(&self.dic)?,
            seed: self.seed,
        })
    }

    /// The synthesised schemes, and the `hw:` schemes the camera offers (looked up by name).
    fn check_schemes(
        &self,
        limits: &BenchLimits,
    ) -> Result<(Vec<Scheme>, Vec<HardwareScheme>), FieldError> {
        check_scheme_count(self.schemes.len())?;
        let mut synthesised: Vec<Scheme> = Vec::new();
        let mut hardware: Vec<HardwareScheme> = Vec::new();
        for (i, spec) in self.schemes.iter().enumerate() {
            let field = format!("schemes[{i}]");
            let Some(name) = hardware_name(spec) else {
                push_unique(&mut synthesised, synthesised_scheme(i, spec)?, &field)?;
                continue;
            };
            let scheme = limits
                .hardware_schemes
                .iter()
                .find(|h| h.name.eq_ignore_ascii_case(name))
                .ok_or_else(|| {
                    let offered: Vec<&str> = limits
                        .hardware_schemes
                        .iter()
                        .map(|h| h.name.as_str())
                        .collect();
                    let offered = if offered.is_empty() {
                        "none".to_string()
                    } else {
                        offered.join(", ")
                    };
                    field_error(
                        &field,
                        format!(
                            "the camera offers no hardware scheme '{name}' (it offers: {offered})"
                        ),
                    )
                })?;
            if hardware.iter().any(|h| h.name == scheme.name) {
                return Err(field_error(
                    field,
                    format!("'{}' appears twice", scheme.name),
                ));
            }
            hardware.push(scheme.clone());
        }
        if synthesised.is_empty() {
            // A hardware scheme's increase is taken over its twin's first synthesised scheme.
            return Err(field_error(
                "schemes",
                "at least one synthesised scheme (e.g. ff100) beside the hardware ones",
            ));
        }
        Ok((synthesised, hardware))
    }

    fn check_patterns(&self, limits: &BenchLimits) -> Result<Vec<SpecklePattern>, FieldError> {
        if self.patterns.is_empty() {
            return Err(field_error("patterns", "at least one pattern"));
        }
        if self.patterns.len() > MAX_PATTERNS {
            return Err(field_error(
                "patterns",
                format!("at most {MAX_PATTERNS} patterns"),
            ));
        }
        if !limits.has_target_mount() && self.patterns.len() != 1 {
            return Err(field_error(
                "patterns",
                "this bench has no target changer: name exactly one pattern, the mounted target",
            ));
        }
        let mut patterns: Vec<SpecklePattern> = Vec::new();
        for (i, p) in self.patterns.iter().enumerate() {
            let pattern = match p {
                PatternSpec::Preset(label) => SpecklePattern::preset(label).ok_or_else(|| {
                    field_error(
                        format!("patterns[{i}]"),
                        format!("unknown preset '{label}' (a, b or c)"),
                    )
                })?,
                PatternSpec::Custom(c) => {
                    limits
                        .check_pattern(c)
                        .map_err(|r| field_error(format!("patterns[{i}]"), r))?;
                    c.clone()
                }
            };
            if !is_plain_id(&pattern.label) {
                return Err(field_error(
                    format!("patterns[{i}].label"),
                    "letters, digits, '-' and '_' only, at most 64",
                ));
            }
            if patterns.iter().any(|q| q.label == pattern.label) {
                return Err(field_error(
                    format!("patterns[{i}]"),
                    format!("label '{}' appears twice", pattern.label),
                ));
            }
            patterns.push(pattern);
        }
        Ok(patterns)
    }

    fn check_moves(&self, limits: &BenchLimits) -> Result<Vec<MoveSpec>, FieldError> {
        // Counted before the step series are expanded: `count` sizes that expansion.
        let requested = self
            .step_series
            .iter()
            .try_fold(self.moves.len(), |n, s| n.checked_add(s.count))
            .unwrap_or(usize::MAX);
        if requested > MAX_MOVES {
            return Err(field_error(
                "moves",
                format!("at most {MAX_MOVES} moves in all"),
            ));
        }
        let moves = ExperimentSpec {
            moves: self.moves.clone(),
            step_series: self.step_series.clone(),
            ..ExperimentSpec::paper()
        }
        .all_moves();
        if moves.is_empty() {
            return Err(field_error("moves", "at least one move or step series"));
        }
        // What the stage is told: each move on its grid of steps.
        let moves: Vec<MoveSpec> = moves
            .into_iter()
            .map(|m| MoveSpec {
                dx_mm: limits.on_stage_grid(m.dx_mm),
                dy_mm: limits.on_stage_grid(m.dy_mm),
                ..m
            })
            .collect();
        for (i, m) in moves.iter().enumerate() {
            limits
                .check_move(m.dx_mm, m.dy_mm)
                .map_err(|e| field_error(format!("moves[{i}]"), e.reason))?;
            if !is_plain_id(&m.id) {
                return Err(field_error(
                    format!("moves[{i}].id"),
                    "letters, digits, '-' and '_' only, at most 64",
                ));
            }
            if moves[..i].iter().any(|o| o.id == m.id) {
                return Err(field_error(
                    format!("moves[{i}].id"),
                    format!("'{}' appears twice", m.id),
                ));
            }
        }
        Ok(moves)
    }
}

/// The longest name a run (experiment, sweep) may have, in characters.
pub const MAX_RUN_NAME_CHARS: usize = 128;

/// A run's name: shown in lists and written into manifests; printable (no control character),
/// 1 to [`MAX_RUN_NAME_CHARS`] characters, not only white space. The field is `name`.
pub fn check_run_name(name: &str) -> Result<(), FieldError> {
    if name.trim().is_empty()
        || name.chars().count() > MAX_RUN_NAME_CHARS
        || name.chars().any(char::is_control)
    {
        return Err(field_error(
            "name",
            format!("must be 1 to {MAX_RUN_NAME_CHARS} printable characters, not only white space"),
        ));
    }
    Ok(())
}

/// The `hw:` name of a scheme spec, if it names a hardware scheme.
fn hardware_name(spec: &SchemeSpec) -> Option<&str> {
    match spec {
        SchemeSpec::Preset(name) => is_hardware_scheme_name(name).then_some(name.as_str()),
        SchemeSpec::Custom(_) => None,
    }
}

/// Whether a scheme name names one of the camera's own schemes (`hw:…`, any case).
pub fn is_hardware_scheme_name(name: &str) -> bool {
    name.get(..HARDWARE_SCHEME_PREFIX.len())
        .is_some_and(|p| p.eq_ignore_ascii_case(HARDWARE_SCHEME_PREFIX))
}

/// The synthesised reduction schemes of a request (shared by analyses, comparisons and sweeps);
/// a `hw:` name is refused: only an experiment captures those.
pub fn check_schemes(specs: &[SchemeSpec]) -> Result<Vec<Scheme>, FieldError> {
    check_scheme_count(specs.len())?;
    let mut schemes: Vec<Scheme> = Vec::new();
    for (i, spec) in specs.iter().enumerate() {
        if let Some(name) = hardware_name(spec) {
            return Err(field_error(
                format!("schemes[{i}]"),
                format!(
                    "'{name}' is a hardware scheme: the camera captures it in an experiment \
                     (POST /experiments); a dataset's hardware runs are analysed in their own scheme"
                ),
            ));
        }
        push_unique(
            &mut schemes,
            synthesised_scheme(i, spec)?,
            &format!("schemes[{i}]"),
        )?;
    }
    Ok(schemes)
}

fn check_scheme_count(n: usize) -> Result<(), FieldError> {
    if n == 0 {
        return Err(field_error("schemes", "at least one scheme"));
    }
    if n > MAX_SCHEMES {
        return Err(field_error(
            "schemes",
            format!("at most {MAX_SCHEMES} schemes"),
        ));
    }
    Ok(())
}

/// Scheme `i` of a request, a preset or spelled out per axis.
fn synthesised_scheme(i: usize, spec: &SchemeSpec) -> Result<Scheme, FieldError> {
    match spec {
        SchemeSpec::Preset(name) => Scheme::parse(name),
        SchemeSpec::Custom(c) => Scheme::new(&c.name, c.x, c.y),
    }
    .map_err(|e| field_error(format!("schemes[{i}]"), e.to_string()))
}

fn push_unique(schemes: &mut Vec<Scheme>, scheme: Scheme, field: &str) -> Result<(), FieldError> {
    if schemes.iter().any(|q| q.name == scheme.name) {
        return Err(field_error(
            field,
            format!("'{}' appears twice", scheme.name),
        ));
    }
    schemes.push(scheme);
    Ok(())
}

/// The DIC settings of a request, with the field named as `dic.<field>`.
pub fn check_dic(dic: &DicSettings) -> Result<DicSettings, FieldError> {
    dic.validate().map_err(|e| match e {
        crate::dic::DicError::Setting { field, reason } => {
            field_error(format!("dic.{field}"), reason)
        }
        other => field_error("dic", other.to_string()),
    })?;
    Ok(dic.clone())
}

/// Ids and labels become file names: keep them plain.
fn is_plain_id(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> BenchLimits {
        BenchLimits {
            target_field_mm: Some((-75.0, -68.0, 75.0, 68.0)),
            travel_x_mm: Some((-25.0, 25.0)),
            travel_y_mm: Some((-25.0, 25.0)),
            stage_resolution_mm: None,
            ..BenchLimits::analysis_only(26.0)
        }
    }

    #[test]
    fn empty_request_is_the_paper() {
        let r: ExperimentRequest = serde_json::from_str("{}").unwrap();
        let p = r.plan(&limits()).unwrap();
        assert_eq!(p.patterns.len(), 3);
        assert_eq!(p.moves.len(), 1);
        assert_eq!(p.moves[0].dx_mm, 5.0);
        assert_eq!(p.schemes.len(), 3);
    }

    #[test]
    fn moves_are_what_the_stage_is_told_on_its_grid() {
        let stepped = BenchLimits {
            stage_resolution_mm: Some(1e-4),
            ..limits()
        };
        let r: ExperimentRequest = serde_json::from_str(
            r#"{"moves":[{"id":"m","dx_mm":0.7692307692307693,"dy_mm":-0.03846153846}],
                "step_series":[{"id":"s","dx_step_mm":0.0038461538,"count":3}]}"#,
        )
        .unwrap();
        let p = r.plan(&stepped).unwrap();
        let got: Vec<(f64, f64)> = p.moves.iter().map(|m| (m.dx_mm, m.dy_mm)).collect();
        assert_eq!(
            got,
            [
                (0.7692, -0.0385),
                (0.0038, 0.0),
                (0.0077, 0.0),
                (0.0115, 0.0)
            ]
        );
        // Without a stated step, nothing is rounded.
        assert_eq!(
            r.plan(&limits()).unwrap().moves[0].dx_mm,
            0.7692307692307693
        );
    }

    #[test]
    fn problems_name_their_field() {
        let bad = |json: &str| {
            serde_json::from_str::<ExperimentRequest>(json)
                .unwrap()
                .plan(&limits())
                .unwrap_err()
                .field
        };
        assert_eq!(bad(r#"{"patterns":["z"]}"#), "patterns[0]");
        assert_eq!(bad(r#"{"frames_averaged":0}"#), "frames_averaged");
        assert_eq!(bad(r#"{"repeats":0}"#), "repeats");
        assert_eq!(bad(r#"{"static_frames":33}"#), "static_frames");
        assert_eq!(
            bad(
                r#"{"repeats":32,"static_frames":32,"step_series":[{"id":"s","dx_step_mm":0.01,"count":100}]}"#
            ),
            "repeats"
        );
        assert_eq!(bad(r#"{"schemes":["ff7"]}"#), "schemes[0]");
        assert_eq!(bad(r#"{"dic":{"subset_px":40}}"#), "dic.subset");
        assert_eq!(bad(r#"{"moves":[{"id":"../x","dx_mm":1}]}"#), "moves[0].id");
        // The issue's reproducers: a layout of 288 GB, a capacity overflow, a move beyond the
        // travel, an exposure of a day, a scheme name that is a path, a control character.
        let custom = |d: f64, s: f64| {
            format!(
                r#"{{"patterns":[{{"label":"x","dot_diameter_mm":{d},"dot_spacing_mm":{s},"contrast":0.8}}]}}"#
            )
        };
        assert_eq!(bad(&custom(0.0005, 0.001)), "patterns[0]");
        assert_eq!(bad(&custom(0.0005, 1e-9)), "patterns[0]");
        assert_eq!(bad(r#"{"moves":[{"id":"far","dx_mm":26}]}"#), "moves[0]");
        assert_eq!(bad(r#"{"exposure_us":8.64e10}"#), "exposure_us");
        assert_eq!(
            bad(
                r#"{"schemes":[{"name":"a/b","x":{"block":2,"first":0,"active":1},"y":{"block":2,"first":0,"active":1}}]}"#
            ),
            "schemes[0]"
        );
        assert_eq!(bad(r#"{"name":"a\u0007b"}"#), "name");
        assert_eq!(
            bad(r#"{"step_series":[{"id":"s","dx_step_mm":0.001,"count":18446744073709551615}]}"#),
            "moves"
        );
        // Preset names in any case.
        let upper: ExperimentRequest = serde_json::from_str(r#"{"schemes":["FF50"]}"#).unwrap();
        assert_eq!(upper.plan(&limits()).unwrap().schemes[0].name, "ff50");
        let one_target = serde_json::from_str::<ExperimentRequest>("{}")
            .unwrap()
            .plan(&BenchLimits::analysis_only(26.0))
            .unwrap_err();
        assert_eq!(one_target.field, "patterns");
        let fixed_target = serde_json::from_str::<ExperimentRequest>(
            r#"{"patterns":["a"],"repeats":3,"new_layout_per_repeat":true}"#,
        )
        .unwrap()
        .plan(&BenchLimits::analysis_only(26.0))
        .unwrap_err();
        assert_eq!(fixed_target.field, "new_layout_per_repeat");
    }

    #[test]
    fn hardware_schemes_come_from_the_camera_and_need_a_synthesised_twin() {
        let caps = ffdic_hw::ReductionCaps {
            binning_max: (2, 2),
            binning_mode: Some(ffdic_hw::BinningMode::Average),
            binning_domain: ffdic_hw::BinningDomain::Digital,
            decimation_max: (1, 1),
        };
        let with_binning = BenchLimits {
            hardware_schemes: ffdic_hw::schemes_for(&caps),
            ..limits()
        };
        let plan = |schemes: &str, l: &BenchLimits| {
            let r: ExperimentRequest =
                serde_json::from_str(&format!(r#"{{"schemes":{schemes}}}"#)).unwrap();
            r.plan(l)
        };
        let p = plan(r#"["ff100","HW:BIN2X2-AVERAGE"]"#, &with_binning).unwrap();
        assert_eq!(p.schemes.len(), 1);
        assert_eq!(p.hardware_schemes[0].name, "hw:bin2x2-average");
        let e = plan(r#"["ff100","hw:dec2x2"]"#, &with_binning).unwrap_err();
        assert_eq!(e.field, "schemes[1]");
        assert!(e.reason.contains("'hw:dec2x2'") && e.reason.contains("hw:bin2x2-average"));
        let e = plan(r#"["ff100","hw:bin2x2-average"]"#, &limits()).unwrap_err();
        assert!(e.reason.contains("offers: none"), "{e}");
        let e = plan(r#"["hw:bin2x2-average"]"#, &with_binning).unwrap_err();
        assert_eq!(e.field, "schemes");
        let e = plan(
            r#"["ff100","hw:bin2x2-average","hw:bin2x2-average"]"#,
            &with_binning,
        )
        .unwrap_err();
        assert_eq!(e.field, "schemes[2]");
        // An analysis of stored frames cannot ask for the camera's own schemes.
        let e = check_schemes(&[SchemeSpec::Preset("hw:bin2x2-average".into())]).unwrap_err();
        assert_eq!(e.field, "schemes[0]");
        assert!(e.reason.contains("hardware scheme"), "{e}");
    }
}
