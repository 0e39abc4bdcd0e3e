//! Calibration of the facility's hardware from its own robot's probes: pure numerics, no I/O
//! (docs/calibration.md).
//!
//! - [`fit_surface`]: a surface's plane and the contact law from probes pressed along its
//!   normal at several points. Each probe `i` has its own plane offset `h_i` along the normal
//!   `n` (the contact point at that probe), all share the law:
//!   ```text
//!   s = p·n,  ḋ = −v·n,  d = h_i − s,  f = F·n          (F: the force on the rod, t frame)
//!   linear:        f = k·(h_i − s) + c·ḋ                  linear least squares in (k·h_i, k, c)
//!   Hunt-Crossley: f = (h_i − s)ⁿ·(k + c·ḋ)               Levenberg-Marquardt in (h_i, ln k, n, c)
//!   ```
//!   so each contact point is corrected for the force at which it was seen through the law;
//!   then a plane through the contact points `h_i·n + (lateral position)` gives the normal, and
//!   the fit is repeated along the new normal.
//! - [`fit_robot_response`]: the robot's delay and second-order servo lag from the commanded
//!   against the reported rod tip.
//!
//! Every fit gives its uncertainties (one standard deviation, from the residuals).

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::contact::{
    ContactLaw, ContactModel, ContactModelKind, HuntCrossley, LinearSpringDamper, Wall,
};

/// Which contact law a calibration fits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FitForm {
    /// Linear spring-damper `f = k·d + c·ḋ`.
    Linear,
    /// Hunt-Crossley `f = dⁿ·(k + c·ḋ)`, the exponent fitted too.
    HuntCrossley,
}

/// One sample of a probe: the robot's rod tip when the force was produced and the force.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeSample {
    /// Rod tip position, `t` frame, m (the robot's reported pose, aligned with the force).
    pub position: Vector3<f64>,
    /// Rod tip velocity, `t` frame, m/s.
    pub velocity: Vector3<f64>,
    /// Contact force on the rod, `t` frame, N (it pushes out of the surface, along `n`).
    pub force: Vector3<f64>,
}

/// A contact law's parameters and their standard deviations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LawFit {
    /// The law.
    pub law: ContactModel,
    /// Standard deviation of k: N/m (linear) or N/mⁿ (Hunt-Crossley).
    pub stiffness_sigma: f64,
    /// Standard deviation of c: N·s/m (linear) or N·s/mⁿ⁺¹ (Hunt-Crossley).
    pub damping_sigma: f64,
    /// Standard deviation of the exponent n (0 for the linear law).
    pub exponent_sigma: f64,
}

/// One surface fitted from its probes.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceFit {
    /// A point of the plane: the centre of the probed region, `t` frame, m.
    pub point: Vector3<f64>,
    /// Unit normal into free space, `t` frame.
    pub normal: Vector3<f64>,
    /// Standard deviation of the plane's offset along its normal at `point`, m.
    pub offset_sigma: f64,
    /// Standard deviation of the normal's direction, rad (infinite with fewer than 3 probes).
    pub angle_sigma: f64,
    /// The law and its uncertainties.
    pub law: LawFit,
    /// The contact point of each probe (on the fitted law's zero-force plane), `t`, m.
    pub contact_points: Vec<Vector3<f64>>,
    /// RMS force residual of the law fit, N.
    pub rms: f64,
    /// Samples used.
    pub samples: usize,
}

/// Why a fit failed.
#[derive(Debug, Clone, PartialEq)]
pub enum FitError {
    /// Too few samples or probes in contact.
    TooFewSamples(String),
    /// The data do not determine a law that pushes (k ≤ 0, non-finite).
    Degenerate(String),
}

impl std::fmt::Display for FitError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FitError::TooFewSamples(m) | FitError::Degenerate(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for FitError {}

/// Factor on the law's σ (k, c, n) from the fit's covariance (the larger of the white, the
/// probe-clustered and the delete-one-probe jackknife one): over 20 synthetic calibrations
/// with the robot's repeatability drift (crates/core/tests/calibration_law.rs) k spread 1.3–1.4
/// times its clustered and jackknifed σ (with 17 probes, both are known to run low; the drift
/// correlates neighbouring probes). Stated σ must cover the error, so they are widened.
const LAW_SIGMA_FACTOR: f64 = 1.5;

/// Iterations of the plane and law refit along the new normal.
const PLANE_ITERATIONS: usize = 3;
/// Most Levenberg-Marquardt iterations of the Hunt-Crossley fit.
const LM_ITERATIONS: usize = 60;

/// Fits a surface's plane and the contact law (`form`) from probes pressed along roughly
/// `nominal_normal` (unit, into free space). Samples whose force along the normal is below
/// `min_force` (N) are left out of the first pass; later passes keep the samples the fitted
/// law puts in contact by more than `min_force` (selected on position, not on the noisy force).
pub fn fit_surface(
    probes: &[Vec<ProbeSample>],
    nominal_normal: &Vector3<f64>,
    form: FitForm,
    min_force: f64,
) -> Result<SurfaceFit, FitError> {
    if probes.is_empty() {
        return Err(FitError::TooFewSamples("no probe".into()));
    }
    let mut normal = nominal_normal.normalize();
    let mut selection: Vec<Vec<bool>> = probes
        .iter()
        .map(|p| p.iter().map(|x| x.force.dot(&normal) > min_force).collect())
        .collect();
    let mut fit = None;
    for _ in 0..PLANE_ITERATIONS {
        let (mut law, offsets, rms, used) = fit_law(probes, &selection, &normal, form)?;
        law.stiffness_sigma *= LAW_SIGMA_FACTOR;
        law.damping_sigma *= LAW_SIGMA_FACTOR;
        law.exponent_sigma *= LAW_SIGMA_FACTOR;
        // each probe's contact point: its mean lateral position on the plane p·n = h_i
        let mut points = Vec::with_capacity(probes.len());
        let mut point_sigmas = Vec::with_capacity(probes.len());
        for (i, p) in probes.iter().enumerate() {
            let chosen: Vec<&ProbeSample> = p
                .iter()
                .zip(&selection[i])
                .filter_map(|(x, &s)| s.then_some(x))
                .collect();
            let mean = chosen.iter().fold(Vector3::zeros(), |a, x| a + x.position)
                / chosen.len().max(1) as f64;
            points.push(mean - normal * (mean.dot(&normal) - offsets[i].0));
            point_sigmas.push(offsets[i].1);
        }
        let plane = fit_plane(&points, &point_sigmas, &normal);
        fit = Some(SurfaceFit {
            point: plane.point,
            normal: plane.normal,
            offset_sigma: plane.offset_sigma,
            angle_sigma: plane.angle_sigma,
            law,
            contact_points: points,
            rms,
            samples: used,
        });
        normal = plane.normal;
        // select on the motion, not on the noisy force: the samples the fitted law, with its
        // damping, puts in contact by more than `min_force`. A sample the law would make pull
        // (a fast retreat: k·d + c·ḋ < 0) reads 0 N, not the law's force, and is left out;
        // selected on the depth alone, such samples pulled c 9 % low (docs/calibration.md).
        let contact_points = &fit.as_ref().expect("set above").contact_points;
        selection = probes
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let h = contact_points[i].dot(&normal);
                p.iter()
                    .map(|x| {
                        let d = h - x.position.dot(&normal);
                        let rate = -x.velocity.dot(&normal);
                        d > 0.0 && law.law.normal_force(d, rate) > min_force
                    })
                    .collect()
            })
            .collect();
    }
    fit.ok_or_else(|| FitError::Degenerate("no fit".into()))
}

