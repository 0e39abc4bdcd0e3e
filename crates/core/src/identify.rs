//! Offline identification of a recording's contacts: per collision, the stiffness k and
//! damping c, and the contact surface (a plane: a point and its normal), each with an
//! uncertainty.
//!
//! k and c come from the compensators' own front end ([`ContactEstimator`]: the noise-aware
//! detector, the sensor-delay handling of `delay_mode`, the Sage-Husa filter of eqs. (8)-(13)),
//! run over the whole recording; its filter is restarted (back to `k̂₀`, `ĉ₀`, `P₀`) at the
//! start of each collision, so that each collision is identified on its own.
//!
//! Their uncertainties are not the filter's `√P` (which assumes white increment noise of the
//! variance R and a random walk of k and c, and overstated the error: every one of 500 noisy
//! collisions of `crates/core/tests/identification.rs` was within its 1σ). The filter's final
//! estimate is linear in its measurements: with the gains `K_t` and rows `H_t` of the
//! collision's N updates, `X_N = Φ·X₀ + Σ W_t·Z_t`, `Φ = Π(I − K_t·H_t)`,
//! `W_t = Π_{s>t}(I − K_s·H_s)·K_t`, and since `Φ + Σ W_t·H_t = I` its error is
//! `Φ·(X₀ − X) + Σ W_t·n_t`, `n_t = Z_t − H_t·X`. [`increment_covariance`] states its mean
//! squared error from that: the initial guess's pull and the noise, the latter from the
//! residuals taken back to force levels (a white force noise makes the increments' lag-1
//! autocorrelation −½; their weighted sum telescopes).
//!
//! The surface, from where the force begins and its direction. The force on the frame points
//! into the wall (`e = F/|F|`, eq. 7), so the wall normal (into free space) is `n = −ē`, `ē`
//! the direction of the collision's summed force; its uncertainty is the standard error of the
//! samples' angles to `ē`. With the sample's tip position `p` and velocity `v` (those that
//! produced the force: `τ_p` earlier for `align`), the linear law `F·ē = k·d + c·ḋ` with
//! `d = (p − p_w)·ē`, `ḋ = v·ē` gives the plane's offset of each sample,
//! `p_w·ē = p·ē − (F·ē − ĉ·v·ē)/k̂`; the offset is their mean, its uncertainty the standard
//! error combined with that of `k̂` and `ĉ`. The point is the tip at the first contact sample
//! projected on the plane.

use nalgebra::{Matrix2, UnitQuaternion, Vector2, Vector3};

use crate::compensator::detect::ON_SIGMAS;
use crate::compensator::surface::{SurfaceFit, SLIDE_SPEED};
use crate::compensator::{
    CompensatorConfig, CompensatorContext, ContactEstimator, DelayMode, ModelParams,
};
use crate::error::RecordingError;
use crate::hil::compensator_context;
use crate::plan::Plan;
use crate::replay::Recording;
use crate::sim::Table;

/// The forgetting factor b of the noise estimate (eq. 13) that offline identification uses
/// by default (`hilcontact identify --forgetting`). The compensators' 0.98 averages the noise
/// over about 50 updates, so the large `H·P⁻·Hᵀ` of the first updates (P₀ is wide) keeps R,
/// and so the gain on ĉ, high for a whole collision: measured on a damped oblique-6dof run
/// without noise, ĉ = 116 ± 101 N·s/m for c = 130 at 0.98, 129.5 ± 18.8 at 0.9, 130.00 ± 0.7
/// at 0.5. 0.9 keeps about 10 updates, still averaging a noisy sensor's increments.
pub const OFFLINE_FORGETTING: f64 = 0.9;

/// Lags of the level residuals' autocovariance in [`increment_covariance`] (Bartlett
/// weights): 0 would take the force noise as white; a few cover a sensor's own filter.
pub const RESIDUAL_LAGS: usize = 3;

/// One filter update of a collision: its row `H = [Δd, Δḋ]`, measurement `Z = ΔF` and gain K.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Update {
    /// `H = [Δd, Δḋ]`, m and m/s.
    pub h: Vector2<f64>,
    /// `Z = ΔF`, N.
    pub z: f64,
    /// The filter's gain K of this update.
    pub gain: Vector2<f64>,
}

/// The mean squared error (a 2×2 matrix) of a filter's final estimate `x` after `updates`
/// (consecutive ticks) from the initial guess `x0` (see the module's doc): the initial guess's
/// pull `b·bᵀ`, `b = Φ·(x0 − X)` with the truth `X` estimated as `x − b` (so
/// `b = Φ·(I − Φ)⁻¹·(x0 − x)`, infinite when the updates leave a parameter unobserved), and
/// the noise's covariance. An update's noise is the
/// difference of two levels' noises, `n_t = ε_t − ε_{t−1}`, so by parts `Σ W_t·n_t = Σ D_t·ε_t`
/// with `D_t = W_t − W_{t+1}` (`W` zero past the last, `−W₁` on the level before the first),
/// and the noise's covariance is `Σ_a Σ_b D_a·D_bᵀ·γ(|a − b|)`, `γ` the autocovariance (Bartlett
/// weights up to `lags`) of the level residuals: the running sum of `Z_t − H_t·x` less its
/// least-squares fit by a constant and the running sums of `H` (a constant error of `x`).
/// Taken by levels, white noise gives no difference of large numbers (the increments' lag-1
/// autocorrelation of −½ cancels what lag 0 adds).
pub fn increment_covariance(
    updates: &[Update],
    x: &Vector2<f64>,
    x0: &Vector2<f64>,
    lags: usize,
) -> Matrix2<f64> {
    segmented_covariance(updates, &[], x, x0, lags)
}

