//! Corrupt values: a deliberate fault injection, not a stealthy attack. The attacker adds a
//! non-finite or absurd `value` (NaN, ±∞, 1e300, …) to the measurement, to exercise the control
//! center's input guard (SPEC §4.10: such a measurement is rejected, counted, the last good one
//! held, and no non-finite torque is ever sent).
//!
//! This is the one waveform exempt from the finiteness check of [`super::Waveform::problems`]:
//! its value is validated by its form only. In TOML it is a string, `"nan"`, `"inf"`, `"+inf"` or
//! `"-inf"` (any case), or a number of any size (`1e300`; TOML's own `nan` and `inf` literals are
//! accepted too). It is written back as a string when non-finite, so a run directory's
//! `scenario.toml` re-reads to the same profile.

use std::fmt;

use serde::de::{self, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// The value a `corrupt` segment injects: any `f64`, NaN and infinities included. Every NaN is
/// stored as the canonical `f64::NAN`, and equality compares bit patterns, so a profile that
/// holds NaN still equals itself (and its re-read copy).
#[derive(Debug, Clone, Copy)]
pub struct CorruptValue(f64);

impl CorruptValue {
    /// `value`, with any NaN made the canonical `f64::NAN`.
    pub fn new(value: f64) -> Self {
        Self(if value.is_nan() { f64::NAN } else { value })
    }

    /// The injected value.
    pub fn get(self) -> f64 {
        self.0
    }

    /// The string forms accepted, as an error message lists them.
    pub const FORMS: &'static str = r#""nan", "inf", "+inf", "-inf" or a number"#;

    fn from_text(text: &str) -> Option<Self> {
        match text.trim().to_ascii_lowercase().as_str() {
            "nan" => Some(Self::new(f64::NAN)),
            "inf" | "+inf" => Some(Self::new(f64::INFINITY)),
            "-inf" => Some(Self::new(f64::NEG_INFINITY)),
            _ => None,
        }
    }
}

/// What the hand-written `Deserialize` below accepts: any number, or one of the strings of
/// [`CorruptValue::FORMS`] in any case, surrounded by white space or not.
impl schemars::JsonSchema for CorruptValue {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "CorruptValue".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "The value injected: a number of any size, or \"nan\", \"inf\", \"+inf\", \"-inf\" (any case; TOML's own nan and inf literals are accepted too).",
            "anyOf": [
                { "type": "number" },
                { "type": "string", "pattern": "^\\s*([nN][aA][nN]|[+-]?[iI][nN][fF])\\s*$" }
            ]
        })
    }
}

impl PartialEq for CorruptValue {
    fn eq(&self, other: &Self) -> bool {
        self.0.to_bits() == other.0.to_bits()
    }
}

impl fmt::Display for CorruptValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

impl Serialize for CorruptValue {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let v = self.0;
        if v.is_nan() {
            s.serialize_str("nan")
        } else if v == f64::INFINITY {
            s.serialize_str("inf")
        } else if v == f64::NEG_INFINITY {
            s.serialize_str("-inf")
        } else {
            s.serialize_f64(v)
        }
    }
}

struct CorruptVisitor;

impl Visitor<'_> for CorruptVisitor {
    type Value = CorruptValue;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(CorruptValue::FORMS)
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<CorruptValue, E> {
        Ok(CorruptValue::new(v))
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<CorruptValue, E> {
        Ok(CorruptValue::new(v as f64))
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<CorruptValue, E> {
        Ok(CorruptValue::new(v as f64))
    }

    fn visit_str<E: de::Error>(self, v: &str) -> Result<CorruptValue, E> {
        CorruptValue::from_text(v).ok_or_else(|| E::invalid_value(de::Unexpected::Str(v), &self))
    }
}

impl<'de> Deserialize<'de> for CorruptValue {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(CorruptVisitor)
    }
}

pub(super) fn value(value: CorruptValue) -> f64 {
    value.get()
}

