//! The contact surface under friction: its normal n̂ and friction coefficient μ̂, identified
//! from the measured force and the robot's motion (the identification samples of
//! [`super::delay::ContactEstimator`]).
//!
//! With friction the force on the frame is not along the normal:
//! `F = F_n·(n + μ·ŝ)` while sliding (n into the wall, ŝ the rod tip's sliding direction), so
//! `e = F/|F|` leans by `atan μ` towards the sliding. The normal is found from the contact
//! law instead: along the true normal the force is a function of the penetration alone,
//! `F·n = k·d + c·ḋ` with `d = −(p − p_w)·n + const`, `ḋ = −v·n`, while along any other
//! direction the sliding `s` enters the penetration (`d′ = d·cos δ + s·sin δ`) and the fit
//! breaks. For a trial normal `n` the least-squares residual of
//! ```text
//! F·n + k·(p − p₀)·n + c·v·n − b = 0          over the contact's samples, k, c, b free
//! ```
//! is a quadratic form of `n` in the samples' moments `M = Σ z·zᵀ`, `z = [F, p − p₀, v, 1]`
//! (10×10, accumulated once per sample, allocation-free): [`SurfaceFit::residual`]. The normal
//! is its minimum (relative residual, so that a trial normal across the force cannot win by
//! making `F·n` vanish) in the plane of the mean force and the robot's sliding (friction on
//! the frame points along the sliding, so the normal lies in that plane, leaning from the mean
//! force away from the sliding; across it a straight slide determines nothing), by a scan and
//! Newton steps on the lean; its standard error is `√(2·σ²/H)`, `H` the residual's curvature
//! in the lean and `σ²` the residual per degree of freedom.
//!
//! The friction coefficient: over the samples that slide (`|v_t| > SLIDE_SPEED`, `v_t` the
//! robot tip's velocity less its normal part), the least squares of `F_t·ŝ = μ·F_n`:
//! `μ̂ = Σ F_n·(F_t·ŝ) / Σ F_n²` (the Coulomb law; the regularisation and the Stribeck peak of
//! the engine's friction lower or raise it below a few mm/s, hence the threshold).
//!
//! A contact whose fitted normal leans from its mean force by less than `atan FRICTION_MIN`
//! (or [`LEAN_SIGMAS`] standard errors) is frictionless: the compensators then use the force direction as the normal, exactly as
//! without this module (so frictionless runs keep their numbers to the bit).

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// The samples' moments `Σ z·zᵀ`, `z = [F (N), p − p₀ (m), v (m/s), 1]`.
type Moments = SMatrix<f64, 10, 10>;

/// Below this friction coefficient (the tangent of the lean of the mean force from the fitted
/// normal) a contact counts as frictionless (2.9°: a noisy frictionless contact's fitted
/// normal is off by up to about 0.4°).
pub const FRICTION_MIN: f64 = 0.05;
/// A lean counts only above this many standard errors of the fitted normal.
pub const LEAN_SIGMAS: f64 = 5.0;
/// Fewest samples for a lean to count (a noisy contact's first samples can fit a spurious
/// lean with a small stated error).
pub const LEAN_SAMPLES: usize = 40;
/// Fewest samples sliding across the mean force (faster than [`SLIDE_SPEED`]) for a lean to
/// count: friction leans the force only while the tip slides.
pub const LEAN_SLIDING: usize = 10;
/// Fewest samples before a contact's own normal is fitted.
pub const MIN_FIT_SAMPLES: usize = 20;
/// Largest standard error of a fitted normal for the compensators to use it, rad (0.5°).
pub const NORMAL_STD_MAX: f64 = 0.5 * std::f64::consts::PI / 180.0;
/// A sample slides (enters μ̂) above this tangential speed of the robot tip, m/s.
pub const SLIDE_SPEED: f64 = 3e-3;
/// Largest lean of a fitted normal from the mean force, rad (μ ≤ 2).
const MAX_LEAN: f64 = 1.107;
/// Angle step of the numerical derivative, rad.
const ANGLE_STEP: f64 = 1e-4;

