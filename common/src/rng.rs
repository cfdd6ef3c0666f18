//! Seeded random streams. The generator is pinned (ChaCha12 from `rand_chacha`) so that a run
//! seed means the same numbers on every machine and in every process: each (run seed, agent,
//! purpose) owns one independent ChaCha stream.

use rand::SeedableRng;
use rand_chacha::ChaCha12Rng;

/// What a random stream is used for; part of the stream id.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Purpose {
    /// Agent sensor noise θ.
    SensorNoise,
    /// Initial inner NN weights V̂(0) of the control center.
    NnInit,
    /// Attacker Gaussian-noise waveforms; `channel` distinguishes signal and link.
    AttackNoise { channel: u32 },
    /// Attacker message attacks (drops, bursts) on one path.
    AttackMessages { torque: bool },
}

impl Purpose {
    fn code(self) -> u64 {
        match self {
            Self::SensorNoise => 1,
            Self::NnInit => 2,
            Self::AttackNoise { channel } => 0x100 + u64::from(channel),
            Self::AttackMessages { torque } => 3 + u64::from(torque),
        }
    }
}

/// The stream for `(run_seed, agent, purpose)`.
pub fn stream(run_seed: u64, agent_id: u32, purpose: Purpose) -> ChaCha12Rng {
    let mut rng = ChaCha12Rng::seed_from_u64(run_seed);
    rng.set_stream((u64::from(agent_id) << 32) | purpose.code());
    rng
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn same_inputs_same_numbers_and_streams_are_distinct() {
        let draw = |mut r: ChaCha12Rng| -> Vec<u64> { (0..8).map(|_| r.random()).collect() };
        let a = draw(stream(7, 1, Purpose::SensorNoise));
        let b = draw(stream(7, 1, Purpose::SensorNoise));
        assert_eq!(a, b);
        let mut other_agent = stream(7, 2, Purpose::SensorNoise);
        let mut other_purpose = stream(7, 1, Purpose::NnInit);
        let mut other_seed = stream(8, 1, Purpose::SensorNoise);
        assert_ne!(a[0], other_agent.random::<u64>());
        assert_ne!(a[0], other_purpose.random::<u64>());
        assert_ne!(a[0], other_seed.random::<u64>());
    }

    #[test]
    fn pinned_algorithm_gives_known_first_value() {
        // Regression guard: if the generator or the seeding scheme changes, every recorded
        // digest changes too. The value was recorded when the scheme was introduced.
        let first: u64 = stream(1, 1, Purpose::SensorNoise).random();
        assert_eq!(
            first, FIRST_VALUE_SEED1_AGENT1,
            "ChaCha12 stream changed: got {first:#x}"
        );
    }

    const FIRST_VALUE_SEED1_AGENT1: u64 = 0x05db_454e_7f9f_55ff;
}
