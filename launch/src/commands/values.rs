//! Value parsers of the command line for the libraries' closed types: their names listed in
//! the help, each with what it is.

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use fdi_orchestrator::Engine;

/// A value of the closed set `all`, by its `name`, listed in the help with its `help`.
pub fn one_of<T: Copy + Send + Sync + 'static, const N: usize>(
    all: [T; N],
    name: fn(T) -> &'static str,
    help: fn(T) -> Option<&'static str>,
) -> impl TypedValueParser<Value = T> {
    PossibleValuesParser::new(all.map(|v| {
        let value = PossibleValue::new(name(v));
        match help(v) {
            Some(h) => value.help(h),
            None => value,
        }
    }))
    .try_map(move |s| {
        all.into_iter()
            .find(|v| name(*v) == s)
            .ok_or_else(|| format!("`{s}` is not one of the values"))
    })
}

/// `--engine`: the engines by their names.
pub fn engine() -> impl TypedValueParser<Value = Engine> {
    one_of(Engine::ALL, Engine::as_str, |e| Some(e.describe()))
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