/// Two unit vectors perpendicular to `n` and to each other.
#[cfg(test)]
fn tangents(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let u = n.cross(&helper).normalize();
    (u, n.cross(&u))
}

/// The fit of one contact's surface (see the module doc). Allocation-free.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceFit {
    moments: Moments,
    origin: Vector3<f64>,
    samples: usize,
    force_sum: Vector3<f64>,
    /// Fitted normal (into the wall, unit), zero before the first fit.
    normal: Vector3<f64>,
    normal_std: f64,
    /// Σ F_n·(F_t·ŝ) and Σ F_n² over the sliding samples, with the normal of their tick.
    friction_sums: (f64, f64),
    /// Samples whose robot tip moved across the mean force faster than [`SLIDE_SPEED`].
    sliding: usize,
}

impl Default for SurfaceFit {
    fn default() -> Self {
        SurfaceFit {
            moments: Moments::zeros(),
            origin: Vector3::zeros(),
            samples: 0,
            force_sum: Vector3::zeros(),
            normal: Vector3::zeros(),
            normal_std: f64::INFINITY,
            friction_sums: (0.0, 0.0),
            sliding: 0,
        }
    }
}

impl SurfaceFit {
    /// Forgets the contact.
    pub fn reset(&mut self) {
        *self = SurfaceFit::default();
    }

    /// Number of samples added.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// Direction of the samples' summed force (into the wall; zero without samples).
    pub fn mean_direction(&self) -> Vector3<f64> {
        let norm = self.force_sum.norm();
        if norm > 0.0 {
            self.force_sum / norm
        } else {
            Vector3::zeros()
        }
    }

    /// Adds one contact sample: force on the frame `force` (N), robot tip position (m) and
    /// velocity (m/s) that produced it, `t` frame.
    pub fn add(&mut self, force: &Vector3<f64>, position: &Vector3<f64>, velocity: &Vector3<f64>) {
        if self.samples == 0 {
            self.origin = *position;
        }
        let q = position - self.origin;
        let mut z = SVector::<f64, 10>::zeros();
        z.fixed_rows_mut::<3>(0).copy_from(force);
        z.fixed_rows_mut::<3>(3).copy_from(&q);
        z.fixed_rows_mut::<3>(6).copy_from(velocity);
        z[9] = 1.0;
        self.moments.ger(1.0, &z, &z, 1.0);
        self.samples += 1;
        self.force_sum += force;
        let mean = self.mean_direction();
        if (velocity - mean * velocity.dot(&mean)).norm() > SLIDE_SPEED {
            self.sliding += 1;
        }
    }

    /// Adds a sample to the friction sums with normal `normal` (into the wall): if the tip
    /// slides faster than [`SLIDE_SPEED`] and pushes, `F_n·(F_t·ŝ)` and `F_n²`.
    pub fn add_friction(
        &mut self,
        force: &Vector3<f64>,
        velocity: &Vector3<f64>,
        normal: &Vector3<f64>,
    ) {
        let f_n = force.dot(normal);
        let v_t = velocity - normal * velocity.dot(normal);
        let speed = v_t.norm();
        if f_n <= 0.0 || speed <= SLIDE_SPEED {
            return;
        }
        let f_t = force - normal * f_n;
        self.friction_sums.0 += f_n * f_t.dot(&(v_t / speed));
        self.friction_sums.1 += f_n * f_n;
    }

    /// The friction coefficient of the sliding samples, and the weight `Σ F_n²` (N²) it rests
    /// on (0: no sliding sample).
    pub fn friction(&self) -> (f64, f64) {
        let (num, den) = self.friction_sums;
        if den > 0.0 {
            ((num / den).max(0.0), den)
        } else {
            (0.0, 0.0)
        }
    }

