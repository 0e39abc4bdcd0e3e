//! Contact detection that the sensor's noise level sets.
//!
//! A fixed force threshold cannot serve every sensor: at 0.9–1.0 N of noise per axis single
//! noisy ticks pass the default 3 N and are taken as contact (and a compensator applies a
//! one-tick force against the free flight). The detector estimates the noise online, out of
//! contact, and declares contact with hysteresis:
//!
//! ```text
//! σ̂² ← σ̂² + λ (|F|²/3 − σ̂²)            out of contact, λ = T / τ_σ (τ_σ = 0.1 s)
//! contact starts when |F| > F_on  = max(F_c, 6 σ̂)
//! contact ends   when |F| ≤ F_off = max(F_c, 4 σ̂)
//! quiet (no wall touched) when |F| ≤ F_q = min(F_off, 5 σ̂)
//! ```
//! `F_c` is the compensator's `contact_force`. For Gaussian noise of σ per axis, |F|/σ
//! follows a χ distribution with 3 degrees of freedom: a free-flight tick passes 6σ with
//! probability 1e-7 (once in three hours at 1 kHz). While σ̂ ≤ F_c/6 (0.5 N for the default
//! 3 N) the detector is the fixed threshold `F_c`, as before. A sensor bias counts as noise
//! (it raises σ̂), which keeps it from being taken as contact. The first ticks, before σ̂ has
//! settled, use the largest |F| seen so far as a floor of 2σ̂ (so a noisy start is not taken
//! as contact either).

use nalgebra::Vector3;

/// Time constant of the noise estimate, s.
pub const NOISE_TIME: f64 = 0.1;
/// Contact starts above this many noise standard deviations of one axis.
pub const ON_SIGMAS: f64 = 6.0;
/// Contact ends at or below this many.
pub const OFF_SIGMAS: f64 = 4.0;
/// A force at or below this many noise standard deviations is quiet: no exchange with a wall.
pub const QUIET_SIGMAS: f64 = 5.0;

/// Noise-aware contact detection with hysteresis (see the module doc). Allocation-free.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactDetector {
    /// The compensator's fixed threshold F_c, N.
    base: f64,
    /// Weight of one tick in the noise estimate, λ = T / τ_σ.
    lambda: f64,
    /// Noise variance estimate σ̂² per axis, N².
    variance: f64,
    /// Ticks seen out of contact (the estimate's warm-up).
    free_ticks: usize,
    /// Largest |F| of the warm-up, N.
    warmup_peak: f64,
    in_contact: bool,
}

impl ContactDetector {
    /// A detector with threshold `base` (N) for a loop of `period` (s).
    pub fn new(base: f64, period: f64) -> Self {
        ContactDetector {
            base,
            lambda: (period / NOISE_TIME).min(1.0),
            variance: 0.0,
            free_ticks: 0,
            warmup_peak: 0.0,
            in_contact: false,
        }
    }

    /// Forgets the noise estimate and the contact.
    pub fn reset(&mut self) {
        self.variance = 0.0;
        self.free_ticks = 0;
        self.warmup_peak = 0.0;
        self.in_contact = false;
    }

    /// The estimated noise standard deviation per axis, N.
    pub fn noise(&self) -> f64 {
        let warmup = 1.0 / self.lambda;
        if (self.free_ticks as f64) < warmup {
            // not settled yet: the largest |F| seen bounds σ̂ from below (as 2σ̂)
            self.variance.sqrt().max(0.5 * self.warmup_peak)
        } else {
            self.variance.sqrt()
        }
    }

    /// The force above which contact starts, N.
    pub fn on_threshold(&self) -> f64 {
        self.base.max(ON_SIGMAS * self.noise())
    }

    /// The force at or below which contact ends, N.
    pub fn off_threshold(&self) -> f64 {
        self.base.max(OFF_SIGMAS * self.noise())
    }

