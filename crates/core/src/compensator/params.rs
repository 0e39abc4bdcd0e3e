//! Parameters of the compensators (`[compensator]` in a scenario), with units, defaults that
//! work for every preset, and valid ranges.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// How the measurement delay `τ_p` is compensated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum DelayMode {
    /// Identify against the kinematics from `τ_p` earlier and predict the present force from
    /// the identified model (robust to sensor noise; the default).
    #[default]
    Align,
    /// The paper's eq. (6): the lead `F_act = F_mea + τ_p·dF_mea/dt` (differentiates noise).
    Lead,
}

/// How the energy observer sums the port's energy (see the energy module).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ObserverMode {
    /// The work of the wrench held over each step (exact for the virtual dynamics; default).
    #[default]
    Work,
    /// Eqs. (15), (16) as printed.
    Paper,
}

/// How the energy controller spreads the dissipation over the axes (see the energy module).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ControllerMode {
    /// One damping along the contact direction, dissipating exactly the deficit, its force
    /// bounded by `force_ratio_max` times the contact force (sound in 6-DOF; default).
    #[default]
    Normal,
    /// Eqs. (18), (19) as printed: the deficit split per axis by `|F_ek,i| / |F_ek|` and one
    /// damping per axis (dissipates up to √3 times the deficit on oblique contacts, and an
    /// axis with little velocity calls for a huge force).
    Paper,
}

/// Parameters of the identification-based compensators `pic`, `dac`, `pida`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ModelParams {
    /// Measurement-delay compensation: `align` or `lead`.
    pub delay_mode: DelayMode,
    /// In contact while the force magnitude exceeds this, N (> 0, <= 1e6; above the noise).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e6))]
    pub contact_force: f64,
    /// Initial stiffness estimate k̂₀, N/m (> 0, <= 1e11).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e11))]
    pub stiffness_initial: f64,
    /// Initial damping estimate ĉ₀, N·s/m (>= 0, <= 1e9).
    #[schemars(range(min = 0.0, max = 1e9))]
    pub damping_initial: f64,
    /// Initial standard deviation of k̂ (√P₀₀), N/m (> 0, <= 1e11).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e11))]
    pub stiffness_std: f64,
    /// Initial standard deviation of ĉ (√P₁₁), N·s/m (> 0, <= 1e9).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e9))]
    pub damping_std: f64,
    /// Random walk of k per update (√Q₀₀), N/m (>= 0, <= 1e11).
    #[schemars(range(min = 0.0, max = 1e11))]
    pub stiffness_walk: f64,
    /// Random walk of c per update (√Q₁₁), N·s/m (>= 0, <= 1e9).
    #[schemars(range(min = 0.0, max = 1e9))]
    pub damping_walk: f64,
    /// Initial measurement noise of a force increment (√R₀), N (> 0, <= 1e6).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e6))]
    pub noise_std: f64,
    /// Forgetting factor b of the Sage-Husa noise estimate (0 < b < 1).
    #[schemars(extend("exclusiveMinimum" = 0.0, "exclusiveMaximum" = 1.0))]
    pub forgetting: f64,
    /// Largest amendment damping α of the energy controller, N·s/m (> 0, <= 1e12).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e12))]
    pub alpha_max: f64,
    /// Energy observer: `work` or `paper`.
    pub observer: ObserverMode,
    /// Energy controller: `normal` or `paper`.
    pub controller: ControllerMode,
    /// Largest amendment force of the `normal` controller, as a multiple of the compensated
    /// contact force `|F_comp|` (and at least of `contact_force`) (> 0, <= 1e6); what it cannot
    /// dissipate in one tick is carried to the next.
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e6))]
    pub force_ratio_max: f64,
    /// `pic` only: `F_comp = F_act + F_err` exactly as eq. (22) writes it, pulling the virtual
    /// body when `F_err` outweighs `F_act` (the virtual rod tip has left the wall while the
    /// lagging robot still presses); `false`, the default: clamped at zero, never pulling.
    pub pull: bool,
}

impl Default for ModelParams {
    fn default() -> Self {
        ModelParams {
            delay_mode: DelayMode::Align,
            contact_force: 3.0,
            stiffness_initial: 1.0e5,
            damping_initial: 0.0,
            stiffness_std: 1.0e5,
            damping_std: 300.0,
            stiffness_walk: 10.0,
            damping_walk: 0.1,
            noise_std: 0.1,
            forgetting: 0.98,
            alpha_max: 100000.0,
            observer: ObserverMode::Work,
            controller: ControllerMode::Normal,
            force_ratio_max: 2.0,
            pull: false,
        }
    }
}

/// Parameters of the TDPA baselines.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TdpaParams {
    /// In contact while the force magnitude exceeds this, N (> 0, <= 1e6); the observer's window
    /// is each exchange with the wall (a windowed observer).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e6))]
    pub contact_force: f64,
    /// Largest damping α of the impedance-type controller, N·s/m (> 0, <= 1e12).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e12))]
    pub alpha_max: f64,
    /// Largest admittance β of the admittance-type controller: its velocity change along the
    /// force at most β·|f|, m/(N·s) (> 0, <= 1e3).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e3))]
    pub beta_max: f64,
    /// Floor on |v| in the impedance controller's division, m/s (> 0, <= 1e3).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e3))]
    pub velocity_floor: f64,
    /// The admittance controller acts only above this force magnitude, N (> 0, <= 1e6).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e6))]
    pub force_floor: f64,
}

impl Default for TdpaParams {
    fn default() -> Self {
        TdpaParams {
            contact_force: 3.0,
            alpha_max: 100000.0,
            beta_max: 1e-4,
            velocity_floor: 1e-3,
            force_floor: 1.0,
        }
    }
}