    /// The least-squares residual (N²) of the normal law along the trial normal `n`, and the
    /// variance of `F·n` about its mean (N², summed over the samples). Computed from the
    /// centred moments with the regressors scaled to unit variance (the raw moments' constant
    /// column made the residual, a millionth of the force's variance, rounding noise).
    pub fn residual(&self, n: &Vector3<f64>) -> (f64, f64) {
        let count = self.samples as f64;
        if self.samples < 4 {
            return (0.0, 0.0);
        }
        let block = |i: usize, j: usize| -> f64 {
            let m: Matrix3<f64> = self.moments.fixed_view::<3, 3>(3 * i, 3 * j).into_owned();
            n.dot(&(m * n))
        };
        let sum = |i: usize| -> f64 {
            let m: Vector3<f64> = self.moments.fixed_view::<3, 1>(3 * i, 9).into_owned();
            n.dot(&m)
        };
        // centred sums of products of y = F·n, x1 = q·n, x2 = v·n
        let (sy, s1, s2) = (sum(0), sum(1), sum(2));
        let c = |a: f64, sa: f64, sb: f64| a - sa * sb / count;
        let cyy = c(block(0, 0), sy, sy).max(0.0);
        let cy1 = c(block(0, 1), sy, s1);
        let cy2 = c(block(0, 2), sy, s2);
        let c11 = c(block(1, 1), s1, s1).max(0.0);
        let c12 = c(block(1, 2), s1, s2);
        let c22 = c(block(2, 2), s2, s2).max(0.0);
        if c11 <= 0.0 || c22 <= 0.0 {
            return (cyy, cyy);
        }
        // scaled: r_i = c_yi/√c_ii, correlation ρ = c12/√(c11 c22)
        let (d1, d2) = (c11.sqrt(), c22.sqrt());
        let (r1, r2) = (cy1 / d1, cy2 / d2);
        let rho = (c12 / (d1 * d2)).clamp(-1.0, 1.0);
        let det = 1.0 - rho * rho;
        let explained = if det > 1e-12 {
            (r1 * r1 - 2.0 * rho * r1 * r2 + r2 * r2) / det
        } else {
            r1 * r1
        };
        ((cyy - explained).max(0.0), cyy)
    }

    /// Relative residual of the trial normal (0 to 1).
    fn relative(&self, n: &Vector3<f64>) -> f64 {
        let (r, v) = self.residual(n);
        if v > 0.0 {
            r / v
        } else {
            1.0
        }
    }

    /// The plane the normal is sought in: the mean force's direction `ē` and the direction
    /// `ŝ′` of the robot's mean velocity across it (the sliding: friction on the frame points
    /// along it, so the normal leans from `ē` away from it). `None` while nothing slides.
    fn lean_plane(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let mean = self.mean_direction();
        let velocity: Vector3<f64> = self.moments.fixed_view::<3, 1>(6, 9).into_owned();
        let across = velocity - mean * velocity.dot(&mean);
        let count = self.samples.max(1) as f64;
        (mean != Vector3::zeros() && across.norm() / count > 1e-2 * SLIDE_SPEED)
            .then(|| (mean, across.normalize()))
    }

    /// The trial normal at lean `theta` (rad) in the plane `(ē, ŝ′)`.
    fn leaned(plane: &(Vector3<f64>, Vector3<f64>), theta: f64) -> Vector3<f64> {
        plane.0 * theta.cos() - plane.1 * theta.sin()
    }