/// [`increment_covariance`] of updates made over several contacts: `breaks` are the indices
/// of the updates that start a new run of consecutive levels (a new collision: its first
/// increment shares no level with the one before). Each run's levels get their own
/// coefficients, residuals and fit (a constant per run); the residuals' autocovariance is
/// pooled over the runs, and the runs' noises are independent.
pub fn segmented_covariance(
    updates: &[Update],
    breaks: &[usize],
    x: &Vector2<f64>,
    x0: &Vector2<f64>,
    lags: usize,
) -> Matrix2<f64> {
    let n = updates.len();
    // W_t backwards, and Φ
    let mut weights = vec![Vector2::zeros(); n];
    let mut m = Matrix2::identity();
    for (t, u) in updates.iter().enumerate().rev() {
        weights[t] = m * u.gain;
        m *= Matrix2::identity() - u.gain * u.h.transpose();
    }
    // the pull of the initial guess: x − X = Φ·(x0 − X) + noise, so X ≈ x − Φ·(I − Φ)⁻¹·(x0 − x)
    let bias = (Matrix2::identity() - m)
        .try_inverse()
        .map_or(Vector2::repeat(f64::INFINITY), |inverse| {
            m * inverse * (x0 - x)
        });
    if n < 4 {
        return bias * bias.transpose();
    }
    // the runs of consecutive levels
    let mut starts: Vec<usize> = std::iter::once(0)
        .chain(breaks.iter().copied().filter(|&b| b > 0 && b < n))
        .collect();
    starts.sort_unstable();
    starts.dedup();
    let ends: Vec<usize> = starts.iter().skip(1).copied().chain([n]).collect();
    // per run: its levels' coefficients and residuals (less the fit by a constant and the
    // running sums of H)
    let mut runs: Vec<(Vec<Vector2<f64>>, Vec<f64>)> = Vec::new();
    for (&from, &to) in starts.iter().zip(&ends) {
        let w = &weights[from..to];
        let coefficient: Vec<Vector2<f64>> = std::iter::once(-w[0])
            .chain(
                (0..w.len()).map(|t| w[t] - w.get(t + 1).copied().unwrap_or_else(Vector2::zeros)),
            )
            .collect();
        let mut level = vec![0.0; w.len() + 1];
        let mut sums = vec![Vector3::zeros(); w.len() + 1];
        sums[0] = Vector3::new(1.0, 0.0, 0.0);
        for (t, u) in updates[from..to].iter().enumerate() {
            level[t + 1] = level[t] + (u.z - u.h.dot(x));
            sums[t + 1] = sums[t] + Vector3::new(0.0, u.h[0], u.h[1]);
        }
        let normal: nalgebra::Matrix3<f64> = sums.iter().map(|s| s * s.transpose()).sum();
        let right: Vector3<f64> = sums.iter().zip(&level).map(|(s, e)| s * *e).sum();
        if let Some(fit) = normal.try_inverse().map(|inverse| inverse * right) {
            level
                .iter_mut()
                .zip(&sums)
                .for_each(|(e, s)| *e -= s.dot(&fit));
        }
        runs.push((coefficient, level));
    }
    let levels: usize = runs.iter().map(|(_, l)| l.len()).sum();
    let dof = levels.saturating_sub(3 * runs.len()).max(1) as f64;
    let lags = lags.min(n);
    let mut noise = Matrix2::zeros();
    for l in 0..=lags {
        let gamma = runs
            .iter()
            .map(|(_, level)| {
                (0..level.len().saturating_sub(l))
                    .map(|a| level[a] * level[a + l])
                    .sum::<f64>()
            })
            .sum::<f64>()
            / dof;
        let bartlett = 1.0 - l as f64 / (lags as f64 + 1.0);
        for (coefficient, _) in &runs {
            for a in 0..coefficient.len().saturating_sub(l) {
                let term = coefficient[a] * coefficient[a + l].transpose();
                noise += if l == 0 {
                    term
                } else {
                    term + term.transpose()
                } * (gamma * bartlett);
            }
        }
    }
    noise[(0, 0)] = noise[(0, 0)].max(0.0);
    noise[(1, 1)] = noise[(1, 1)].max(0.0);
    bias * bias.transpose() + noise
}