/// The joint law fit with an offset per probe: the law, each probe's offset `h_i` along
/// `normal` and its standard deviation (m), the RMS residual (N), the samples used.
#[allow(clippy::type_complexity)]
fn fit_law(
    probes: &[Vec<ProbeSample>],
    selection: &[Vec<bool>],
    normal: &Vector3<f64>,
    form: FitForm,
) -> Result<(LawFit, Vec<(f64, f64)>, f64, usize), FitError> {
    // rows (probe, s, ḋ, f), s from the reported velocity where it explains the positions
    let positions = integrated_positions(probes, selection, normal);
    let mut rows = Vec::new();
    for (i, p) in probes.iter().enumerate() {
        for (j, (x, &chosen)) in p.iter().zip(&selection[i]).enumerate() {
            if chosen {
                rows.push((
                    i,
                    positions[i][j],
                    -x.velocity.dot(normal),
                    x.force.dot(normal),
                ));
            }
        }
    }
    let np = probes.len();
    for i in 0..np {
        if rows.iter().filter(|r| r.0 == i).count() < 3 {
            return Err(FitError::TooFewSamples(format!(
                "probe {} has fewer than 3 samples in contact",
                i + 1
            )));
        }
    }
    let linear = fit_linear_rows(&rows, np)?;
    match form {
        FitForm::Linear => Ok(linear),
        FitForm::HuntCrossley => fit_hunt_crossley_rows(&rows, np, &linear),
    }
}

/// Share of the positions' variance within a probe that the integrated velocity must explain
/// (`1 −` this) for [`integrated_positions`] to use it.
const INTEGRATION_RESIDUAL_SHARE: f64 = 0.02;
/// Below this share of their variance the reported positions' noise pulls k by less than
/// 0.1 %: they are used as they are (integrating needs nothing, and gains nothing).
const INTEGRATION_MIN_NOISE_SHARE: f64 = 1e-3;

/// Each probe's positions along `normal` (`s = p·n`, m) for the law fit: the reported
/// velocity integrated, `s_j = s̄_i + Δt·(U_j − Ū_i) + β·(v_j − v̄_i)` with
/// `U_j = Σ_{m≤j} v_m·n`, the sample period `Δt` and the velocity's place in its period `β`
/// fitted over all probes (least squares of the positions, each probe's mean removed), where
/// that explains the reported positions (all but
/// [`INTEGRATION_RESIDUAL_SHARE`] of their variance within the probes) and their noise is
/// worth removing (at least [`INTEGRATION_MIN_NOISE_SHARE`] of their variance over the
/// selected samples); else the reported
/// positions as they are.
///
/// Why: the reported positions carry the robot's reporting noise (0.03 mm at 0.03 mm
/// repeatability; a twelfth of it in variance once smoothed), which in the regressor `s` of
/// `f = k·(h_i − s) + c·ḋ` pulls k low by `var(noise)/var(s)` (errors in variables: 0.2–0.4 %
/// on paper-table1's probes, more than k's σ), and a smoothing window across the retreat's
/// corner bends them by up to `1.2·v·T`. The reported velocity carries neither; its integral
/// is the tracked motion up to a constant per probe, which `h_i` absorbs.
fn integrated_positions(
    probes: &[Vec<ProbeSample>],
    selection: &[Vec<bool>],
    normal: &Vector3<f64>,
) -> Vec<Vec<f64>> {
    let reported: Vec<Vec<f64>> = probes
        .iter()
        .map(|p| p.iter().map(|x| x.position.dot(normal)).collect())
        .collect();
    let sums: Vec<Vec<f64>> = probes
        .iter()
        .map(|p| {
            let mut u = 0.0;
            p.iter()
                .map(|x| {
                    u += x.velocity.dot(normal);
                    u
                })
                .collect()
        })
        .collect();
    let rates: Vec<Vec<f64>> = probes
        .iter()
        .map(|p| p.iter().map(|x| x.velocity.dot(normal)).collect())
        .collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    // s − s̄ = Δt·(U − Ū) + β·(v − v̄): β places the velocity within its period (−Δt/2 for
    // an instantaneous one, 0 for the mean over the period ending at the sample)
    let mut normal_matrix = nalgebra::Matrix2::zeros();
    let mut right = nalgebra::Vector2::zeros();
    let mut ss = 0.0;
    for ((s, u), v) in reported.iter().zip(&sums).zip(&rates) {
        let (s_mean, u_mean, v_mean) = (mean(s), mean(u), mean(v));
        for ((a, b), c) in s.iter().zip(u).zip(v) {
            let x = nalgebra::Vector2::new(b - u_mean, c - v_mean);
            normal_matrix += x * x.transpose();
            right += x * (a - s_mean);
            ss += (a - s_mean) * (a - s_mean);
        }
    }
    let Some(coefficients) = normal_matrix.try_inverse().map(|m| m * right) else {
        return reported;
    };
    let (dt, beta) = (coefficients[0], coefficients[1]);
    let residual = ss - coefficients.dot(&right);
    // the noise's share of the positions' variance over the samples the law fit uses
    let (mut noise, mut motion) = (0.0, 0.0);
    for (((s, u), v), chosen) in reported.iter().zip(&sums).zip(&rates).zip(selection) {
        let (u_mean, v_mean) = (mean(u), mean(v));
        let picked: Vec<(f64, f64)> = s
            .iter()
            .zip(u)
            .zip(v)
            .zip(chosen)
            .filter(|(_, &c)| c)
            .map(|(((a, b), c), _)| (*a, a - dt * (b - u_mean) - beta * (c - v_mean)))
            .collect();
        let count = picked.len().max(1) as f64;
        let (s_mean, e_mean) = picked.iter().fold((0.0, 0.0), |acc, x| {
            (acc.0 + x.0 / count, acc.1 + x.1 / count)
        });
        for (a, e) in picked {
            motion += (a - s_mean) * (a - s_mean);
            noise += (e - e_mean) * (e - e_mean);
        }
    }
    let useful = noise >= INTEGRATION_MIN_NOISE_SHARE * motion;
    if !(useful
        && dt > 0.0
        && dt.is_finite()
        && beta.is_finite()
        && residual <= INTEGRATION_RESIDUAL_SHARE * ss)
    {
        return reported;
    }
    reported
        .iter()
        .zip(&sums)
        .zip(&rates)
        .map(|((s, u), v)| {
            let (s_mean, u_mean, v_mean) = (mean(s), mean(u), mean(v));
            u.iter()
                .zip(v)
                .map(|(b, c)| s_mean + dt * (b - u_mean) + beta * (c - v_mean))
                .collect()
        })
        .collect()
}

