//! The reconstruction's one configuration, [`ReconConfig`]: every setting of the method, with
//! units, serialisable (JSON) and described by a JSON Schema ([`json_schema`]).
//!
//! `ReconConfig::default()` is the paper's method (Sec. 5 and 6, uncalibrated lamps; the
//! `paper` preset). Named presets ([`Preset`]) are whole configurations; a run's resolved
//! configuration is written next to its results, and reading it back reproduces the run.
//! [`ReconConfig::set`] changes one value by its dotted path (`shape.iterations=300`), the
//! way `simbench reconstruct --set` does; unknown keys and mistyped values are refused with
//! the JSON path that is wrong.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::ReconError;
use crate::stage1::{Known, Radiation, Stencil, TimeRule};
use crate::stage2::Optimizer;

/// Version of the configuration format, written into every `config.json`.
pub const CONFIG_VERSION: u32 = 1;

/// Everything the reconstruction is told (SI units). `Default` is the paper's method.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct ReconConfig {
    /// Format version of this file ([`CONFIG_VERSION`]).
    pub version: u32,
    /// The stage to run up to.
    pub stage: Stage,
    /// Finest image-pyramid level reconstructed (0: full resolution; each level halves the
    /// resolution by 2 x 2 block averaging).
    pub level: usize,
    /// How the videos are read and what is known about the scene.
    pub input: InputConfig,
    /// Stage 1 (paper Sec. 5): the Laplacian, the fluxes and the heat-exchange parameters.
    pub stage1: Stage1Config,
    /// Stage 2 (paper Sec. 6): the shape, coarse to fine.
    pub shape: ShapeConfig,
    /// Opt-in experiments, part of neither preset (builds with the feature `experimental`).
    #[cfg(feature = "experimental")]
    #[serde(skip_serializing_if = "crate::experimental::ExperimentalConfig::is_off")]
    pub experimental: crate::experimental::ExperimentalConfig,
}

/// The stage a run goes up to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Stage 1 only: Laplacian, fluxes, lambda, C and h at `level`.
    Laplacian,
    /// Stages 1 and 2, coarse to fine: the shape (the whole method).
    Shape,
}

/// Which video of a dataset is read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Video {
    /// `video.npy`: what the camera recorded (noise, fixed pattern, quantisation).
    Measured,
    /// `video_clean.npy`: the noise-free video of a simulated dataset.
    Clean,
}

/// The side of the camera (image x) a video's lamp stands on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum LampSide {
    /// Image x < 0 of the camera.
    Left,
    /// Image x > 0 of the camera.
    Right,
}

/// The reading of the datasets and the scene's known quantities.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct InputConfig {
    /// Which video file is read.
    pub video: Video,
    /// Emissivity of the object (dimensionless); `null`: `environment.json`'s.
    pub emissivity: Option<f64>,
    /// Temporal noise of the camera (NETD, K); `null`: measured on the frames at t <= 0.
    pub netd_k: Option<f64>,
    /// The material's thermal diffusivity k/(rho c_p), m^2/s: a metric shape. `null`: the
    /// diffusivity is profiled out and the size is fixed by `distance_m`.
    pub diffusivity_m2_per_s: Option<f64>,
    /// Nominal object distance, m: the start plane, and the mean depth when the diffusivity is
    /// unknown. `null`: the camera's distance to the world origin (|t| of `camera.json`).
    pub distance_m: Option<f64>,
    /// The side of each video's lamp; `null`: from `lamps.json` beside each video.
    pub lamp_sides: Option<Vec<LampSide>>,
}

/// How stage 1's temporal noise is reduced before the estimate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Denoise {
    /// The series as read.
    None,
    /// Truncated SVD of each video's series at the noise threshold (`stage1::denoise`).
    LowRank,
}

/// The sign constraint on stage 1's edge weights.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum EdgeWeights {
    /// Any sign (cotangent weights of obtuse triangles are negative).
    AnySign,
    /// Non-negative (the paper's constraint).
    Nonnegative,
}