/// The filter's estimate after `updates` from `x0`, from their gains alone:
/// `X = X⁻ + K·(Z − H·X⁻)` per update (what [`increment_covariance`] takes the estimate to be).
pub fn linear_estimate(updates: &[Update], x0: &Vector2<f64>) -> Vector2<f64> {
    updates
        .iter()
        .fold(*x0, |x, u| x + u.gain * (u.z - u.h.dot(&x)))
}

/// One collision's identified contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CollisionIdentification {
    /// Number of the collision, from 1.
    pub index: usize,
    /// Time of its first contact sample, s.
    pub start: f64,
    /// Time of its last contact sample, s.
    pub end: f64,
    /// Number of contact samples.
    pub samples: usize,
    /// Filter updates made on it (eqs. 11-13).
    pub updates: u32,
    /// Identified stiffness k̂, N/m.
    pub stiffness: f64,
    /// Its standard deviation ([`increment_covariance`]), N/m.
    pub stiffness_std: f64,
    /// Identified damping ĉ, N·s/m.
    pub damping: f64,
    /// Its standard deviation ([`increment_covariance`]), N·s/m.
    pub damping_std: f64,
    /// Wall normal n (into free space, unit), `t`.
    pub normal: Vector3<f64>,
    /// Angular uncertainty of n, rad.
    pub normal_std: f64,
    /// A point of the wall (the first contact, on the plane), `t`, m.
    pub point: Vector3<f64>,
    /// Uncertainty of the plane's position along n, m.
    pub offset_std: f64,
    /// Peak measured force magnitude, N.
    pub peak_force: f64,
    /// Whether the surface is frictional: its fitted normal leans from the mean force by more
    /// than `atan FRICTION_MIN` ([`crate::compensator::surface`]). Then `normal` is the fitted
    /// one, and `stiffness`, `damping` the least squares of the normal law along it over the
    /// collision's samples (the filter's first updates, before the normal was known, lean).
    pub frictional: bool,
    /// Identified friction coefficient μ̂ (0 when frictionless or nothing slid): the least
    /// squares of `F_t·ŝ = μ·F_n` over the samples sliding faster than `SLIDE_SPEED`.
    pub friction: f64,
    /// Its standard error.
    pub friction_std: f64,
    /// Number of sliding samples μ̂ rests on.
    pub sliding_samples: usize,
}

/// What [`identify`] gives: per tick and per collision.
#[derive(Debug, Clone, PartialEq)]
pub struct Identification {
    /// Per tick: `time` (s), `in_contact` (1 or 0), `stiffness_estimate` (N/m),
    /// `stiffness_std` (N/m), `damping_estimate` (N·s/m), `damping_std` (N·s/m); the stds
    /// per tick are the filter's `√P` (the running estimate's own view; per collision the
    /// stated ones are [`CollisionIdentification`]'s).
    pub timeseries: Table,
    /// Per collision.
    pub collisions: Vec<CollisionIdentification>,
    /// Per collision, the filter updates its estimate is made of (from its restart to its
    /// last contact tick), whose gains state its uncertainty ([`increment_covariance`]).
    pub updates: Vec<Vec<Update>>,
}

/// The identification parameters of a compensator config: its own for `pic`, `dac`, `pida`,
/// the defaults for the others.
pub fn model_params(config: &CompensatorConfig) -> ModelParams {
    match config {
        CompensatorConfig::Pic(p) | CompensatorConfig::Dac(p) | CompensatorConfig::Pida(p) => {
            p.clone()
        }
        _ => ModelParams::default(),
    }
}

