//! Numbers of a summary that may be non-finite (the RMSE of a robot that diverged), written to
//! JSON and read back as they were. JSON has no NaN or infinity: `serde_json` writes them as
//! `null`, which reads back as no number at all ("invalid type: null, expected f64"). Here a
//! finite number is written as a number and the others as the strings `"NaN"`, `"inf"` and
//! `"-inf"` (what Python's `float()` and pandas read), and both read back to the same value.
//!
//! `#[serde(with = "crate::json_float")]` on an `f64`, [`map`] on a map of them.

use serde::{Deserialize, Deserializer, Serializer};

/// The string a non-finite number is written as.
fn word(v: f64) -> &'static str {
    if v.is_nan() {
        "NaN"
    } else if v > 0.0 {
        "inf"
    } else {
        "-inf"
    }
}

pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    if v.is_finite() {
        s.serialize_f64(*v)
    } else {
        s.serialize_str(word(*v))
    }
}

/// A number as written: a JSON number, or one of the words for a non-finite one.
#[derive(Deserialize)]
#[serde(untagged)]
enum Written {
    Number(f64),
    Word(String),
}

pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    match Written::deserialize(d)? {
        Written::Number(v) => Ok(v),
        Written::Word(w) => match w.as_str() {
            "NaN" => Ok(f64::NAN),
            "inf" => Ok(f64::INFINITY),
            "-inf" => Ok(f64::NEG_INFINITY),
            other => Err(serde::de::Error::custom(format!(
                "`{other}` is not a number (a number, or \"NaN\", \"inf\" or \"-inf\")"
            ))),
        },
    }
}

/// The same for the values of a map (`#[serde(with = "crate::json_float::map")]`).
pub mod map {
    use std::collections::BTreeMap;

    use serde::ser::SerializeMap as _;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(m: &BTreeMap<String, f64>, s: S) -> Result<S::Ok, S::Error> {
        #[derive(serde::Serialize)]
        struct One(#[serde(with = "crate::json_float")] f64);
        let mut out = s.serialize_map(Some(m.len()))?;
        for (k, v) in m {
            out.serialize_entry(k, &One(*v))?;
        }
        out.end()
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<BTreeMap<String, f64>, D::Error> {
        #[derive(Deserialize)]
        struct One(#[serde(with = "crate::json_float")] f64);
        let m = BTreeMap::<String, One>::deserialize(d)?;
        Ok(m.into_iter().map(|(k, One(v))| (k, v)).collect())
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    #[derive(Debug, serde::Serialize, serde::Deserialize)]
    struct S {
        #[serde(with = "super")]
        x: f64,
        #[serde(with = "super::map")]
        m: BTreeMap<String, f64>,
    }

    /// Every value, finite or not, reads back to its bits (NaN to a NaN); finite ones are
    /// plain JSON numbers.
    #[test]
    fn non_finite_numbers_are_written_as_words_and_read_back() {
        for x in [
            0.25,
            -1e300,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            0.0,
        ] {
            let m = BTreeMap::from([("1".to_string(), x), ("2".to_string(), 1.5)]);
            let text = serde_json::to_string(&S { x, m }).expect("written");
            assert!(!text.contains("null"), "{text}");
            let back: S = serde_json::from_str(&text).expect("read back");
            for v in [back.x, back.m["1"]] {
                assert!(
                    v.to_bits() == x.to_bits() || (x.is_nan() && v.is_nan()),
                    "{text}"
                );
            }
            assert_eq!(back.m["2"], 1.5);
        }
        let e = serde_json::from_str::<S>(r#"{"x": "many", "m": {}}"#).expect_err("a word");
        assert!(e.to_string().contains("did not match") || e.to_string().contains("many"));
        assert!(serde_json::from_str::<S>(r#"{"x": null, "m": {}}"#).is_err());
    }
}