    /// Refits the normal, once there are [`MIN_FIT_SAMPLES`]: the lean `θ` in the plane of
    /// the mean force and the sliding ([`SurfaceFit::lean_plane`]; the normal's tilt across it
    /// changes nothing in a straight slide, and friction lies in it) that minimises the
    /// relative residual, by a scan every 8 samples (2° steps up to `MAX_LEAN`) and Newton
    /// steps from the last lean otherwise. Returns the normal and its standard error (rad;
    /// infinite while it is not determined). Allocation-free.
    pub fn fit(&mut self, iterations: usize) -> (Vector3<f64>, f64) {
        let mean = self.mean_direction();
        let Some(plane) = self
            .lean_plane()
            .filter(|_| self.samples >= MIN_FIT_SAMPLES)
        else {
            self.normal_std = f64::INFINITY;
            return (mean, f64::INFINITY);
        };
        let at = |theta: f64| self.relative(&Self::leaned(&plane, theta));
        // θ of the last normal (n = cos θ ē − sin θ ŝ′), 0 at the first fit
        let mut theta = if self.normal == Vector3::zeros() {
            0.0
        } else {
            (-self.normal.dot(&plane.1)).atan2(self.normal.dot(&plane.0))
        };
        if self.normal == Vector3::zeros() || self.samples % 8 == 0 {
            let step = 2f64.to_radians();
            let mut best = (at(theta), theta);
            let mut x = -5f64.to_radians();
            while x <= MAX_LEAN {
                let f = at(x);
                if f < best.0 {
                    best = (f, x);
                }
                x += step;
            }
            theta = best.1;
        }
        let h = ANGLE_STEP;
        let mut curvature = 0.0;
        for _ in 0..iterations.max(1) + 2 {
            let (f0, fp, fm) = (at(theta), at(theta + h), at(theta - h));
            let slope = (fp - fm) / (2.0 * h);
            curvature = (fp - 2.0 * f0 + fm) / (h * h);
            if curvature <= 0.0 {
                break;
            }
            let step = (-slope / curvature).clamp(-0.035, 0.035);
            if at(theta + step) <= f0 {
                theta += step;
            } else {
                break;
            }
            if step.abs() < 1e-9 {
                break;
            }
        }
        let n = Self::leaned(&plane, theta);
        self.normal = n;
        // standard error of θ: 2σ²/H_r, H_r = v·d²ρ/dθ² the residual's own curvature
        let (r, v) = self.residual(&n);
        let dof = (self.samples as f64 - 4.0).max(1.0);
        let sigma2 = r / dof + (1e-6 * v / self.samples as f64);
        let stiff = curvature * v;
        self.normal_std = if stiff > 0.0 {
            (2.0 * sigma2 / stiff).sqrt()
        } else {
            f64::INFINITY
        };
        (self.normal, self.normal_std)
    }

    /// The normal law along `n` (into the wall) by least squares over the samples:
    /// `F·n = k·(p − p₀)·n + c·v·n + b`; returns `(k, c)` (N/m, N·s/m) and their standard
    /// errors (from the residual per degree of freedom), or `None` when singular.
    pub fn law(&self, n: &Vector3<f64>) -> Option<((f64, f64), (f64, f64))> {
        let block = |i: usize, j: usize| -> f64 {
            let m: Matrix3<f64> = self.moments.fixed_view::<3, 3>(3 * i, 3 * j).into_owned();
            n.dot(&(m * n))
        };
        let with_one = |i: usize| -> f64 {
            let m: Vector3<f64> = self.moments.fixed_view::<3, 1>(3 * i, 9).into_owned();
            n.dot(&m)
        };
        let g = Vector3::new(block(0, 1), block(0, 2), with_one(0));
        let (g11, g12, g22) = (block(1, 1), block(1, 2), block(2, 2));
        let (g13, g23, g33) = (with_one(1), with_one(2), self.moments[(9, 9)]);
        let gr = Matrix3::new(g11, g12, g13, g12, g22, g23, g13, g23, g33);
        let inverse = gr.try_inverse()?;
        let beta = inverse * g;
        let (r, _) = self.residual(n);
        let sigma2 = r / (self.samples as f64 - 3.0).max(1.0);
        Some((
            (beta[0], beta[1]),
            (
                (sigma2 * inverse[(0, 0)]).max(0.0).sqrt(),
                (sigma2 * inverse[(1, 1)]).max(0.0).sqrt(),
            ),
        ))
    }

    /// The last fitted normal (into the wall, zero before the first fit) and its standard
    /// error, rad.
    pub fn normal(&self) -> (Vector3<f64>, f64) {
        (self.normal, self.normal_std)
    }

    /// Whether the last fit is good enough to use ([`NORMAL_STD_MAX`]).
    pub fn is_determined(&self) -> bool {
        self.normal_std < NORMAL_STD_MAX && self.normal != Vector3::zeros()
    }