/// Identifies the contacts of `recording` (the desired tip is not used) with the front end of
/// `params` built with `context`; `sensor_to_t` is the sensor's attitude in `t`.
pub fn identify(
    params: &ModelParams,
    context: &CompensatorContext,
    sensor_to_t: &UnitQuaternion<f64>,
    recording: &Recording<'_>,
) -> Result<Identification, RecordingError> {
    recording.check()?;
    let n = recording.len();
    let mut estimator = ContactEstimator::new(params, context);
    let lag = match params.delay_mode {
        DelayMode::Align => context.sensor_delay_ticks,
        DelayMode::Lead => 0,
    };
    let mut contact = vec![0.0; n];
    let mut k_hat = vec![0.0; n];
    let mut k_std = vec![0.0; n];
    let mut c_hat = vec![0.0; n];
    let mut c_std = vec![0.0; n];
    // (first, last) contact tick of each collision
    let mut spans: Vec<(usize, usize)> = Vec::new();
    let mut updates: Vec<u32> = Vec::new();
    // each collision's filter updates (tick, update), to state the uncertainty
    let mut logs: Vec<Vec<(usize, Update)>> = Vec::new();
    // each collision's surface fit at its last contact tick
    let mut fits: Vec<SurfaceFit> = Vec::new();
    let mut previous = false;
    for k in 0..n {
        let before = estimator.filter.t;
        let view = estimator.step(&recording.input(k, sensor_to_t));
        if estimator.filter.t != before && k > 0 {
            if let (Some(log), Some((h, z))) = (logs.last_mut(), estimator.last_update()) {
                log.push((
                    k,
                    Update {
                        h,
                        z,
                        gain: estimator.filter.k,
                    },
                ));
            }
        }
        if view.in_contact && !previous {
            // a new collision: identified on its own from its second sample on
            estimator.filter.reset();
            spans.push((k, k));
            updates.push(0);
            fits.push(SurfaceFit::default());
            logs.push(Vec::new());
        }
        if view.in_contact {
            if let (Some(span), Some(u)) = (spans.last_mut(), updates.last_mut()) {
                span.1 = k;
                *u = estimator.filter.t;
            }
            if let Some(fit) = fits.last_mut() {
                *fit = *estimator.surface().0;
            }
        }
        previous = view.in_contact;
        let f = &estimator.filter;
        contact[k] = f64::from(u8::from(view.in_contact));
        k_hat[k] = f.x[0];
        c_hat[k] = f.x[1];
        k_std[k] = f.p[(0, 0)].max(0.0).sqrt();
        c_std[k] = f.p[(1, 1)].max(0.0).sqrt();
    }

    let force = |k: usize| {
        let c = &recording.measured_force;
        sensor_to_t * Vector3::new(c[0][k], c[1][k], c[2][k])
    };
    let kinematics = |k: usize| {
        let j = k.saturating_sub(lag);
        let (p, v) = (
            &recording.actual_tip_position,
            &recording.actual_tip_velocity,
        );
        (
            Vector3::new(p[0][j], p[1][j], p[2][j]),
            Vector3::new(v[0][j], v[1][j], v[2][j]),
        )
    };
    let x0 = Vector2::new(params.stiffness_initial, params.damping_initial);
    let made: Vec<Vec<Update>> = spans
        .iter()
        .zip(&logs)
        .map(|(&(_, last), log)| {
            log.iter()
                .filter(|(k, _)| *k <= last)
                .map(|(_, u)| *u)
                .collect()
        })
        .collect();
    // the same updates less the bias of projecting on the noisy direction F/|F| (align only:
    // lead's force is a difference, its noise another)
    let variance = match params.delay_mode {
        DelayMode::Align => force_noise_variance(recording, &spans),
        DelayMode::Lead => 0.0,
    };
    // the force above which a level's noise is not truncated by the detector's thresholds
    let sigma = variance.sqrt();
    let band = params.contact_force.max(ON_SIGMAS * sigma) + TRUNCATION_SIGMAS * sigma;
    let unbiased: Vec<Vec<Update>> = spans
        .iter()
        .zip(&logs)
        .map(|(&(_, last), log)| {
            let log: Vec<(usize, Update)> =
                log.iter().filter(|(k, _)| *k <= last).copied().collect();
            // both levels of an update (its sample and the one before) above the band
            let clear = |j: usize| {
                let before = if j == 0 {
                    log[0].0.saturating_sub(1)
                } else {
                    log[j - 1].0
                };
                force(log[j].0).norm() > band && force(before).norm() > band
            };
            let from = (0..log.len()).find(|&j| clear(j)).unwrap_or(log.len());
            let to = (from..log.len())
                .rev()
                .find(|&j| clear(j))
                .map_or(from, |j| j + 1);
            log[from..to]
                .iter()
                .map(|&(k, u)| Update {
                    z: u.z - direction_bias(variance, force(k).norm()),
                    ..u
                })
                .collect()
        })
        .collect();
    let collisions = spans
        .iter()
        .zip(&updates)
        .enumerate()
        .map(|(i, (&(first, last), &u))| {
            // without noise, the filter's own estimate; with noise, its gains over the
            // updates clear of the thresholds, less the direction bias
            let (stiffness, damping, used) = if variance > 0.0 {
                let x = linear_estimate(&unbiased[i], &x0);
                (x[0], x[1], &unbiased[i])
            } else {
                (k_hat[last], c_hat[last], &made[i])
            };
            let cov =
                increment_covariance(used, &Vector2::new(stiffness, damping), &x0, RESIDUAL_LAGS);
            // no update: the initial guess and its prior
            let (sk, sc) = if made[i].is_empty() {
                (params.stiffness_std, params.damping_std)
            } else {
                (cov[(0, 0)].sqrt(), cov[(1, 1)].sqrt())
            };
            let count = (last - first + 1) as f64;
            let total: Vector3<f64> = (first..=last).map(force).sum();
            let fit = &fits[i];
            let frictional = fit.leans();
            let (stiffness, damping, sk, sc) = match (frictional, fit.law(&fit.normal().0)) {
                (true, Some(((k, c), (sk, sc)))) => (k, c, sk, sc),
                _ => (stiffness, damping, sk, sc),
            };
            let e = if frictional {
                fit.normal().0
            } else {
                total.normalize()
            };
            let (friction, friction_std, sliding_samples) = if frictional {
                friction_fit(&e, (first..=last).map(|k| (force(k), kinematics(k).1)))
            } else {
                (0.0, 0.0, 0)
            };
            let peak_force = (first..=last).map(|k| force(k).norm()).fold(0.0, f64::max);
            // angles of the samples' force to ē
            let angle2: f64 = (first..=last)
                .map(|k| force(k).normalize().dot(&e).clamp(-1.0, 1.0).acos().powi(2))
                .sum();
            let normal_std = if frictional {
                fit.normal().1
            } else {
                (angle2 / count).sqrt() / count.sqrt()
            };
            // the plane's offset along ē from each sample
            let offset_of = |k: usize| {
                let (p, v) = kinematics(k);
                let penetration = (force(k).dot(&e) - damping * v.dot(&e)) / stiffness;
                (p.dot(&e) - penetration, penetration, v.dot(&e))
            };
            let (mut sum, mut sum2, mut pen, mut rate) = (0.0, 0.0, 0.0, 0.0);
            for k in first..=last {
                let (o, d, r) = offset_of(k);
                sum += o;
                sum2 += o * o;
                pen += d.abs();
                rate += r.abs();
            }
            let offset = sum / count;
            let spread = (sum2 / count - offset * offset).max(0.0).sqrt();
            let from_k = pen / count * sk / stiffness;
            let from_c = rate / count * sc / stiffness;
            let offset_std = ((spread * spread) / count + from_k * from_k + from_c * from_c).sqrt();
            let (p_first, _) = kinematics(first);
            CollisionIdentification {
                index: i + 1,
                start: recording.time[first],
                end: recording.time[last],
                samples: last - first + 1,
                updates: u,
                stiffness,
                stiffness_std: sk,
                damping,
                damping_std: sc,
                normal: -e,
                normal_std,
                point: p_first - e * (p_first.dot(&e) - offset),
                offset_std,
                peak_force,
                frictional,
                friction,
                friction_std,
                sliding_samples,
            }
        })
        .collect();
    let names = [
        "time",
        "in_contact",
        "stiffness_estimate",
        "stiffness_std",
        "damping_estimate",
        "damping_std",
    ];
    let values = [recording.time.to_vec(), contact, k_hat, k_std, c_hat, c_std];
    Ok(Identification {
        timeseries: Table {
            columns: names.iter().map(|s| s.to_string()).zip(values).collect(),
        },
        collisions,
        updates: made,
    })
}

