//! Corrupt values: a deliberate fault injection, not a stealthy attack. The attacker adds a
//! non-finite or absurd `value` (NaN, ±∞, 1e300, …) to the measurement, to exercise the control
//! center's input guard (docs/model.md, "Control center", step 10: such a measurement is rejected, counted, the last good one
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
mod tests;