#[cfg(test)]
mod tests {
    use super::super::Waveform;
    use super::CorruptValue;
    use crate::attack::AttackProfile;

    fn profile(value: &str) -> Result<AttackProfile, toml::de::Error> {
        toml::from_str(&format!(
            r#"
name = "t"
[[channels]]
agent = 1
signal = "position"
links = [1]
units = "rad"
segments = [{{ from_s = 0.0, waveform = {{ kind = "corrupt", value = {value} }} }}]
"#
        ))
    }

    fn injected(p: &AttackProfile) -> f64 {
        let w = p.channels[0].segments[0].waveform;
        let mut rng = crate::rng::stream(1, 1, crate::rng::Purpose::AttackNoise { channel: 0 });
        w.value(0.0, 0.0, &mut rng)
    }

    #[test]
    fn every_form_parses_to_its_value_and_passes_validation() {
        let dofs = [(1, 2)].into_iter().collect();
        for (text, check) in [
            (r#""nan""#, (|v: f64| v.is_nan()) as fn(f64) -> bool),
            (r#""NaN""#, |v| v.is_nan()),
            ("nan", |v| v.is_nan()),
            (r#""inf""#, |v| v == f64::INFINITY),
            (r#""+inf""#, |v| v == f64::INFINITY),
            ("inf", |v| v == f64::INFINITY),
            (r#""-inf""#, |v| v == f64::NEG_INFINITY),
            ("-inf", |v| v == f64::NEG_INFINITY),
            ("1e300", |v| v == 1e300),
            ("-1e300", |v| v == -1e300),
            ("7", |v| v == 7.0),
            ("0.25", |v| v == 0.25),
        ] {
            let p = profile(text).unwrap_or_else(|e| panic!("{text}: {e}"));
            assert!(check(injected(&p)), "{text} gave {}", injected(&p));
            assert!(
                p.problems(&dofs).is_empty(),
                "{text}: {:?}",
                p.problems(&dofs)
            );
        }
    }

    #[test]
    fn other_strings_are_refused_naming_the_accepted_forms() {
        for bad in [r#""banana""#, r#""""#, r#""1e300""#, "true", "[1.0]"] {
            let e = profile(bad).expect_err(bad).to_string();
            assert!(
                e.contains("corrupt") || e.contains(CorruptValue::FORMS) || e.contains("invalid"),
                "{bad}: {e}"
            );
        }
        let e = profile(r#""banana""#).expect_err("banana").to_string();
        assert!(e.contains(CorruptValue::FORMS), "{e}");
    }

    #[test]
    fn the_profile_round_trips_through_toml_with_nan_and_infinities() {
        for text in [r#""nan""#, r#""inf""#, r#""-inf""#, "1e300", "-0.5"] {
            let p = profile(text).unwrap_or_else(|e| panic!("{text}: {e}"));
            let written = toml::to_string(&p).unwrap_or_else(|e| panic!("{text}: {e}"));
            let again: AttackProfile =
                toml::from_str(&written).unwrap_or_else(|e| panic!("{text}: {e}\n{written}"));
            assert_eq!(again, p, "{text} written as\n{written}");
        }
    }

    #[test]
    fn corrupt_is_exempt_from_the_finiteness_check_but_other_waveforms_are_not() {
        for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, f64::MAX] {
            let w = Waveform::Corrupt {
                value: CorruptValue::new(v),
            };
            assert!(w.problems().is_empty(), "{v}");
            assert!(!w.is_none());
            if !v.is_finite() {
                assert!(
                    !Waveform::Constant { value: v }.problems().is_empty(),
                    "{v}"
                );
            }
        }
        assert!(!Waveform::Constant { value: f64::NAN }.problems().is_empty());
        // Every NaN is stored canonically, so equal profiles compare equal.
        assert_eq!(
            CorruptValue::new(-f64::NAN),
            CorruptValue::new(f64::NAN),
            "NaN sign and payload are canonicalised"
        );
        assert_ne!(CorruptValue::new(0.0), CorruptValue::new(-0.0));
    }
}