/// The updates' rows and measurements with the gains of the filter of `params` (eqs. 11-12:
/// `P₀`, the walk Q) at a fixed measurement noise `r`, N² (eq. 13's adaptation off): then each
/// gain no longer depends on its own innovation, and the estimate is linear in the
/// measurements.
pub fn fixed_gain_replay(updates: &[Update], params: &ModelParams, r: f64) -> Vec<Update> {
    let mut p = Matrix2::from_diagonal(&Vector2::new(
        params.stiffness_std.powi(2),
        params.damping_std.powi(2),
    ));
    let q = Matrix2::from_diagonal(&Vector2::new(
        params.stiffness_walk.powi(2),
        params.damping_walk.powi(2),
    ));
    updates
        .iter()
        .map(|u| {
            let prior = p + q;
            let gain = prior * u.h / (u.h.dot(&(prior * u.h)) + r);
            let i_kh = Matrix2::identity() - gain * u.h.transpose();
            p = i_kh * prior * i_kh.transpose() + gain * r * gain.transpose();
            Update { gain, ..*u }
        })
        .collect()
}

/// A collision's first and last updates whose force is within this many noise standard
/// deviations above the detector's thresholds are left out of the noisy case's estimate: the
/// detector keeps a contact only while its noisy force is above the threshold, so the noise of
/// the levels near it is truncated (not zero-mean), which biased k̂ low by about 0.3 σ.
pub const TRUNCATION_SIGMAS: f64 = 3.0;

/// Ticks on either side of a collision left out of [`force_noise_variance`] (the force's
/// rise and fall below the detector's threshold).
pub const NOISE_MARGIN: usize = 50;

/// The force sensor's noise variance per axis σ², N², of a recording whose collisions span
/// `spans` (first, last tick): the variance about their mean of the force samples more than
/// [`NOISE_MARGIN`] ticks from every collision, averaged over the three axes (0 with fewer
/// than 10 such samples: no correction).
pub fn force_noise_variance(recording: &Recording<'_>, spans: &[(usize, usize)]) -> f64 {
    let n = recording.len();
    let free = |k: usize| {
        spans
            .iter()
            .all(|&(a, b)| k + NOISE_MARGIN < a || k > b + NOISE_MARGIN)
    };
    let ticks: Vec<usize> = (0..n).filter(|&k| free(k)).collect();
    if ticks.len() < 10 {
        return 0.0;
    }
    let count = ticks.len() as f64;
    recording
        .measured_force
        .iter()
        .map(|axis| {
            let mean = ticks.iter().map(|&k| axis[k]).sum::<f64>() / count;
            ticks.iter().map(|&k| (axis[k] - mean).powi(2)).sum::<f64>() / (count - 1.0)
        })
        .sum::<f64>()
        / 3.0
}

