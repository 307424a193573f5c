//! Learning-rate schedules: svox2's delayed exponential (method.md §2).

use serde::{Deserialize, Serialize};

/// lr(t) = D(t)·exp((1 − u)·ln lr₀ + u·ln lr₁), u = clip(t/T_max, 0, 1);
/// D(t) = m + (1 − m)·sin(½π·clip(t/t_delay, 0, 1)) when t_delay > 0, else 1. A zero endpoint
/// (a frozen or vanishing rate) has no logarithm: then the interpolation is linear.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DelayedExp {
    pub init: f32,
    pub last: f32,
    pub max_steps: u32,
    pub delay_steps: u32,
    pub delay_mult: f32,
}

impl DelayedExp {
    /// A constant rate.
    pub fn constant(lr: f32) -> Self {
        DelayedExp {
            init: lr,
            last: lr,
            max_steps: 1,
            delay_steps: 0,
            delay_mult: 1.0,
        }
    }

    /// Refuse a rate no run can use: `init`, `last` and `delay_mult` must be finite and ≥ 0
    /// (`name` is the field, e.g. `lr_sigma`).
    pub fn check(&self, name: &str) -> anyhow::Result<()> {
        for (field, v) in [
            ("init", self.init),
            ("last", self.last),
            ("delay_mult", self.delay_mult),
        ] {
            anyhow::ensure!(
                v.is_finite() && v >= 0.0,
                "{name}.{field} must be finite and ≥ 0, got {v}"
            );
        }
        Ok(())
    }

    /// The rate at step `t`.
    pub fn at(&self, t: u32) -> f32 {
        let u = (t as f64 / self.max_steps.max(1) as f64).clamp(0.0, 1.0);
        let (a, b) = (self.init as f64, self.last as f64);
        let base = if a > 0.0 && b > 0.0 {
            ((1.0 - u) * a.ln() + u * b.ln()).exp()
        } else {
            (1.0 - u) * a + u * b
        };
        let delay = if self.delay_steps > 0 {
            let v = (t as f64 / self.delay_steps as f64).clamp(0.0, 1.0);
            let m = self.delay_mult as f64;
            m + (1.0 - m) * (0.5 * std::f64::consts::PI * v).sin()
        } else {
            1.0
        };
        (delay * base) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_rates_stay_finite() {
        let mut s = DelayedExp::constant(0.0);
        s.max_steps = 100;
        assert!(
            (0..200).all(|t| s.at(t) == 0.0),
            "a frozen group stays frozen"
        );
        s.init = 1e-3;
        assert!((s.at(50) - 5e-4).abs() < 1e-9, "towards zero: linear");
        assert_eq!(s.at(100), 0.0);
    }

    #[test]
    fn delayed_exponential_endpoints() {
        let s = DelayedExp {
            init: 30.0,
            last: 0.05,
            max_steps: 250_000,
            delay_steps: 15_000,
            delay_mult: 0.01,
        };
        assert!((s.at(0) - 0.3).abs() < 1e-6, "delayed start = m·lr₀");
        assert!((s.at(250_000) - 0.05).abs() < 1e-6);
        assert!((s.at(1_000_000) - 0.05).abs() < 1e-6);
        // Past the delay the rate is the plain exponential.
        let plain = (30f64.ln() * 0.9 + 0.05f64.ln() * 0.1).exp();
        assert!((s.at(25_000) as f64 - plain).abs() < 1e-4 * plain);
        assert_eq!(DelayedExp::constant(1e-3).at(12345), 1e-3);
    }
}