/// Solves the least-squares problem `A·θ ≈ y`; returns θ, its covariance and the RMS
/// residual. The covariance is the larger, parameter by parameter, of `σ²·(AᵀA)⁻¹` (`σ²` the
/// residual variance: white residuals) and the probe-clustered one of [`clustered_covariance`]
/// (`clusters[j]`: the probe of row `j`), which holds when the residuals are correlated
/// within a probe.
fn least_squares(
    a: &DMatrix<f64>,
    y: &DVector<f64>,
    clusters: &[usize],
) -> Option<(DVector<f64>, DMatrix<f64>, f64)> {
    let ata = a.transpose() * a;
    let aty = a.transpose() * y;
    let chol = ata.clone().cholesky()?;
    let theta = chol.solve(&aty);
    let residual = y - a * &theta;
    let (m, p) = (a.nrows() as f64, a.ncols() as f64);
    let dof = (m - p).max(1.0);
    let variance = residual.norm_squared() / dof;
    let inverse = chol.inverse();
    let white = &inverse * variance;
    let clustered = clustered_covariance(a, &residual, clusters, &inverse);
    let jackknife = jackknife_covariance(a, y, clusters, &ata, &aty);
    let rms = (residual.norm_squared() / m).sqrt();
    theta.iter().all(|x| x.is_finite()).then(|| {
        let larger = larger_covariance(&white, &clustered);
        (theta, larger_covariance(&larger, &jackknife), rms)
    })
}

/// The delete-one-probe jackknife covariance of a least-squares fit:
/// `(G−1)/G · Σ_g (θ₍g₎ − θ̄)(θ₍g₎ − θ̄)ᵀ`, `θ₍g₎` the fit without probe `g`'s rows (its own
/// columns, which no other row uses, held at 0). With the 17 probes of a wall the clustered
/// covariance alone understates the spread of k over repeated calibrations by about 1.4×
/// (its known small-sample bias); the jackknife does not.
fn jackknife_covariance(
    a: &DMatrix<f64>,
    y: &DVector<f64>,
    clusters: &[usize],
    ata: &DMatrix<f64>,
    aty: &DVector<f64>,
) -> DMatrix<f64> {
    let p = a.ncols();
    let groups = clusters.iter().copied().max().map_or(0, |g| g + 1);
    let mut partial_ata = vec![DMatrix::<f64>::zeros(p, p); groups];
    let mut partial_aty = vec![DVector::<f64>::zeros(p); groups];
    for (j, &g) in clusters.iter().enumerate() {
        let row = a.row(j).transpose();
        partial_ata[g] += &row * row.transpose();
        partial_aty[g] += row * y[j];
    }
    let mut estimates = Vec::with_capacity(groups);
    for g in 0..groups {
        let mut m = ata - &partial_ata[g];
        let v = aty - &partial_aty[g];
        for i in 0..p {
            if m[(i, i)] <= 0.0 {
                m[(i, i)] = 1.0;
            }
        }
        if let Some(chol) = m.cholesky() {
            estimates.push(chol.solve(&v));
        }
    }
    let count = estimates.len() as f64;
    if count < 3.0 {
        return DMatrix::zeros(p, p);
    }
    let mean = estimates.iter().fold(DVector::zeros(p), |acc, e| acc + e) / count;
    let mut cov = DMatrix::zeros(p, p);
    for e in &estimates {
        let d = e - &mean;
        cov += &d * d.transpose();
    }
    // a probe's own columns (its offset) are not estimated without it: not jackknifed
    for i in 0..p {
        let own = partial_ata.iter().any(|m| m[(i, i)] >= ata[(i, i)]);
        if own {
            cov.row_mut(i).fill(0.0);
            cov.column_mut(i).fill(0.0);
        }
    }
    cov * ((count - 1.0) / count)
}