/// Which contact law `model-mediated` identifies and renders.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum LawForm {
    /// Linear spring-damper `f = k·d + c·ḋ` (eq. 5).
    Linear,
    /// Hunt-Crossley `f = dⁿ·(k + c·ḋ)`, the exponent identified too.
    HuntCrossley,
    /// Both fitted at each contact; Hunt-Crossley is kept when it explains the force clearly
    /// better (residual below 0.7 of the linear fit's) (default).
    #[default]
    Auto,
}

/// What `model-mediated` takes of the scenario's shapes (`[[servicer.shapes]]`,
/// `[[target.shapes]]`) as prior geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum PriorShapes {
    /// Nothing: the shapes' contacts are fitted as planes at the rod tip, or `pida`'s (default).
    #[default]
    None,
    /// Their nominal geometry: the contact between the servicer's and the target's shapes is
    /// rendered at the virtual pose by the engine's shape query, with the calibration's law
    /// (`compensator.calibration`) or else the law identified from the first contact (that one
    /// `pida`'s), and `prior_friction` until a contact identifies μ̂.
    Geometry,
    /// Their nominal geometry and the scenario's contact law and friction (`[contact]`, the
    /// law the hardware is stated to have): rendered from the first contact, kept as given.
    GeometryAndLaw,
}

/// Parameters of the `model-mediated` compensator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ModelMediatedParams {
    /// The contact law to identify: `linear`, `hunt-crossley` or `auto`.
    pub law: LawForm,
    /// Prior contact geometry (a CAD model), in the `[[walls]]` format: each surface the rod may
    /// touch, its point (m) and its normal into free space, target frame. It may be off by
    /// millimetres and degrees: each contact corrects it. Empty: every surface is learned at
    /// its first contact.
    #[schemars(length(max = 8))]
    pub prior_walls: Vec<crate::contact::WallConfig>,
    /// Whether contacts correct the prior walls' geometry (true), or the priors are rendered as
    /// given (false; the law is identified all the same, and surfaces without a prior learned).
    pub correct_priors: bool,
    /// Prior Coulomb friction coefficient (0 to 2; default 0: none): rendered on the prior and
    /// calibrated surfaces until a contact identifies their own (a calibration has none).
    #[schemars(range(min = 0.0, max = 2.0))]
    pub prior_friction: f64,
    /// The scenario's shapes as prior geometry: `none` (default), `geometry` (the shapes'
    /// nominal geometry, the law identified or the calibration's) or `geometry-and-law` (also
    /// the scenario's contact law and friction); see [`PriorShapes`]. A scenario without shapes
    /// refuses anything but `none`.
    pub prior_shapes: PriorShapes,
    /// A calibration of the hardware (`hilcontact calibrate`, the calibration file's tables;
    /// `--calibration FILE`): its walls and law are rendered from the very first contact, trusted
    /// as far as their uncertainties say; a contact that contradicts them corrects them. Without
    /// walls (the default): none.
    pub calibration: crate::calibration::CalibrationFile,
    /// Largest angle between a contact's force and a surface's normal for the contact to
    /// belong to that surface, degrees (> 0, <= 90).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 90.0))]
    pub match_angle: f64,
    /// How far the robot's rod tip may still be from a modelled surface (m) when a force
    /// appears for the contact to count as that surface's (the model renders it; the surface's
    /// error shows in the peak force); farther, the model does not explain the contact and
    /// `pida` handles it (>= 0, <= 1).
    #[schemars(range(min = 0.0, max = 1.0))]
    pub gap_tolerance: f64,
    /// Fewest samples in contact for a contact to update a surface (>= 3, <= 1e6).
    #[schemars(range(min = 3, max = 1_000_000))]
    pub min_samples: u32,
    /// Samples of one contact kept for its fit; memory allocated once (>= 16, <= 1e7; 20000:
    /// 20 s of contact at 1 kHz, 1 MB).
    #[schemars(range(min = 16, max = 10_000_000))]
    pub max_samples: u32,
    /// Weight of a surface's past contacts against a new one, in samples (>= 0, <= 1e9): the
    /// estimate is the sample-weighted mean of the past (weight at most this) and the new fit.
    #[schemars(range(min = 0, max = 1_000_000_000))]
    pub memory: u32,
    /// Share of the residual fed back into the virtual dynamics (0 to 1; default 0, the model
    /// alone): 1 corrects the force level of a wrong model, but late by the loop's delay, which
    /// loses more rebound than it saves (docs/compensators/model-mediated.md).
    #[schemars(range(min = 0.0, max = 1.0))]
    pub residual_gain: f64,
    /// Largest damping force of the residual's energy controller, as a multiple of the force
    /// applied (and at least of `fallback.contact_force`) (> 0, <= 1e6).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e6))]
    pub force_ratio_max: f64,
    /// Contact detection, and the `pida` that handles contacts the model does not explain
    /// (every contact before the first is identified), `[compensator.fallback]`.
    pub fallback: ModelParams,
}

impl Default for ModelMediatedParams {
    fn default() -> Self {
        ModelMediatedParams {
            law: LawForm::Auto,
            prior_walls: Vec::new(),
            correct_priors: true,
            prior_friction: 0.0,
            prior_shapes: PriorShapes::None,
            calibration: crate::calibration::CalibrationFile::default(),
            match_angle: 30.0,
            gap_tolerance: 1e-3,
            min_samples: 20,
            max_samples: 20_000,
            memory: 2_000,
            residual_gain: 0.0,
            force_ratio_max: 2.0,
            fallback: ModelParams::default(),
        }
    }
}