/// Stage 1's settings (`heatrecon::stage1`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Stage1Config {
    /// Time rule of the heat equations (stage 2's frame pairs use the trapezoid for `central`).
    pub time_rule: TimeRule,
    /// Radiation model: `full` fits 1/C on the T^4 curvature, `linearized` (Eq. 5) only (h+R)/C.
    pub radiation: Radiation,
    /// A known global (convection coefficient h in W/(m^2 K), or heat capacity per area C in
    /// J/(m^2 K)) that splits lambda = (h + R)/C.
    pub known: Known,
    /// Sign constraint of the edge weights.
    pub edge_weights: EdgeWeights,
    /// First frame time used, s (lamps switch on at t = 0).
    pub t_start_s: f64,
    /// Last frame time used, s; `null`: the last frame.
    pub t_end_s: Option<f64>,
    /// Parameterisation of the rows of Delta_s (`paired`: opposite neighbours share a weight).
    pub stencil: Stencil,
    /// Temporal denoising before the estimate.
    pub denoise: Denoise,
    /// Graph regularisation strength kappa of the rows (dimensionless; 0: none); `null`: 1e-6 x
    /// 10^level below 1 mK of noise, else 1 (`Stage1Options::for_noise`).
    pub smoothing: Option<f64>,
    /// Threshold on the normalised flux difference that assigns a half-space (Eq. 9).
    pub halfspace_threshold: f64,
}

/// How stage 2's data term treats stage 1's fluxes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum FluxModel {
    /// Minimised over a constant flux per vertex and video: only the time-varying part of the
    /// heat equation constrains the shape.
    Profiled,
    /// Stage 1's flux images as they are.
    Stage1,
}

/// How stage 2 treats lambda = (h + R)/C and 1/C.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Globals {
    /// Minimised jointly with the depths from stage 1's values (robust loss and L-BFGS;
    /// otherwise profiled).
    Joint,
    /// Profiled out at every evaluation of the energy (robust loss only).
    Profiled,
    /// Held at stage 1's values.
    Stage1,
}

/// Stage 2's data loss.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum DataLoss {
    /// Mean over vertices of each vertex's RMS residual.
    Robust,
    /// Mean squared residual.
    L2,
}

/// How a known diffusivity sets the shape's size.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SizeRule {
    /// Each level optimised with the diffusivity profiled out (mean depth held), then scaled
    /// to the known diffusivity (`stage2::coarse_to_fine`, "Size"). With the lamp shading on,
    /// `fixed` all the same: the lamps fix the distance.
    ProfiledThenScaled,
    /// The known diffusivity held fixed in the data term (the size a slow mode).
    Fixed,
}

/// The temperature noise's expected contribution to the data term (errors in variables).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum NoiseCorrection {
    /// Removed (`stage2::noise`).
    Removed,
    /// Left in: it biases the shape away from the camera.
    None,
}

/// A term of calibrated point lamps (`lamps.json` beside each video): the lamp shading
/// (`stage2::lamp_shading`) or the two-light ratio. Not the paper's method.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LampTermConfig {
    /// Weight of the term at every level (dimensionless, as the normal consistency's).
    pub weight: f64,
    /// A vertex enters the term for a video when its stage-1 flux (the ratio: both fluxes)
    /// exceeds this fraction of the image's maximum (leaves cast shadows out).
    pub threshold: f64,
}