/// The cluster-robust ("sandwich") covariance of a least-squares fit with Jacobian `a`,
/// residuals `residual` and `inverse = (AᵀA)⁻¹`, the rows grouped by `clusters` (a probe
/// each):
/// ```text
/// V = G/(G−1) · (AᵀA)⁻¹ · Σ_g (A_gᵀ r_g)(A_gᵀ r_g)ᵀ · (AᵀA)⁻¹        G: the clusters
/// ```
/// The residuals within a probe are not independent: the robot's unreported repeatability
/// error drifts over a probe (a correlation time of about a second), the smoothed positions'
/// noise is correlated over the smoothing window, so `σ²·(AᵀA)⁻¹` understates the law's
/// uncertainty many times over; the probes, seconds apart, are nearly independent.
fn clustered_covariance(
    a: &DMatrix<f64>,
    residual: &DVector<f64>,
    clusters: &[usize],
    inverse: &DMatrix<f64>,
) -> DMatrix<f64> {
    let p = a.ncols();
    let groups = clusters.iter().copied().max().map_or(0, |g| g + 1);
    let mut scores = vec![DVector::<f64>::zeros(p); groups];
    for (j, &g) in clusters.iter().enumerate() {
        scores[g] += a.row(j).transpose() * residual[j];
    }
    let used = scores.iter().filter(|s| s.norm_squared() > 0.0).count() as f64;
    let mut meat = DMatrix::zeros(p, p);
    for s in &scores {
        meat += s * s.transpose();
    }
    let correction = if used > 1.0 { used / (used - 1.0) } else { 1.0 };
    inverse * meat * inverse * correction
}

/// `white` with each parameter's variance (and its covariances, scaled alike) raised to
/// `clustered`'s where that is larger.
fn larger_covariance(white: &DMatrix<f64>, clustered: &DMatrix<f64>) -> DMatrix<f64> {
    let p = white.nrows();
    let scale: Vec<f64> = (0..p)
        .map(|i| {
            let (w, c) = (white[(i, i)], clustered[(i, i)]);
            if w > 0.0 && c > w {
                (c / w).sqrt()
            } else {
                1.0
            }
        })
        .collect();
    DMatrix::from_fn(p, p, |i, j| white[(i, j)] * scale[i] * scale[j])
}

/// Linear law: `f = a_i − k·s + c·ḋ` with `a_i = k·h_i`; a negative `c` is refitted with `c = 0`.
#[allow(clippy::type_complexity)]
fn fit_linear_rows(
    rows: &[(usize, f64, f64, f64)],
    np: usize,
) -> Result<(LawFit, Vec<(f64, f64)>, f64, usize), FitError> {
    // centre s per probe for conditioning: f = a'_i − k·(s − s̄_i) + c·ḋ
    let mut s_mean = vec![0.0; np];
    let mut count = vec![0.0; np];
    for r in rows {
        s_mean[r.0] += r.1;
        count[r.0] += 1.0;
    }
    for i in 0..np {
        s_mean[i] /= count[i];
    }
    let clusters: Vec<usize> = rows.iter().map(|r| r.0).collect();
    let solve = |with_damping: bool| {
        let cols = np + 1 + usize::from(with_damping);
        let mut a = DMatrix::zeros(rows.len(), cols);
        let mut y = DVector::zeros(rows.len());
        for (j, r) in rows.iter().enumerate() {
            a[(j, r.0)] = 1.0;
            a[(j, np)] = -(r.1 - s_mean[r.0]);
            if with_damping {
                a[(j, np + 1)] = r.2;
            }
            y[j] = r.3;
        }
        least_squares(&a, &y, &clusters)
    };
    let full = solve(true);
    // a negative c (noise about a small damping) is refitted with c = 0; its uncertainty
    // stays the unconstrained fit's
    let free_sigma = full
        .as_ref()
        .map_or(f64::INFINITY, |(_, c, _)| c[(np + 1, np + 1)].sqrt());
    let (theta, cov, rms, damped) = match full {
        Some((t, c, r)) if t[np + 1] >= 0.0 => (t, c, r, true),
        _ => {
            let (t, c, r) = solve(false)
                .ok_or_else(|| FitError::Degenerate("the probes do not determine k".into()))?;
            (t, c, r, false)
        }
    };
    let k = theta[np];
    if !(k > 0.0 && k.is_finite()) {
        return Err(FitError::Degenerate(format!(
            "the fitted stiffness is not positive ({k} N/m)"
        )));
    }
    let (c, c_sigma) = if damped {
        (theta[np + 1], cov[(np + 1, np + 1)].sqrt())
    } else {
        (0.0, free_sigma)
    };
    // h_i = s̄_i + a'_i/k (the damping's share of the mean force is in a'_i: ḋ's mean is
    // near 0 over a press, dwell and release; a'_i = k·(h_i − s̄_i) + c·ḋ̄_i)
    let mut offsets = Vec::with_capacity(np);
    for i in 0..np {
        let mut rate_mean = 0.0;
        for r in rows.iter().filter(|r| r.0 == i) {
            rate_mean += r.2 / count[i];
        }
        let a_i = theta[i] - if damped { c * rate_mean } else { 0.0 };
        let h = s_mean[i] + a_i / k;
        // σ_h² ≈ (σ_a²/k²) + (a/k²)²·σ_k² − 2·(a/k³)·cov(a, k)
        let var = cov[(i, i)] / (k * k) + (a_i / (k * k)).powi(2) * cov[(np, np)]
            - 2.0 * a_i / (k * k * k) * cov[(i, np)];
        offsets.push((h, var.max(0.0).sqrt()));
    }
    Ok((
        LawFit {
            law: ContactModel::Linear(LinearSpringDamper {
                stiffness: k,
                damping: c,
            }),
            stiffness_sigma: cov[(np, np)].sqrt(),
            damping_sigma: c_sigma,
            exponent_sigma: 0.0,
        },
        offsets,
        rms,
        rows.len(),
    ))
}

