//! Value parsers of the command line for the libraries' closed types: their names listed in
//! the help, each with what it is.

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use fdi_orchestrator::Engine;

/// `--engine`: the engines by their names.
pub fn engine() -> impl TypedValueParser<Value = Engine> {
    PossibleValuesParser::new(
        Engine::ALL.map(|e| PossibleValue::new(e.as_str()).help(e.describe())),
    )
    .try_map(|s| s.parse::<Engine>())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every engine parses back from the name the help lists for it.
    #[test]
    fn every_engine_parses_from_its_name() {
        let cmd = clap::Command::new("t");
        for e in Engine::ALL {
            let parsed = engine()
                .parse_ref(&cmd, None, std::ffi::OsStr::new(e.as_str()))
                .expect("an engine's name");
            assert_eq!(parsed, e);
        }
        assert!(engine()
            .parse_ref(&cmd, None, std::ffi::OsStr::new("threads"))
            .is_err());
    }
}