/// The mean bias, N, of an increment `ΔF·e` projected on the noisy direction `e = F/|F|` of
/// the later sample (eqs. 7-8), for a white force noise of variance σ² per axis and a force
/// of magnitude `force` (N): `F_t·e_t = |F_t|` gains `|ε⊥|²/(2|F|)`, on average `σ²/|F|`
/// (the noise across the force, two axes), and `F_{t−1}·e_t` loses as much (`e_t` leans
/// from `F_{t−1}` by the angle `|ε⊥|/|F|`), so `ΔF·e` gains `2σ²/|F|`. Against
/// the damping's part of an increment, `c·Δḋ = c·F·T/m`, this is not small: at 0.5 N on 20 N
/// it is 0.025 N a tick, as much as `c·Δḋ` for c = 190 N·s/m and m = 300 kg, and as `Δḋ < 0`
/// throughout a contact it drove ĉ low (docs/identification.md, "Coverage").
pub fn direction_bias(variance: f64, force: f64) -> f64 {
    if variance > 0.0 && force > 0.0 {
        2.0 * variance / force
    } else {
        0.0
    }
}

/// The friction coefficient of a collision's samples `(F, v)` (force on the frame N, robot tip
/// velocity m/s) against the normal `n` (into the wall): least squares of `F_t·ŝ = μ·F_n` over
/// the samples that slide faster than [`SLIDE_SPEED`] and push; returns μ̂, its standard error
/// (from the residuals) and the number of sliding samples.
pub fn friction_fit(
    n: &Vector3<f64>,
    samples: impl Iterator<Item = (Vector3<f64>, Vector3<f64>)>,
) -> (f64, f64, usize) {
    let pairs: Vec<(f64, f64)> = samples
        .filter_map(|(f, v)| {
            let f_n = f.dot(n);
            let v_t = v - n * v.dot(n);
            let speed = v_t.norm();
            (f_n > 0.0 && speed > SLIDE_SPEED).then(|| (f_n, (f - n * f_n).dot(&(v_t / speed))))
        })
        .collect();
    let den: f64 = pairs.iter().map(|(f_n, _)| f_n * f_n).sum();
    if pairs.len() < 2 || den <= 0.0 {
        return (0.0, f64::INFINITY, pairs.len());
    }
    let mu = pairs.iter().map(|(f_n, f_t)| f_n * f_t).sum::<f64>() / den;
    let residual: f64 = pairs
        .iter()
        .map(|(f_n, f_t)| (f_t - mu * f_n).powi(2))
        .sum();
    let sigma2 = residual / (pairs.len() - 1) as f64;
    (mu.max(0.0), (sigma2 / den).sqrt(), pairs.len())
}

/// [`identify`] with a plan's identification parameters ([`model_params`]), context and
/// sensor attitude.
pub fn identify_plan(
    plan: &Plan,
    recording: &Recording<'_>,
) -> Result<Identification, RecordingError> {
    identify(
        &model_params(&plan.compensator),
        &compensator_context(plan),
        &plan.sensor.orientation,
        recording,
    )
}

/// The live loop's own identification at the end of a run ([`online_identification`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnlineIdentification {
    /// The loop's k̂ at the last tick, N/m.
    pub stiffness: f64,
    /// Its standard deviation, N/m.
    pub stiffness_std: f64,
    /// The loop's ĉ at the last tick, N·s/m.
    pub damping: f64,
    /// Its standard deviation, N·s/m.
    pub damping_std: f64,
    /// Filter updates over the run.
    pub updates: usize,
    /// Runs of consecutive updates (contacts).
    pub contacts: usize,
}