/// Hunt-Crossley law `f = dⁿ·(k + c·ḋ)`, `d = max(0, h_i − s)`: Levenberg-Marquardt on
/// `θ = (h_1..h_P, ln k, n, c)` from the linear fit's offsets and `n = 1.5`.
#[allow(clippy::type_complexity)]
fn fit_hunt_crossley_rows(
    rows: &[(usize, f64, f64, f64)],
    np: usize,
    linear: &(LawFit, Vec<(f64, f64)>, f64, usize),
) -> Result<(LawFit, Vec<(f64, f64)>, f64, usize), FitError> {
    let p = np + 3;
    let mut theta = DVector::zeros(p);
    for i in 0..np {
        theta[i] = linear.1[i].0;
    }
    // k for n = 1.5 with c = 0 by least squares
    let n0 = 1.5;
    let (mut num, mut den) = (0.0, 0.0);
    for r in rows {
        let d = (theta[r.0] - r.1).max(0.0);
        let dn = d.powf(n0);
        num += r.3 * dn;
        den += dn * dn;
    }
    if !(num > 0.0 && den > 0.0) {
        return Err(FitError::Degenerate(
            "the probes do not determine a Hunt-Crossley law".into(),
        ));
    }
    theta[np] = (num / den).ln();
    theta[np + 1] = n0;
    theta[np + 2] = 0.0;
    let model = |t: &DVector<f64>, r: &(usize, f64, f64, f64)| {
        let d = (t[r.0] - r.1).max(0.0);
        if d == 0.0 {
            return 0.0;
        }
        d.powf(t[np + 1]) * (t[np].exp() + t[np + 2] * r.2)
    };
    let cost = |t: &DVector<f64>| {
        rows.iter()
            .map(|r| (r.3 - model(t, r)).powi(2))
            .sum::<f64>()
    };
    // analytic Jacobian
    let jacobian = |t: &DVector<f64>| {
        let mut j = DMatrix::zeros(rows.len(), p);
        for (row, r) in rows.iter().enumerate() {
            let d = (t[r.0] - r.1).max(0.0);
            if d == 0.0 {
                continue;
            }
            let (k, n, c) = (t[np].exp(), t[np + 1], t[np + 2]);
            let dn = d.powf(n);
            let g = k + c * r.2;
            j[(row, r.0)] = n * d.powf(n - 1.0) * g;
            j[(row, np)] = dn * k;
            j[(row, np + 1)] = dn * d.ln() * g;
            j[(row, np + 2)] = dn * r.2;
        }
        j
    };
    let mut lambda = 1e-3;
    let mut current = cost(&theta);
    for _ in 0..LM_ITERATIONS {
        let j = jacobian(&theta);
        let residual =
            DVector::from_iterator(rows.len(), rows.iter().map(|r| r.3 - model(&theta, r)));
        let jtj = j.transpose() * &j;
        let jtr = j.transpose() * residual;
        let mut improved = false;
        for _ in 0..10 {
            let mut damped = jtj.clone();
            for i in 0..p {
                damped[(i, i)] += lambda * jtj[(i, i)].max(1e-30);
            }
            let Some(step) = damped.cholesky().map(|ch| ch.solve(&jtr)) else {
                lambda *= 10.0;
                continue;
            };
            let candidate = &theta + step;
            let c = cost(&candidate);
            if c.is_finite() && c < current && candidate[np + 1] > 0.1 {
                let relative = (current - c) / current.max(1e-300);
                theta = candidate;
                current = c;
                lambda = (lambda * 0.3).max(1e-12);
                improved = relative > 1e-12;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let j = jacobian(&theta);
    let m = rows.len() as f64;
    let variance = current / (m - p as f64).max(1.0);
    let residual = DVector::from_iterator(rows.len(), rows.iter().map(|r| r.3 - model(&theta, r)));
    let clusters: Vec<usize> = rows.iter().map(|r| r.0).collect();
    let cov = (j.transpose() * &j)
        .try_inverse()
        .map(|inv| {
            let clustered = clustered_covariance(&j, &residual, &clusters, &inv);
            larger_covariance(&(inv * variance), &clustered)
        })
        .unwrap_or_else(|| DMatrix::from_element(p, p, f64::INFINITY));
    let (k, n, c) = (theta[np].exp(), theta[np + 1], theta[np + 2].max(0.0));
    if !(k.is_finite() && k > 0.0 && n.is_finite()) {
        return Err(FitError::Degenerate(
            "the Hunt-Crossley fit did not converge".into(),
        ));
    }
    let offsets = (0..np)
        .map(|i| (theta[i], cov[(i, i)].max(0.0).sqrt()))
        .collect();
    Ok((
        LawFit {
            law: ContactModel::HuntCrossley(HuntCrossley {
                stiffness: k,
                damping: c,
                exponent: n,
            }),
            // σ(k) = k·σ(ln k)
            stiffness_sigma: k * cov[(np, np)].max(0.0).sqrt(),
            damping_sigma: cov[(np + 2, np + 2)].max(0.0).sqrt(),
            exponent_sigma: cov[(np + 1, np + 1)].max(0.0).sqrt(),
        },
        offsets,
        (current / m).sqrt(),
        rows.len(),
    ))
}

/// A plane fitted to points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneFit {
    /// The centroid of the points, on the plane, m.
    pub point: Vector3<f64>,
    /// Unit normal, on the side of the guess.
    pub normal: Vector3<f64>,
    /// Standard deviation of the offset at `point`, m.
    pub offset_sigma: f64,
    /// Standard deviation of the normal's direction, rad (infinite with fewer than 3 points).
    pub angle_sigma: f64,
}

/// Fits a plane to `points` (each with the standard deviation `sigmas[i]` along the normal,
/// m) near the normal `guess`: `z = z₀ + α·a + β·b` in coordinates `(a, b)` along the plane of
/// `guess` and `z` along it, centred on the points' centroid; weighted least squares. The
/// offset's uncertainty comes from the larger of the points' own and their scatter. Fewer than
/// 3 points keep the normal `guess`.
pub fn fit_plane(points: &[Vector3<f64>], sigmas: &[f64], guess: &Vector3<f64>) -> PlaneFit {
    let n = guess.normalize();
    let u = n
        .cross(&if n.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        })
        .normalize();
    let w = n.cross(&u);
    let count = points.len().max(1) as f64;
    let centroid = points.iter().fold(Vector3::zeros(), |a, p| a + p) / count;
    let weight = |i: usize| 1.0 / sigmas.get(i).copied().unwrap_or(0.0).max(1e-9).powi(2);
    if points.len() < 3 {
        let wsum: f64 = (0..points.len()).map(weight).sum();
        let z = (0..points.len())
            .map(|i| weight(i) * points[i].dot(&n))
            .sum::<f64>()
            / wsum.max(f64::MIN_POSITIVE);
        return PlaneFit {
            point: centroid + n * (z - centroid.dot(&n)),
            normal: n,
            offset_sigma: (1.0 / wsum.max(f64::MIN_POSITIVE)).sqrt(),
            angle_sigma: f64::INFINITY,
        };
    }
    let mut ata = Matrix3::zeros();
    let mut atz = Vector3::zeros();
    for (i, p) in points.iter().enumerate() {
        let q = p - centroid;
        let row = Vector3::new(1.0, q.dot(&u), q.dot(&w));
        ata += row * row.transpose() * weight(i);
        atz += row * (q.dot(&n) * weight(i));
    }
    let Some(inverse) = ata.try_inverse() else {
        // collinear points: the tilt across them is not determined
        return fit_plane(&points[..2], sigmas, guess);
    };
    let theta = inverse * atz;
    let (z0, alpha, beta) = (theta[0], theta[1], theta[2]);
    // scatter of the points about the plane against their own uncertainties
    let mut chi2 = 0.0;
    for (i, p) in points.iter().enumerate() {
        let q = p - centroid;
        let r = q.dot(&n) - (z0 + alpha * q.dot(&u) + beta * q.dot(&w));
        chi2 += r * r * weight(i);
    }
    let dof = (points.len() as f64 - 3.0).max(1.0);
    let scale = if points.len() > 3 {
        (chi2 / dof).max(1.0)
    } else {
        1.0
    };
    let cov = inverse * scale;
    let normal = (n - u * alpha - w * beta).normalize();
    PlaneFit {
        point: centroid + n * z0,
        normal,
        offset_sigma: cov[(0, 0)].max(0.0).sqrt(),
        angle_sigma: (cov[(1, 1)] + cov[(2, 2)]).max(0.0).sqrt(),
    }
}

/// The robot's response fitted from command against feedback.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotResponse {
    /// Pure delay τ_r, s: the feedback at tick `j` follows the command issued at tick
    /// `j − 1 − τ_r/T` (the command issued at a tick is the pose for the next one, as the
    /// loop and `facility.robot_delay` count it).
    pub delay: f64,
    /// Its standard deviation, s (at least the resolution of the fit, T/√12 for whole ticks).
    pub delay_sigma: f64,
    /// Natural frequency of the second-order servo lag, Hz (0: none found).
    pub servo_frequency: f64,
    /// Its damping ratio.
    pub servo_damping: f64,
    /// RMS of the feedback against the fitted response, m.
    pub rms: f64,
}