/// Stage 2's settings (`heatrecon::stage2`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct ShapeConfig {
    /// Coarser pyramid levels above `level` to start from.
    pub extra_levels: usize,
    /// Start no coarser than the coarsest of those levels whose pixel mesh has at least this
    /// many vertices.
    pub min_coarsest_vertices: usize,
    /// Optimiser (both on the large-steps parameterisation).
    pub optimizer: Optimizer,
    /// Iterations per level.
    pub iterations: usize,
    /// Iterations at the coarsest level; `null`: `iterations`.
    pub coarsest_iterations: Option<usize>,
    /// AdamUniform step, m; L-BFGS: the first step's largest depth change, m.
    pub learning_rate_m: f64,
    /// Large-steps lambda (dimensionless, per unit graph Laplacian).
    pub large_steps_lambda: f64,
    /// Weight of the normal-consistency smoothness (Eq. 11's lambda_sm).
    pub normal_weight: f64,
    /// Weight of the half-space hinge (Eq. 10) at the coarsest level.
    pub halfspace_weight: f64,
    /// Factor of the half-space weight per finer level (0 at the finest of several).
    pub halfspace_decay: f64,
    /// Weight of the mirror-symmetry term at the coarsest level (Eq. 11's lambda_sy; 0: off).
    pub symmetry_weight: f64,
    /// Data loss.
    pub data_loss: DataLoss,
    /// Stage 1's fluxes in the data term.
    pub flux: FluxModel,
    /// Vertices within this many rings of the mask boundary carry no data term.
    pub boundary_rings: usize,
    /// lambda and 1/C in the data term.
    pub globals: Globals,
    /// How a known diffusivity sets the size.
    pub size: SizeRule,
    /// The noise's contribution to the data term.
    pub noise_correction: NoiseCorrection,
    /// The calibrated-lamp shading term; `null`: off (the paper's method).
    pub lamp_shading: Option<LampTermConfig>,
}

/// A named configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// The paper's method: uncalibrated lamps (Sec. 5-6). The default.
    Paper,
    /// The paper's method plus the shading of calibrated point lamps (`lamps.json`).
    CalibratedLamps,
}

impl Preset {
    /// Every preset, in the order `simbench reconstruct --help` lists them.
    pub const ALL: [Preset; 2] = [Preset::Paper, Preset::CalibratedLamps];

    /// The preset's name (`--preset NAME`).
    pub fn name(self) -> &'static str {
        match self {
            Preset::Paper => "paper",
            Preset::CalibratedLamps => "calibrated-lamps",
        }
    }

    /// The preset of this name.
    ///
    /// # Errors
    /// An unknown name, listing the known ones.
    pub fn from_name(name: &str) -> Result<Preset, ReconError> {
        Preset::ALL.into_iter().find(|p| p.name() == name).ok_or_else(|| {
            let known: Vec<&str> = Preset::ALL.iter().map(|p| p.name()).collect();
            ReconError::Input(format!("unknown preset `{name}`; known presets: {}", known.join(", ")))
        })
    }

    /// The preset's configuration.
    pub fn config(self) -> ReconConfig {
        let paper = ReconConfig::default();
        match self {
            Preset::Paper => paper,
            // Lamp shading went wrong from coarsest levels of about 200 vertices (the bottle at
            // 160 x 128 moved 10 cm), not from 576 and more; its lamps fix the distance, so the
            // size is not profiled.
            Preset::CalibratedLamps => ReconConfig {
                shape: ShapeConfig {
                    lamp_shading: Some(LampTermConfig { weight: 10.0, threshold: 0.2 }),
                    normal_weight: 1.0,
                    coarsest_iterations: Some(1000),
                    min_coarsest_vertices: 500,
                    size: SizeRule::Fixed,
                    ..paper.shape
                },
                ..paper
            },
        }
    }
}

impl Default for ReconConfig {
    fn default() -> Self {
        ReconConfig {
            version: CONFIG_VERSION,
            stage: Stage::Shape,
            level: 0,
            input: InputConfig::default(),
            stage1: Stage1Config::default(),
            shape: ShapeConfig::default(),
            #[cfg(feature = "experimental")]
            experimental: Default::default(),
        }
    }
}

impl Default for InputConfig {
    fn default() -> Self {
        InputConfig {
            video: Video::Measured,
            emissivity: None,
            netd_k: None,
            diffusivity_m2_per_s: None,
            distance_m: None,
            lamp_sides: None,
        }
    }
}

