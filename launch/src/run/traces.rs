//! What a run keeps of its traces (`--traces`): every record, every K-th tick, or none. The
//! metrics and the digest of the summary cover every tick whichever is chosen.

use std::fmt;
use std::num::NonZeroU32;
use std::str::FromStr;

/// `--traces full|decimate=K|none`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Traces {
    /// Every record of every process.
    #[default]
    Full,
    /// The records of every K-th tick (ticks 0, K, 2K, …), and every event.
    Decimate(NonZeroU32),
    /// No trace files; the summary only.
    None,
}

impl FromStr for Traces {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "full" => Ok(Self::Full),
            "none" => Ok(Self::None),
            _ => match s.strip_prefix("decimate=") {
                Some(k) => k
                    .parse::<NonZeroU32>()
                    .map(Self::Decimate)
                    .map_err(|_| format!("decimate=K takes a whole number K ≥ 1, not {k:?}")),
                None => Err(format!("{s:?} is not full, decimate=K (K ≥ 1) or none")),
            },
        }
    }
}

impl fmt::Display for Traces {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Full => f.write_str("full"),
            Self::Decimate(k) => write!(f, "decimate={k}"),
            Self::None => f.write_str("none"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_what_it_prints_and_refuses_the_rest() {
        for t in [
            Traces::Full,
            Traces::None,
            Traces::Decimate(NonZeroU32::new(10).expect("non-zero")),
        ] {
            assert_eq!(t.to_string().parse::<Traces>(), Ok(t));
        }
        for bad in ["", "decimate=0", "decimate=", "decimate=-3", "some"] {
            assert!(bad.parse::<Traces>().is_err(), "{bad}");
        }
    }
}