/// Servo natural frequencies tried, Hz (a geometric grid).
const SERVO_FREQUENCIES: (f64, f64, usize) = (2.0, 200.0, 40);
/// Servo damping ratios tried.
const SERVO_DAMPINGS: [f64; 5] = [0.5, 0.6, 0.7, 0.85, 1.0];
/// The servo lag is kept when its mean square is below this share of the pure delay's.
const SERVO_PREFERENCE: f64 = 0.8;
/// Integration sub-steps per period of the servo model.
const SERVO_SUBSTEPS: usize = 10;

/// Fits the robot's delay and servo lag from the commanded rod tip (`commanded[j]`, issued at
/// tick `j`) and the reported one (`reported[j]`, received at tick `j`), `t` frame, m, with the
/// control period `period` (s), delays up to `max_delay` (s). First the pure delay (whole
/// ticks, least squares), then the second-order lag `ω_n²/(s² + 2ζω_n s + ω_n²)` on a grid
/// of `(ω_n, ζ)` with the delay shortened by the lag's own; the lag is kept when its mean square is below
/// [`SERVO_PREFERENCE`] of the pure delay's. `None` without
/// motion or with fewer samples than the longest delay.
pub fn fit_robot_response(
    commanded: &[Vector3<f64>],
    reported: &[Vector3<f64>],
    period: f64,
    max_delay: f64,
) -> Option<RobotResponse> {
    let n = commanded.len().min(reported.len());
    let max_ticks = (max_delay / period).round() as usize + 1;
    if n < max_ticks + 10 {
        return None;
    }
    let start = max_ticks + 1;
    let mean_square = |lag: usize| -> f64 {
        (start..n)
            .map(|j| (reported[j] - commanded[j - lag]).norm_squared())
            .sum::<f64>()
            / (n - start) as f64
    };
    let motion = (start..n)
        .map(|j| (commanded[j] - commanded[start]).norm_squared())
        .sum::<f64>();
    if motion == 0.0 {
        return None;
    }
    // pure delay: lag L = 1 + τ_r/T ticks
    let (best_lag, best) = (1..=max_ticks)
        .map(|lag| (lag, mean_square(lag)))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    // sub-tick refinement of the pure delay (parabola through the neighbours)
    let mut delay_ticks = best_lag as f64 - 1.0;
    if best_lag > 1 && best_lag < max_ticks {
        let (a, b, c) = (mean_square(best_lag - 1), best, mean_square(best_lag + 1));
        let curvature = a - 2.0 * b + c;
        if curvature > 0.0 {
            delay_ticks += (0.5 * (a - c) / curvature).clamp(-0.5, 0.5);
        }
    }
    let mut response = RobotResponse {
        delay: delay_ticks * period,
        delay_sigma: period / 12f64.sqrt(),
        servo_frequency: 0.0,
        servo_damping: 0.0,
        rms: best.sqrt(),
    };
    // the servo lag on a grid
    let (f_lo, f_hi, steps) = SERVO_FREQUENCIES;
    let mut best_servo: Option<(f64, f64, usize, f64)> = None;
    for i in 0..steps {
        let hz = f_lo * (f_hi / f_lo).powf(i as f64 / (steps - 1) as f64);
        let omega = 2.0 * std::f64::consts::PI * hz;
        for &zeta in &SERVO_DAMPINGS {
            let lag_ticks = (2.0 * zeta / omega / period).round() as usize;
            let centre = best_lag.saturating_sub(lag_ticks).max(1);
            for lag in centre.saturating_sub(2).max(1)..=(centre + 2).min(max_ticks) {
                let ms = servo_mean_square(commanded, reported, period, lag, omega, zeta, start, n);
                if best_servo.is_none_or(|b| ms < b.3) {
                    best_servo = Some((hz, zeta, lag, ms));
                }
            }
        }
    }
    if let Some((hz, zeta, lag, ms)) = best_servo {
        if ms < SERVO_PREFERENCE * best {
            response.delay = (lag as f64 - 1.0) * period;
            response.servo_frequency = hz;
            response.servo_damping = zeta;
            response.rms = ms.sqrt();
        }
    }
    Some(response)
}