    /// Whether the fitted normal leans from the mean force by more than `atan FRICTION_MIN`
    /// and [`LEAN_SIGMAS`] standard errors, on at least [`LEAN_SAMPLES`] samples, and the
    /// mean force's direction explains the samples significantly worse than the fitted normal
    /// (residual larger by [`LEAN_SIGMAS`]² times the residual per degree of freedom): friction
    /// at work.
    pub fn leans(&self) -> bool {
        // friction needs sliding: without it a lean is the noise's
        if !self.is_determined() || self.samples < LEAN_SAMPLES || self.sliding < LEAN_SLIDING {
            return false;
        }
        let mean = self.mean_direction();
        let lean = mean.dot(&self.normal).clamp(-1.0, 1.0).acos();
        let (at_normal, _) = self.residual(&self.normal);
        let (at_mean, _) = self.residual(&mean);
        let sigma2 = at_normal / (self.samples as f64 - 4.0).max(1.0);
        lean > FRICTION_MIN.atan().max(LEAN_SIGMAS * self.normal_std)
            && at_mean - at_normal > LEAN_SIGMAS * LEAN_SIGMAS * sigma2
    }
}

/// One surface of a corner contact as [`CornerFit`] identifies it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerSurface {
    /// Stiffness k̂, N/m.
    pub stiffness: f64,
    /// Damping ĉ, N·s/m.
    pub damping: f64,
    /// Friction coefficient μ̂.
    pub friction: f64,
}

/// The unknowns of [`CornerFit`]: per surface `k, c, μ·k, μ·c`.
type CornerMoments = SMatrix<f64, 8, 8>;

/// A contact pressing two surfaces at once (a corner, an edge): the measured force split into
/// the two surfaces' laws, with each surface's geometry known (from the scenario's shapes as the
/// prior, or identified planes). With `n_i` surface i's normal (into it), `d_i = (p − p_i)·n_i`
/// the penetration of the robot tip `p` (`p_i` a point of the surface), `ḋ_i = v·n_i`, and
/// `ŝ_i` the tip's sliding direction on the surface (its velocity less the normal part), the
/// force on the frame is, while each pressed surface slides,
/// ```text
/// F = Σ_i (k_i·d_i + c_i·ḋ_i)·(n_i + μ_i·ŝ_i)
///   = Σ_i [k_i·d_i·n_i + c_i·ḋ_i·n_i + (μ_i k_i)·d_i·ŝ_i + (μ_i c_i)·ḋ_i·ŝ_i]
/// ```
/// linear in the eight unknowns `(k_i, c_i, μ_i k_i, μ_i c_i)`: least squares over the samples
/// (three equations each), `μ̂_i = (μ_i k_i)^/k̂_i`. Samples where a pressed surface does not
/// slide (faster than [`SLIDE_SPEED`]) are left out (sticking friction is not `μ·F_n`); a
/// sample pressing one surface only enters that surface's columns. Allocation-free.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerFit {
    normals: [Vector3<f64>; 2],
    points: [Vector3<f64>; 2],
    moments: CornerMoments,
    right: SVector<f64, 8>,
    samples: usize,
}

impl CornerFit {
    /// A fit for the surfaces of normals `normals` (into each surface, unit) through `points`
    /// (m, `t` frame).
    pub fn new(normals: [Vector3<f64>; 2], points: [Vector3<f64>; 2]) -> Self {
        CornerFit {
            normals,
            points,
            moments: CornerMoments::zeros(),
            right: SVector::zeros(),
            samples: 0,
        }
    }

    /// Samples used so far.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// Adds a sample: force on the frame (N), robot tip position (m) and velocity (m/s) that
    /// produced it. Returns whether it was used (a surface pressed, every pressed one sliding).
    pub fn add(
        &mut self,
        force: &Vector3<f64>,
        position: &Vector3<f64>,
        velocity: &Vector3<f64>,
    ) -> bool {
        let mut columns = [Vector3::zeros(); 8];
        let mut pressed = false;
        for i in 0..2 {
            let n = self.normals[i];
            let d = (position - self.points[i]).dot(&n);
            if d <= 0.0 {
                continue;
            }
            let v_t = velocity - n * velocity.dot(&n);
            let speed = v_t.norm();
            if speed <= SLIDE_SPEED {
                return false;
            }
            let (rate, slide) = (velocity.dot(&n), v_t / speed);
            columns[4 * i] = n * d;
            columns[4 * i + 1] = n * rate;
            columns[4 * i + 2] = slide * d;
            columns[4 * i + 3] = slide * rate;
            pressed = true;
        }
        if !pressed {
            return false;
        }
        for a in 0..8 {
            self.right[a] += columns[a].dot(force);
            for b in 0..8 {
                self.moments[(a, b)] += columns[a].dot(&columns[b]);
            }
        }
        self.samples += 1;
        true
    }

