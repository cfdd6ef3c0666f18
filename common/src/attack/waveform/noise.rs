//! Gaussian noise injection, drawn from the attacker's seeded stream.

use rand_chacha::ChaCha12Rng;
use rand_distr::{Distribution, Normal};

pub(super) fn value(rng: &mut ChaCha12Rng, mean: f64, std: f64) -> f64 {
    match Normal::new(mean, std) {
        Ok(normal) => normal.sample(rng),
        Err(_) => mean,
    }
}