/// Mean square of the feedback against the command delayed by `lag` ticks through the servo
/// lag (semi-implicit Euler at [`SERVO_SUBSTEPS`] per period, the command interpolated
/// linearly, as the facility model integrates it), from the robot at rest at the first
/// delayed command.
#[allow(clippy::too_many_arguments)]
fn servo_mean_square(
    commanded: &[Vector3<f64>],
    reported: &[Vector3<f64>],
    period: f64,
    lag: usize,
    omega: f64,
    zeta: f64,
    start: usize,
    n: usize,
) -> f64 {
    let h = period / SERVO_SUBSTEPS as f64;
    let (w2, damp) = (omega * omega, 2.0 * zeta * omega);
    let mut x = commanded[0];
    let mut v = Vector3::zeros();
    let mut sum = 0.0;
    for j in lag.max(1)..n {
        // during the period ending at tick j the robot follows command[j−lag−1] → command[j−lag]
        let a = commanded[j - lag - usize::from(j > lag)];
        let b = commanded[j - lag];
        for s in 1..=SERVO_SUBSTEPS {
            let u = a.lerp(&b, s as f64 / SERVO_SUBSTEPS as f64);
            v += (w2 * (u - x) - damp * v) * h;
            x += v * h;
        }
        if j >= start {
            sum += (reported[j] - x).norm_squared();
        }
    }
    sum / (n - start) as f64
}

/// Savitzky-Golay smoothing of `values`: at each sample, the value at its centre of the
/// least-squares quadratic over `±half_width` samples (a moving average where the window does
/// not fit, at the ends). It keeps a parabola, and a sinusoid of period much longer than the
/// window (the error at `ω·half_width·T = 0.5` is 0.3 %), and averages white noise down
/// (variance `3(3w² + 3w − 1)/((2w + 1)(4w² + 4w − 3))` of the samples', w the half-width).
pub fn smooth(values: &[Vector3<f64>], half_width: usize) -> Vec<Vector3<f64>> {
    let n = values.len();
    let w = half_width as f64;
    let norm = (2.0 * w + 1.0) * (4.0 * w * w + 4.0 * w - 3.0);
    let coefficient = |j: f64| (3.0 * (3.0 * w * w + 3.0 * w - 1.0) - 15.0 * j * j) / norm;
    (0..n)
        .map(|i| {
            if half_width == 0 {
                return values[i];
            }
            if i >= half_width && i + half_width < n {
                let mut sum = Vector3::zeros();
                for k in 0..=2 * half_width {
                    sum += values[i + k - half_width] * coefficient(k as f64 - w);
                }
                sum
            } else {
                let lo = i.saturating_sub(half_width);
                let hi = (i + half_width + 1).min(n);
                values[lo..hi].iter().fold(Vector3::zeros(), |a, v| a + v) / (hi - lo) as f64
            }
        })
        .collect()
}

/// The calibration file (`hilcontact calibrate ... --out cal.toml`), and the
/// `[compensator.calibration]` table of `model-mediated`: the hardware as the facility's robot
/// measured it. Defined once here; [`CalibrationFile::check`] turns it into validated values.
/// Without walls (the default) it is no calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema, Default)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationFile {
    /// When, on what and how it was measured.
    pub measured: CalibrationInfo,
    /// Each probed surface (at most 8; none: no calibration).
    #[schemars(length(max = 8))]
    pub walls: Vec<CalibratedWall>,
    /// The contact law.
    pub law: CalibratedLaw,
    /// The robot's response.
    pub robot: CalibratedRobot,
}

/// When, on what and how a calibration was measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema, Default)]
#[serde(deny_unknown_fields)]
pub struct CalibrationInfo {
    /// The scenario whose nominal hardware was probed (its `name`).
    #[serde(default)]
    pub scenario: String,
    /// When the measurement ended, UTC, ISO 8601.
    #[serde(default)]
    pub at: String,
    /// The facility measured: `"simulated"` (the facility model), or the devices' protocols and
    /// addresses of a real or emulated facility.
    #[serde(default)]
    pub facility: String,
    /// The hilcontact version that measured it.
    #[serde(default)]
    pub version: String,
    /// Probes per surface.
    #[serde(default)]
    #[schemars(range(max = 10000))]
    pub probes_per_wall: u32,
    /// The force each probe pressed to, N (0 to 1e6).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e6))]
    pub press_force: f64,
    /// How long the procedure took, s (0 to 1e6).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e6))]
    pub duration: f64,
}

/// One probed surface: its plane and how well it is known.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CalibratedWall {
    /// The scenario's name of the wall.
    #[serde(default)]
    pub name: String,
    /// The centre of the probed region, on the plane, m (`t` frame).
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 1e3))]
    pub point: [f64; 3],
    /// Normal into free space (non-zero; normalised).
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 1e6))]
    pub normal: [f64; 3],
    /// Standard deviation of the plane's offset along its normal at `point`, m (0 to 1).
    #[schemars(range(min = 0.0, max = 1.0))]
    pub offset_sigma: f64,
    /// Standard deviation of the normal's direction, degrees (0 to 90).
    #[schemars(range(min = 0.0, max = 90.0))]
    pub angle_sigma: f64,
    /// Radius of the probed region around `point`, m (0 to 10): farther, the tilt's
    /// uncertainty grows the offset's.
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 10.0))]
    pub radius: f64,
    /// Probes behind the fit.
    #[serde(default)]
    #[schemars(range(max = 10000))]
    pub probes: u32,
    /// RMS of the law fit's force residual on this surface, N (0 to 1e9).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e9))]
    pub rms: f64,
}