    /// The two surfaces' laws and friction coefficients, or `None` while the samples do not
    /// determine them (a surface never pressed, or its penetration and rate not independent).
    pub fn fit(&self) -> Option<[CornerSurface; 2]> {
        // scaled to unit diagonal: the columns' sizes differ by orders of magnitude
        let mut scale = SVector::<f64, 8>::zeros();
        for a in 0..8 {
            let m = self.moments[(a, a)];
            if m <= 0.0 {
                return None;
            }
            scale[a] = m.sqrt().recip();
        }
        let scaled = CornerMoments::from_fn(|a, b| self.moments[(a, b)] * scale[a] * scale[b]);
        let beta = scaled
            .cholesky()?
            .solve(&self.right.component_mul(&scale))
            .component_mul(&scale);
        let surface = |i: usize| CornerSurface {
            stiffness: beta[4 * i],
            damping: beta[4 * i + 1],
            friction: if beta[4 * i] > 0.0 {
                (beta[4 * i + 2] / beta[4 * i]).max(0.0)
            } else {
                0.0
            },
        };
        Some([surface(0), surface(1)])
    }
}

#[cfg(test)]
mod corner_tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    /// A random corner (two planes 60-120° apart), laws and friction; a tip pressing both
    /// while sliding along their edge, the penetrations varying independently; the force of
    /// the laws with Coulomb friction on each surface, plus Gaussian noise `noise` (N per
    /// axis). Returns the worst |μ̂ − μ| and |k̂/k − 1| over `count` corners.
    fn corners(seed: u64, count: usize, noise: f64) -> (f64, f64) {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        let gauss = Normal::new(0.0, 1.0).expect("normal");
        let (mut worst_mu, mut worst_k) = (0.0f64, 0.0f64);
        for _ in 0..count {
            let n1 = Vector3::new(1.0, 0.0, 0.0);
            let angle = rng.random_range(60f64..120.0).to_radians();
            let tilt = rng.random_range(-0.3f64..0.3);
            let n2 = Vector3::new(
                angle.cos(),
                angle.sin() * tilt.cos(),
                angle.sin() * tilt.sin(),
            );
            let edge = n1.cross(&n2).normalize();
            let corner = Vector3::new(0.1, -0.2, 0.05);
            let k = [rng.random_range(1e5..3e5), rng.random_range(1e5..3e5)];
            let c = [rng.random_range(0.0..200.0), rng.random_range(0.0..200.0)];
            let mu = [rng.random_range(0.1..0.3), rng.random_range(0.1..0.3)];
            let slide = rng.random_range(0.01..0.03); // m/s along the edge
            let (w1, w2) = (rng.random_range(20.0..40.0), rng.random_range(45.0..70.0));
            // p with (p − corner)·n_i = d_i and (p − corner)·edge = s: the dual basis
            let basis = Matrix3::from_rows(&[n1.transpose(), n2.transpose(), edge.transpose()]);
            let inverse = basis.try_inverse().expect("basis");
            let mut fit = CornerFit::new([n1, n2], [corner, corner]);
            for j in 0..400 {
                let t = j as f64 * 1e-3;
                let d = [
                    2e-4 + 1.5e-4 * (w1 * t).sin(),
                    2e-4 + 1.5e-4 * (w2 * t + 1.0).sin(),
                ];
                let rate = [
                    1.5e-4 * w1 * (w1 * t).cos(),
                    1.5e-4 * w2 * (w2 * t + 1.0).cos(),
                ];
                let p = corner + inverse * Vector3::new(d[0], d[1], slide * t);
                let v = inverse * Vector3::new(rate[0], rate[1], slide);
                let mut force = Vector3::zeros();
                for (i, n) in [n1, n2].iter().enumerate() {
                    let f_n = (k[i] * d[i] + c[i] * rate[i]).max(0.0);
                    let v_t = v - n * v.dot(n);
                    force += (n + v_t.normalize() * mu[i]) * f_n;
                }
                let noisy = force + Vector3::from_fn(|_, _| noise * gauss.sample(&mut rng));
                fit.add(&noisy, &p, &v);
            }
            let surfaces = fit.fit().expect("determined");
            for i in 0..2 {
                worst_mu = worst_mu.max((surfaces[i].friction - mu[i]).abs());
                worst_k = worst_k.max((surfaces[i].stiffness / k[i] - 1.0).abs());
            }
        }
        (worst_mu, worst_k)
    }

    #[test]
    fn a_clean_corner_is_split_into_its_two_surfaces() {
        let (mu, k) = corners(22, 20, 0.0);
        println!("clean: worst μ error {mu:.2e}, k error {k:.2e}");
        assert!(mu <= 0.03 && k <= 0.02, "μ {mu}, k {k}");
    }

    #[test]
    fn a_noisy_corner_is_split_into_its_two_surfaces() {
        let (mu, k) = corners(23, 20, 0.2);
        println!("0.2 N noise: worst μ error {mu:.2e}, k error {k:.2e}");
        assert!(mu <= 0.05 && k <= 0.05, "μ {mu}, k {k}");
    }

    /// One surface never pressed: the fit says so instead of inventing it.
    #[test]
    fn a_surface_never_pressed_is_not_determined() {
        let n1 = Vector3::x();
        let n2 = Vector3::y();
        let mut fit = CornerFit::new([n1, n2], [Vector3::zeros(), Vector3::new(0.0, 1.0, 0.0)]);
        for j in 0..100 {
            let t = j as f64 * 1e-3;
            let p = Vector3::new(1e-4 * (1.0 + (30.0 * t).sin()), 0.0, 0.02 * t);
            let v = Vector3::new(3e-3 * (30.0 * t).cos(), 0.0, 0.02);
            let force = (n1 + Vector3::z() * 0.2) * (1e5 * p.x);
            fit.add(&force, &p, &v);
        }
        assert!(fit.samples() > 0);
        assert!(fit.fit().is_none());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An oblique sliding contact of a linear law with Coulomb friction, sampled like the
    /// estimator samples it: the fit finds the normal, and μ from the sliding samples.
    #[test]
    fn finds_the_normal_and_the_coefficient_of_a_sliding_contact() {
        let n_out = Vector3::new(-0.8924, -0.4161, 0.1736).normalize(); // into free space
        let n = -n_out; // into the wall
        let (k, c, mu, m) = (176_275.0, 130.0, 0.2, 279.0);
        let (t_hat, _) = tangents(&n);
        let (mut p, mut v) = (Vector3::zeros(), n * 0.02 + t_hat * 0.03);
        let mut fit = SurfaceFit::default();
        for _ in 0..2000 {
            let d = p.dot(&n);
            if d < 0.0 && fit.samples() > 0 {
                break;
            }
            let d_dot = v.dot(&n);
            let f_n = (k * d.max(0.0) + c * d_dot).max(0.0);
            let v_t = v - n * d_dot;
            let s = v_t.norm();
            let f = n * f_n + v_t * (mu * f_n / (s * s + 1e-6 * 1e-6).sqrt()); // on the frame
            if f.norm() > 3.0 {
                fit.add(&f, &p, &v);
                fit.add_friction(&f, &v, &n);
            }
            v -= f / m * 1e-3;
            p += v * 1e-3;
        }
        let (normal, std) = fit.fit(20);
        let angle = normal.dot(&n).clamp(-1.0, 1.0).acos();
        assert!(angle < 1e-3, "angle {angle} rad, std {std}");
        assert!(fit.is_determined() && fit.leans());
        let (mu_hat, _) = fit.friction();
        assert!((mu_hat - mu).abs() < 0.01, "μ̂ {mu_hat}");
    }
}