impl Default for Stage1Config {
    fn default() -> Self {
        Stage1Config {
            time_rule: TimeRule::Central,
            radiation: Radiation::Full,
            known: Known::None,
            edge_weights: EdgeWeights::AnySign,
            t_start_s: 0.0,
            t_end_s: None,
            stencil: Stencil::Free,
            denoise: Denoise::LowRank,
            smoothing: None,
            halfspace_threshold: crate::halfspace::DEFAULT_THRESHOLD,
        }
    }
}

impl Default for ShapeConfig {
    fn default() -> Self {
        ShapeConfig {
            extra_levels: 2,
            min_coarsest_vertices: 0,
            optimizer: Optimizer::Lbfgs,
            iterations: 200,
            coarsest_iterations: None,
            learning_rate_m: 2e-4,
            large_steps_lambda: 2.0,
            normal_weight: 0.1,
            halfspace_weight: 1e-2,
            halfspace_decay: 0.7,
            symmetry_weight: 0.0,
            data_loss: DataLoss::Robust,
            flux: FluxModel::Profiled,
            boundary_rings: 2,
            globals: Globals::Joint,
            size: SizeRule::ProfiledThenScaled,
            noise_correction: NoiseCorrection::Removed,
            lamp_shading: None,
        }
    }
}

impl ReconConfig {
    /// Reads a configuration from JSON text; `origin` names it in errors (a file's path).
    /// Keys left out take the defaults of the paper's method.
    ///
    /// # Errors
    /// Invalid JSON, an unknown key or a mistyped value (naming its JSON path), or a value
    /// out of range ([`ReconConfig::validate`]).
    pub fn from_json(text: &str, origin: &str) -> Result<ReconConfig, ReconError> {
        let de = &mut serde_json::Deserializer::from_str(text);
        let cfg: ReconConfig = serde_path_to_error::deserialize(de).map_err(|e| {
            let path = e.path().to_string();
            ReconError::Input(format!("{origin}: at `{path}`: {}", e.into_inner()))
        })?;
        cfg.validate().map_err(|e| ReconError::Input(format!("{origin}: {e}")))?;
        Ok(cfg)
    }