/// The identification front end of `params` replayed over `recording` as the live loop runs
/// it (one filter over the whole run, never restarted, the compensator's own forgetting), and
/// the uncertainty of its final `k̂`, `ĉ`: [`segmented_covariance`] of all its updates (a run
/// of consecutive updates per contact), plus three errors the loop does not remove, each as
/// `b·bᵀ` with `b` its part of the final estimate: the direction bias of its increments
/// ([`direction_bias`]), the updates on levels the detector truncates (within
/// [`TRUNCATION_SIGMAS`] of its thresholds), and the adaptive gains' own pull (the estimate
/// against [`fixed_gain_replay`]'s at R = 2σ²; eq. 13 makes each gain depend on its own
/// innovation, which the linear analysis does not see). None before any update.
pub fn online_identification(
    params: &ModelParams,
    context: &CompensatorContext,
    sensor_to_t: &UnitQuaternion<f64>,
    recording: &Recording<'_>,
) -> Result<Option<OnlineIdentification>, RecordingError> {
    recording.check()?;
    let mut estimator = ContactEstimator::new(params, context);
    let mut log: Vec<(usize, Update)> = Vec::new();
    let mut spans: Vec<(usize, usize)> = Vec::new();
    let mut previous = false;
    for k in 0..recording.len() {
        let before = estimator.filter.t;
        let view = estimator.step(&recording.input(k, sensor_to_t));
        if estimator.filter.t != before {
            if let Some((h, z)) = estimator.last_update() {
                let gain = estimator.filter.k;
                log.push((k, Update { h, z, gain }));
            }
        }
        match (previous, view.in_contact) {
            (false, true) => spans.push((k, k)),
            (true, true) => {
                if let Some(span) = spans.last_mut() {
                    span.1 = k;
                }
            }
            _ => {}
        }
        previous = view.in_contact;
    }
    if log.is_empty() {
        return Ok(None);
    }
    let x = estimator.filter.x;
    let x0 = Vector2::new(params.stiffness_initial, params.damping_initial);
    let breaks: Vec<usize> = (1..log.len())
        .filter(|&j| log[j].0 != log[j - 1].0 + 1)
        .collect();
    let updates: Vec<Update> = log.iter().map(|(_, u)| *u).collect();
    let variance = match params.delay_mode {
        DelayMode::Align => force_noise_variance(recording, &spans),
        DelayMode::Lead => 0.0,
    };
    let force = |k: usize| {
        let c = &recording.measured_force;
        (sensor_to_t * Vector3::new(c[0][k], c[1][k], c[2][k])).norm()
    };
    let unbiased: Vec<Update> = log
        .iter()
        .map(|&(k, u)| Update {
            z: u.z - direction_bias(variance, force(k)),
            ..u
        })
        .collect();
    let bias = linear_estimate(&updates, &x0) - linear_estimate(&unbiased, &x0);
    // the part of the estimate that rests on levels the detector truncates: their residuals'
    // weight in it (the estimate with those residuals zeroed, against the estimate)
    let sigma = variance.sqrt();
    let band = params.contact_force.max(ON_SIGMAS * sigma) + TRUNCATION_SIGMAS * sigma;
    let edgeless: Vec<Update> = log
        .iter()
        .enumerate()
        .map(|(j, &(k, u))| {
            let before = if j > 0 && !breaks.contains(&j) {
                log[j - 1].0
            } else {
                k.saturating_sub(1)
            };
            if variance > 0.0 && (force(k) <= band || force(before) <= band) {
                Update {
                    z: u.h.dot(&x),
                    ..u
                }
            } else {
                u
            }
        })
        .collect();
    let edge = linear_estimate(&updates, &x0) - linear_estimate(&edgeless, &x0);
    // how far the adaptive gains (eq. 13: each gain depends on its own innovation) moved the
    // estimate from the same filter's with R fixed at the noise's level
    let adaptive = if variance > 0.0 {
        x - linear_estimate(&fixed_gain_replay(&updates, params, 2.0 * variance), &x0)
    } else {
        Vector2::zeros()
    };
    let cov = segmented_covariance(&updates, &breaks, &x, &x0, RESIDUAL_LAGS)
        + bias * bias.transpose()
        + edge * edge.transpose()
        + adaptive * adaptive.transpose();
    Ok(Some(OnlineIdentification {
        stiffness: x[0],
        stiffness_std: cov[(0, 0)].sqrt(),
        damping: x[1],
        damping_std: cov[(1, 1)].sqrt(),
        updates: log.len(),
        contacts: breaks.len() + 1,
    }))
}