    /// The force at or below which no wall is touched, N: `min(F_off, 5 σ̂)` (0 without
    /// noise). Between it and the contact thresholds lies the force of a contact's first and
    /// last ticks, which does work (an energy observer must count it) but is too small to tell
    /// contact by; below it lies the noise (a noise tick passes 5 σ̂ with probability 1.5e-5).
    pub fn quiet_threshold(&self) -> f64 {
        (QUIET_SIGMAS * self.noise()).min(self.off_threshold())
    }

    /// The level the force is compared with now: `F_off` in contact, `F_on` out of it, N.
    pub fn level(&self) -> f64 {
        if self.in_contact {
            self.off_threshold()
        } else {
            self.on_threshold()
        }
    }

    /// Whether the detector is in contact.
    pub fn in_contact(&self) -> bool {
        self.in_contact
    }

    /// One tick's force (N): updates the contact state and, out of contact, the noise
    /// estimate; returns whether the tick is in contact.
    pub fn update(&mut self, force: &Vector3<f64>) -> bool {
        let magnitude = force.norm();
        self.in_contact = magnitude > self.level();
        if !self.in_contact {
            let sample = magnitude * magnitude / 3.0;
            self.free_ticks += 1;
            let warmup = 1.0 / self.lambda;
            if (self.free_ticks as f64) <= warmup {
                // the mean of the first samples, then the exponential average
                self.variance += (sample - self.variance) / self.free_ticks as f64;
                self.warmup_peak = self.warmup_peak.max(magnitude);
            } else {
                self.variance += self.lambda * (sample - self.variance);
            }
        }
        self.in_contact
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    use rand_pcg::Pcg64Mcg;

    fn noise(rng: &mut Pcg64Mcg, sigma: f64) -> Vector3<f64> {
        let n = Normal::new(0.0, sigma).unwrap();
        Vector3::from_fn(|_, _| n.sample(rng))
    }

    #[test]
    fn without_noise_it_is_the_fixed_threshold() {
        let mut d = ContactDetector::new(3.0, 1e-3);
        for _ in 0..200 {
            assert!(!d.update(&Vector3::zeros()));
        }
        assert!(!d.update(&Vector3::new(2.9, 0.0, 0.0)));
        assert!(d.update(&Vector3::new(3.1, 0.0, 0.0)));
        assert!(!d.update(&Vector3::new(2.9, 0.0, 0.0)));
        assert_eq!(d.on_threshold(), 3.0);
    }

    #[test]
    fn noise_up_to_one_newton_is_never_taken_as_contact_and_a_contact_still_is() {
        for sigma in [0.2, 0.5, 1.0, 2.0] {
            let mut rng = Pcg64Mcg::seed_from_u64(7);
            let mut d = ContactDetector::new(3.0, 1e-3);
            let false_alarms = (0..100_000)
                .filter(|_| d.update(&noise(&mut rng, sigma)))
                .count();
            assert_eq!(false_alarms, 0, "σ = {sigma}");
            assert!(
                (d.noise() / sigma - 1.0).abs() < 0.15,
                "σ̂ {} for {sigma}",
                d.noise()
            );
            // a 100 N contact is detected, held through its noisy tail and released
            assert!(d.update(&(Vector3::new(100.0, 0.0, 0.0) + noise(&mut rng, sigma))));
            let hold = d.off_threshold() + 0.5;
            assert!(hold < d.on_threshold() || sigma <= 0.5, "hysteresis");
            assert!(d.update(&Vector3::new(hold, 0.0, 0.0)));
            assert!(!d.update(&Vector3::zeros()));
            // the quiet level: above the noise, at most the level contact ends at
            let quiet = d.quiet_threshold();
            assert!(quiet <= d.off_threshold(), "σ = {sigma}");
            assert!(
                (quiet / (QUIET_SIGMAS * sigma) - 1.0).abs() < 0.15 || quiet == d.off_threshold()
            );
        }
    }

    #[test]
    fn without_noise_every_force_is_above_the_quiet_level() {
        let mut d = ContactDetector::new(3.0, 1e-3);
        for _ in 0..200 {
            d.update(&Vector3::zeros());
        }
        assert_eq!(d.quiet_threshold(), 0.0);
    }
}
