//! Sage-Husa adaptive Kalman filter for the contact stiffness and damping, eqs. (11)-(13).
//!
//! State `X = [k_d, c_d]ᵀ` (N/m, N·s/m), a random walk (`A = G = I`); measurement
//! `Z = ΔF` (N) with `H = [Δd, Δḋ]` (m, m/s): `ΔF = k·Δd + c·Δḋ + v`. The measurement noise
//! R is re-estimated at each update with the amnestic factor `d_t = (1−b)/(1−b^(t+1))`.

use nalgebra::{Matrix2, Vector2};

/// The filter, with the textbook symbols and the last update's intermediates kept inspectable.
#[derive(Debug, Clone, PartialEq)]
pub struct SageHusaFilter {
    /// State estimate X̂ = [k̂, ĉ].
    pub x: Vector2<f64>,
    /// State covariance P.
    pub p: Matrix2<f64>,
    /// Process noise Q (random walk per update).
    pub q: Matrix2<f64>,
    /// Measurement noise R, N².
    pub r: f64,
    /// Forgetting factor b, 0 < b < 1.
    pub b: f64,
    /// Number of updates so far (t).
    pub t: u32,
    /// Last innovation y, N.
    pub y: f64,
    /// Last innovation variance S, N².
    pub s: f64,
    /// Last gain K.
    pub k: Vector2<f64>,
    initial: (Vector2<f64>, Matrix2<f64>, f64),
}

impl SageHusaFilter {
    /// A filter at `x0` with covariance `p0`, process noise `q`, measurement noise `r0`, forgetting `b`.
    pub fn new(x0: Vector2<f64>, p0: Matrix2<f64>, q: Matrix2<f64>, r0: f64, b: f64) -> Self {
        SageHusaFilter {
            x: x0,
            p: p0,
            q,
            r: r0,
            b,
            t: 0,
            y: 0.0,
            s: 0.0,
            k: Vector2::zeros(),
            initial: (x0, p0, r0),
        }
    }

    /// Back to the initial guess.
    pub fn reset(&mut self) {
        (self.x, self.p, self.r) = self.initial;
        self.t = 0;
    }

    /// One update with observation row `h = [Δd, Δḋ]` and measurement `z = ΔF`.
    pub fn update(&mut self, h: &Vector2<f64>, z: f64) {
        // (12) prediction: X⁻ = A X, P⁻ = A P Aᵀ + G Q Gᵀ with A = G = I
        let x_prior = self.x;
        let p_prior = self.p + self.q;
        // innovation y = Z − H X⁻
        self.y = z - h.dot(&x_prior);
        // (13) R(t) = (1 − d_t) R(t−1) + d_t (y yᵀ + H P⁻ Hᵀ), d_t = (1 − b)/(1 − b^(t+1))
        let d_t = (1.0 - self.b) / (1.0 - self.b.powf(self.t as f64 + 1.0));
        let hph = h.dot(&(p_prior * h));
        self.r = (1.0 - d_t) * self.r + d_t * (self.y * self.y + hph);
        // K = P⁻ Hᵀ (H P⁻ Hᵀ + R)⁻¹, with the new R
        self.s = hph + self.r;
        self.k = p_prior * h / self.s;
        // X = X⁻ + K y
        self.x = x_prior + self.k * self.y;
        // P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ  (Joseph form)
        let i_kh = Matrix2::identity() - self.k * h.transpose();
        self.p = i_kh * p_prior * i_kh.transpose() + self.k * self.r * self.k.transpose();
        self.t = self.t.saturating_add(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn filter() -> SageHusaFilter {
        SageHusaFilter::new(
            Vector2::new(1.0e5, 0.0),
            Matrix2::from_diagonal(&Vector2::new(1e10, 9e4)),
            Matrix2::from_diagonal(&Vector2::new(100.0, 0.01)),
            0.01,
            0.98,
        )
    }

    #[test]
    fn recovers_stiffness_and_damping_from_exact_increments() {
        let (k, c) = (176_275.0, 130.0);
        let mut f = filter();
        for i in 0..400 {
            // increments of a contact: Δd ~ v T, Δḋ ~ a T, varying along the contact
            let phase = i as f64 * 0.025;
            let h = Vector2::new(2e-5 * phase.cos(), 5e-4 * phase.sin());
            f.update(&h, k * h[0] + c * h[1]);
        }
        assert!((f.x[0] / k - 1.0).abs() < 1e-3, "k̂ = {}", f.x[0]);
        assert!((f.x[1] - c).abs() < 2.0, "ĉ = {}", f.x[1]);
        assert!(f.p[(0, 0)] > 0.0 && f.p[(1, 1)] > 0.0 && f.r > 0.0);
    }

    #[test]
    fn recovers_stiffness_from_noisy_increments() {
        let (k, c) = (76_900.0, 130.0);
        let mut f = filter();
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        let noise = Normal::new(0.0, 0.28).unwrap();
        for i in 0..2000 {
            let phase = i as f64 * 0.02;
            let h = Vector2::new(2e-5 * phase.cos(), 5e-4 * phase.sin());
            f.update(&h, k * h[0] + c * h[1] + noise.sample(&mut rng));
        }
        assert!((f.x[0] / k - 1.0).abs() < 0.02, "k̂ = {}", f.x[0]);
        // the adapted R tracks the true increment noise (0.28² ≈ 0.078 N²) within a factor 2
        assert!(f.r > 0.03 && f.r < 0.2, "R = {}", f.r);
    }
}