/// [`online_identification`] with a plan's compensator parameters ([`model_params`]),
/// context and sensor attitude.
pub fn online_identification_plan(
    plan: &Plan,
    recording: &Recording<'_>,
) -> Result<Option<OnlineIdentification>, RecordingError> {
    online_identification(
        &model_params(&plan.compensator),
        &compensator_context(plan),
        &plan.sensor.orientation,
        recording,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::replay::tests::preset_plan;
    use crate::sim::simulate_plan;

    /// A damped oblique-6dof run with the given sensor delay (s), and the identification of
    /// its recording.
    fn identified(sensor_delay: f64) -> (Plan, Identification) {
        let mut plan = preset_plan("oblique-6dof", "pida", 0.01);
        let mut scenario = plan.scenario.clone();
        scenario.contact.damping = 130.0;
        scenario.facility.sensor_delay = sensor_delay;
        plan = scenario.resolve().expect("plan");
        let table = simulate_plan(&plan).timeseries;
        let recording = Recording::from_table(&table, false).expect("recording");
        let mut params = model_params(&plan.compensator);
        params.forgetting = OFFLINE_FORGETTING;
        let context = compensator_context(&plan);
        let q = plan.sensor.orientation;
        let id = identify(&params, &context, &q, &recording).expect("identify");
        (plan, id)
    }

    #[test]
    fn identifies_a_damped_oblique_wall_with_and_without_sensor_delay() {
        for delay in [0.0, 0.005] {
            let (plan, id) = identified(delay);
            assert!(!id.collisions.is_empty());
            for c in &id.collisions {
                let wall = plan
                    .system
                    .contact
                    .walls
                    .iter()
                    .max_by(|a, b| a.normal.dot(&c.normal).total_cmp(&b.normal.dot(&c.normal)))
                    .expect("wall");
                let angle = wall
                    .normal
                    .dot(&c.normal)
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees();
                let distance = (c.point - wall.point).dot(&wall.normal);
                println!(
                    "delay {delay} #{} k {:.1}±{:.1} c {:.2}±{:.2} angle {angle:.4}° ±{:.4} plane {:.4} mm ±{:.4}",
                    c.index, c.stiffness, c.stiffness_std, c.damping, c.damping_std,
                    c.normal_std.to_degrees(), distance * 1e3, c.offset_std * 1e3
                );
                assert!((c.stiffness / 176_275.0 - 1.0).abs() < 0.01, "{c:?}");
                assert!((c.damping / 130.0 - 1.0).abs() < 0.01, "{c:?}");
                assert!(angle < 0.5, "{angle}");
                assert!(distance.abs() < 0.5e-3, "{distance}");
            }
        }
    }

    #[test]
    fn the_recorded_updates_are_the_filters_own() {
        // the updates reconstructed from the recording, replayed with their gains from the
        // initial guess, give the filter's estimate: h and z are what the filter saw
        for delay in [0.0, 0.005] {
            let (plan, id) = identified(delay);
            let params = model_params(&plan.compensator);
            let x0 = Vector2::new(params.stiffness_initial, params.damping_initial);
            assert_eq!(id.updates.len(), id.collisions.len());
            for (c, updates) in id.collisions.iter().zip(&id.updates) {
                assert_eq!(updates.len() as u32, c.updates, "{c:?}");
                let x = linear_estimate(updates, &x0);
                assert!((x[0] / c.stiffness - 1.0).abs() < 1e-9, "{x} {c:?}");
                assert!(
                    (x[1] - c.damping).abs() < 1e-6 * c.damping.abs().max(1.0),
                    "{x} {c:?}"
                );
            }
        }
    }

    #[test]
    fn the_direction_bias_is_the_mean_of_an_increment_projected_on_its_noisy_direction() {
        // two samples of the same force F̄ with white noise σ per axis: ΔF·e, e = F_t/|F_t|,
        // has the mean 2σ²/|F̄| (second order in σ/|F̄|), for several forces and noises
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(11);
        for (force, sigma) in [(10.0, 0.5), (20.0, 1.0), (40.0, 0.5), (5.0, 0.2)] {
            let normal = Normal::new(0.0, sigma).expect("normal");
            let mean_force = Vector3::new(0.6, -0.48, 0.64) * force;
            let n = 400_000;
            let mut sum = 0.0;
            for _ in 0..n {
                let mut draw = || Vector3::from_fn(|_, _| normal.sample(&mut rng));
                let (before, now) = (mean_force + draw(), mean_force + draw());
                sum += (now - before).dot(&now.normalize());
            }
            let measured = sum / n as f64;
            let stated = direction_bias(sigma * sigma, force);
            // the sample mean's standard error is σ·√2/√n (0.0022 N at σ = 1); the formula's
            // own error is of order σ⁴/|F̄|³
            println!("|F| {force} σ {sigma}: mean {measured:.5} N, 2σ²/|F| {stated:.5} N");
            assert!(
                (measured - stated).abs() < 4.0 * sigma * (2.0 / n as f64).sqrt() + 0.05 * stated,
                "{measured} against {stated}"
            );
        }
        assert_eq!(direction_bias(0.0, 10.0), 0.0);
    }

    #[test]
    fn white_level_noise_has_the_covariance_of_its_levels() {
        // z_t = ε_t − ε_{t−1} with ε white (σ = 1): the estimate's noise is Σ D_t ε_t,
        // variance Σ D_t² — checked against the empirical variance over many draws
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let n = 200;
        let h: Vec<Vector2<f64>> = (0..n)
            .map(|t| {
                let phase = t as f64 * 0.02;
                Vector2::new(2e-5 * phase.cos(), 5e-4 * phase.sin())
            })
            .collect();
        let truth = Vector2::new(80_000.0, 130.0);
        let x0 = Vector2::new(100_000.0, 0.0);
        let p0 = Matrix2::from_diagonal(&Vector2::new(1e10, 9e4));
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        let normal = Normal::new(0.0, 1.0).expect("normal");
        let mut errors = Vec::new();
        for _ in 0..400 {
            let eps: Vec<f64> = (0..=n).map(|_| normal.sample(&mut rng)).collect();
            let mut filter = crate::compensator::SageHusaFilter::new(
                x0,
                p0,
                Matrix2::from_diagonal(&Vector2::new(100.0, 0.01)),
                0.01,
                OFFLINE_FORGETTING,
            );
            let mut updates = Vec::new();
            for t in 0..n {
                let z = h[t].dot(&truth) + eps[t + 1] - eps[t];
                filter.update(&h[t], z);
                updates.push(Update {
                    h: h[t],
                    z,
                    gain: filter.k,
                });
            }
            let cov = increment_covariance(&updates, &filter.x, &x0, RESIDUAL_LAGS);
            errors.push((filter.x[0] - truth[0]) / cov[(0, 0)].sqrt());
        }
        let rms = (errors.iter().map(|z| z * z).sum::<f64>() / errors.len() as f64).sqrt();
        println!("normalised error RMS {rms:.3}");
        // 1 for a stated σ that is the error's (measured 1.235: the initial guess's pull is
        // estimated from the estimate itself); the filter's own √P gave far below 1
        assert!((0.75..1.35).contains(&rms), "{rms}");
    }
}