    /// The configuration as pretty JSON with a trailing newline (what `config.json` holds).
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a configuration always serialises") + "\n"
    }

    /// Sets the value at a dotted `path` (e.g. `shape.iterations`) from `value`: JSON when it
    /// parses as JSON (`300`, `null`, `{"convection": 5}`), else a string (`lbfgs`).
    ///
    /// # Errors
    /// A path that names no key of the configuration, or a value of the wrong type or range.
    pub fn set(&mut self, path: &str, value: &str) -> Result<(), ReconError> {
        let bad = |msg: String| ReconError::Input(format!("--set {path}={value}: {msg}"));
        let mut doc = serde_json::to_value(&*self).expect("a configuration always serialises");
        let keys: Vec<&str> = path.split('.').collect();
        let mut node = &mut doc;
        for (i, key) in keys.iter().enumerate() {
            let here = keys[..=i].join(".");
            let obj = node.as_object_mut().ok_or_else(|| bad(format!("`{}` is not a section", keys[..i].join("."))))?;
            if !obj.contains_key(*key) {
                let known: Vec<&str> = obj.keys().map(|k| k.as_str()).collect();
                return Err(bad(format!("no key `{here}`; keys here: {}", known.join(", "))));
            }
            node = obj.get_mut(*key).expect("checked above");
        }
        *node = serde_json::from_str(value).unwrap_or_else(|_| serde_json::Value::String(value.to_string()));
        let text = doc.to_string();
        *self = ReconConfig::from_json(&text, "--set").map_err(|e| bad(e.to_string()))?;
        Ok(())
    }

    /// Checks the ranges the types cannot express.
    ///
    /// # Errors
    /// The first value out of range, with its path.
    pub fn validate(&self) -> Result<(), String> {
        let positive = |v: f64, path: &str| {
            if v > 0.0 && v.is_finite() {
                Ok(())
            } else {
                Err(format!("`{path}` must be a finite number > 0, got {v}"))
            }
        };
        let nonnegative = |v: f64, path: &str| {
            if v >= 0.0 && v.is_finite() {
                Ok(())
            } else {
                Err(format!("`{path}` must be a finite number >= 0, got {v}"))
            }
        };
        if self.version != CONFIG_VERSION {
            return Err(format!(
                "`version` {} is not this program's configuration version {CONFIG_VERSION}",
                self.version
            ));
        }
        let i = &self.input;
        if let Some(e) = i.emissivity {
            if !(e > 0.0 && e <= 1.0) {
                return Err(format!("`input.emissivity` must be in (0, 1], got {e}"));
            }
        }
        if let Some(s) = i.netd_k {
            nonnegative(s, "input.netd_k")?;
        }
        if let Some(a) = i.diffusivity_m2_per_s {
            positive(a, "input.diffusivity_m2_per_s")?;
        }
        if let Some(d) = i.distance_m {
            positive(d, "input.distance_m")?;
        }
        let s1 = &self.stage1;
        match s1.known {
            Known::Convection(h) => nonnegative(h, "stage1.known.convection")?,
            Known::HeatCapacity(c) => positive(c, "stage1.known.heat_capacity")?,
            Known::None => {}
        }
        if let Some(k) = s1.smoothing {
            nonnegative(k, "stage1.smoothing")?;
        }
        nonnegative(s1.halfspace_threshold, "stage1.halfspace_threshold")?;
        let s = &self.shape;
        positive(s.learning_rate_m, "shape.learning_rate_m")?;
        nonnegative(s.large_steps_lambda, "shape.large_steps_lambda")?;
        nonnegative(s.normal_weight, "shape.normal_weight")?;
        nonnegative(s.halfspace_weight, "shape.halfspace_weight")?;
        nonnegative(s.halfspace_decay, "shape.halfspace_decay")?;
        nonnegative(s.symmetry_weight, "shape.symmetry_weight")?;
        if let Some(l) = &s.lamp_shading {
            lamp_term(l, "shape.lamp_shading")?;
        }
        #[cfg(feature = "experimental")]
        self.validate_experiments()?;
        Ok(())
    }
}

impl ReconConfig {
    #[cfg(feature = "experimental")]
    fn validate_experiments(&self) -> Result<(), String> {
        let e = &self.experimental;
        if let Some(l) = &e.lamp_ratio {
            lamp_term(l, "experimental.lamp_ratio")?;
        }
        if let Some(oe) = &e.output_error {
            let coarsest = self.level + self.shape.extra_levels;
            if !(self.level..=coarsest).contains(&oe.level) {
                return Err(format!(
                    "`experimental.output_error.level` {}: not among the reconstructed levels {}..={coarsest} \
                     (`level`, `shape.extra_levels`)",
                    oe.level, self.level
                ));
            }
            if self.input.diffusivity_m2_per_s.is_none() {
                return Err("`experimental.output_error` needs the diffusivity (`input.diffusivity_m2_per_s`): \
                            the refinement is metric"
                    .into());
            }
            if let Some(f) = oe.mode_starts.iter().find(|f| !(f.is_finite() && **f > 0.0)) {
                return Err(format!("`experimental.output_error.mode_starts`: {f} is not a positive factor"));
            }
        }
        Ok(())
    }
}

/// Checks a lamp term's weight and threshold; `path` names it.
fn lamp_term(l: &LampTermConfig, path: &str) -> Result<(), String> {
    if !(l.weight >= 0.0 && l.weight.is_finite()) {
        return Err(format!("`{path}.weight` must be a finite number >= 0, got {}", l.weight));
    }
    if !(0.0..1.0).contains(&l.threshold) {
        return Err(format!("`{path}.threshold` must be in [0, 1), got {}", l.threshold));
    }
    Ok(())
}