/// The contact law measured, with its standard deviations.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CalibratedLaw {
    /// `"linear"` or `"hunt-crossley"`.
    pub model: ContactModelKind,
    /// k: N/m (linear) or N/mⁿ (Hunt-Crossley), > 0, <= 1e15.
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e15))]
    pub stiffness: f64,
    /// c: N·s/m (linear) or N·s/mⁿ⁺¹ (Hunt-Crossley), 0 to 1e15.
    #[schemars(range(min = 0.0, max = 1e15))]
    pub damping: f64,
    /// n (Hunt-Crossley; 1 for the linear law), > 0, <= 5.
    #[serde(default = "one")]
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 5.0))]
    pub exponent: f64,
    /// Standard deviation of k, same unit (0 to 1e15).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e15))]
    pub stiffness_sigma: f64,
    /// Standard deviation of c, same unit (0 to 1e15).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e15))]
    pub damping_sigma: f64,
    /// Standard deviation of n (0 to 5).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 5.0))]
    pub exponent_sigma: f64,
}

fn one() -> f64 {
    1.0
}

impl Default for CalibratedLaw {
    fn default() -> Self {
        CalibratedLaw {
            model: ContactModelKind::Linear,
            stiffness: 1.0,
            damping: 0.0,
            exponent: 1.0,
            stiffness_sigma: 0.0,
            damping_sigma: 0.0,
            exponent_sigma: 0.0,
        }
    }
}

/// The robot's response measured from command against feedback.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema, Default)]
#[serde(deny_unknown_fields)]
pub struct CalibratedRobot {
    /// Pure delay τ_r, s, as `facility.robot_delay` counts it (0 to 60).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 60.0))]
    pub delay: f64,
    /// Its standard deviation, s (0 to 60).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 60.0))]
    pub delay_sigma: f64,
    /// Servo lag natural frequency, Hz (0: none found; <= 1e4).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e4))]
    pub servo_frequency: f64,
    /// Servo lag damping ratio (0 to 100; 0 without a lag).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 100.0))]
    pub servo_damping: f64,
    /// The sensor delay the procedure assumed (the scenario's `facility.sensor_delay`), s.
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 60.0))]
    pub sensor_delay: f64,
}

/// A calibrated surface in the types the physics uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibratedSurface {
    /// The plane (point m, unit normal), `t` frame.
    pub wall: Wall,
    /// Standard deviation of its offset at `wall.point`, m.
    pub offset_sigma: f64,
    /// Standard deviation of its normal's direction, rad.
    pub angle_sigma: f64,
    /// Radius of the probed region, m.
    pub radius: f64,
    /// Relative standard deviation of the law's stiffness.
    pub stiffness_relative_sigma: f64,
    /// Standard deviation of the law's damping, N·s/m (N·s/mⁿ⁺¹ for Hunt-Crossley).
    pub damping_sigma: f64,
}

impl CalibratedSurface {
    /// The plane's standard deviation along its normal at `p` (m): the offset's and the
    /// tilt's times the distance from the probed point, combined.
    pub fn sigma_at(&self, p: &Vector3<f64>) -> f64 {
        let lateral =
            (p - self.wall.point) - self.wall.normal * (p - self.wall.point).dot(&self.wall.normal);
        let tilt = self.angle_sigma * lateral.norm();
        (self.offset_sigma * self.offset_sigma + tilt * tilt).sqrt()
    }
}

/// A validated calibration: surfaces and the law.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// The surfaces.
    pub surfaces: Vec<CalibratedSurface>,
    /// The law.
    pub law: ContactModel,
    /// Relative standard deviation of the law's stiffness.
    pub stiffness_relative_sigma: f64,
    /// The robot's delay, s.
    pub robot_delay: f64,
}

impl CalibrationFile {
    /// Whether it holds no calibration (no walls).
    pub fn is_empty(&self) -> bool {
        self.walls.is_empty()
    }

    /// Checks the values a schema cannot (finite points, non-zero normals) and returns the
    /// calibration in the physics' types; `Err` lists `(key, message)` of every problem, keys
    /// relative to the calibration (`walls[0].normal`).
    pub fn check(&self) -> Result<Calibration, Vec<(String, String)>> {
        let mut problems = Vec::new();
        let mut surfaces = Vec::new();
        for (i, w) in self.walls.iter().enumerate() {
            let point = Vector3::from(w.point);
            let normal = Vector3::from(w.normal);
            if !point.iter().all(|x| x.is_finite()) {
                problems.push((
                    format!("walls[{i}].point"),
                    format!("must contain finite numbers, got {:?}", w.point),
                ));
            }
            if !normal.iter().all(|x| x.is_finite()) || normal.norm() < 1e-12 {
                problems.push((
                    format!("walls[{i}].normal"),
                    format!("must be a finite nonzero vector, got {:?}", w.normal),
                ));
                continue;
            }
            surfaces.push(CalibratedSurface {
                wall: Wall {
                    point,
                    normal: normal.normalize(),
                },
                offset_sigma: w.offset_sigma,
                angle_sigma: w.angle_sigma.to_radians(),
                radius: w.radius,
                stiffness_relative_sigma: self.law.stiffness_sigma / self.law.stiffness,
                damping_sigma: self.law.damping_sigma,
            });
        }
        if self.walls.is_empty() {
            problems.push(("walls".into(), "at least one wall is required".into()));
        }
        let l = &self.law;
        let law = ContactModel::new(l.model, l.stiffness, l.damping, l.exponent);
        if !(l.stiffness > 0.0 && l.stiffness.is_finite()) {
            problems.push((
                "law.stiffness".into(),
                format!("must be a positive number, got {}", l.stiffness),
            ));
        }
        if problems.is_empty() {
            Ok(Calibration {
                surfaces,
                law,
                stiffness_relative_sigma: l.stiffness_sigma / l.stiffness,
                robot_delay: self.robot.delay,
            })
        } else {
            Err(problems)
        }
    }
}