/// The JSON Schema of [`ReconConfig`] (`simbench schema recon-config`).
pub fn json_schema() -> serde_json::Value {
    serde_json::to_value(schemars::schema_for!(ReconConfig)).expect("the schema serialises")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_round_trip_through_json() {
        for p in Preset::ALL {
            let c = p.config();
            let back = ReconConfig::from_json(&c.to_json(), "test").expect("parses");
            assert_eq!(back, c, "{}", p.name());
            assert_eq!(Preset::from_name(p.name()).expect("known"), p);
        }
        assert_ne!(Preset::Paper.config(), Preset::CalibratedLamps.config());
    }

    #[test]
    fn missing_keys_take_the_papers_defaults() {
        let c = ReconConfig::from_json(r#"{"shape": {"iterations": 7}}"#, "test").expect("parses");
        assert_eq!(c.shape.iterations, 7);
        assert_eq!(
            ReconConfig { shape: ShapeConfig { iterations: 200, ..c.shape.clone() }, ..c },
            ReconConfig::default()
        );
    }

    #[test]
    fn unknown_keys_and_bad_values_name_their_path() {
        let e = ReconConfig::from_json(r#"{"shape": {"iteratons": 7}}"#, "cfg.json").unwrap_err().to_string();
        assert!(e.contains("cfg.json") && e.contains("shape") && e.contains("iteratons"), "{e}");
        let e = ReconConfig::from_json(r#"{"stage1": {"stencil": "round"}}"#, "cfg.json").unwrap_err().to_string();
        assert!(e.contains("stage1.stencil"), "{e}");
        let e = ReconConfig::from_json(r#"{"shape": {"learning_rate_m": -1}}"#, "cfg.json").unwrap_err().to_string();
        assert!(e.contains("shape.learning_rate_m"), "{e}");
        assert!(Preset::from_name("fast").unwrap_err().to_string().contains("paper, calibrated-lamps"));
    }

    /// A start factor of the mode fit that is not positive is refused with the configuration,
    /// before any data are read.
    #[cfg(feature = "experimental")]
    #[test]
    fn mode_starts_must_be_positive() {
        let json = |starts: &str| {
            format!(
                r#"{{"input": {{"diffusivity_m2_per_s": 1e-7}}, "experimental": {{"output_error": {{"mode_starts": {starts}}}}}}}"#
            )
        };
        let e = ReconConfig::from_json(&json("[1.0, 0.0]"), "cfg.json").unwrap_err().to_string();
        assert!(e.contains("experimental.output_error.mode_starts"), "{e}");
        assert!(ReconConfig::from_json(&json("[0.8, 1.25]"), "cfg.json").is_ok());
    }

    #[test]
    fn set_changes_one_value_and_refuses_missing_keys() {
        let mut c = ReconConfig::default();
        c.set("shape.iterations", "300").expect("set");
        c.set("shape.optimizer", "adam_uniform").expect("set");
        c.set("stage1.known", r#"{"convection": 5.0}"#).expect("set");
        c.set("input.diffusivity_m2_per_s", "1.2e-7").expect("set");
        assert_eq!(c.shape.iterations, 300);
        assert_eq!(c.shape.optimizer, Optimizer::AdamUniform);
        assert_eq!(c.stage1.known, Known::Convection(5.0));
        assert_eq!(c.input.diffusivity_m2_per_s, Some(1.2e-7));
        let before = c.clone();
        for (path, value, expected) in [
            ("shape.iteration", "3", "no key `shape.iteration`"),
            ("shape.iterations.x", "3", "`shape.iterations` is not a section"),
            ("shape.iterations", "many", "shape.iterations"),
            ("shape.optimizer", "newton", "shape.optimizer"),
        ] {
            let e = c.set(path, value).unwrap_err().to_string();
            assert!(e.contains(expected), "{path}={value}: {e}");
            assert_eq!(c, before, "a refused --set changes nothing");
        }
    }

    #[test]
    fn schema_documents_the_fields() {
        let s = json_schema().to_string();
        for key in ["diffusivity_m2_per_s", "lamp_shading", "halfspace_threshold", "m^2/s"] {
            assert!(s.contains(key), "{key} missing from the schema");
        }
    }
}
