//! Field paths into a scenario's TOML document (`controller.beta`, `agents[2].delay.offset_s`,
//! `attack.channels[0].segments[1].waveform.amplitude`) and the edit of the value at one.
//!
//! A path must name a value the document holds: a key that is not there is an error naming the
//! path and the keys that are there, an index out of range names the length. Paths into the
//! attack (`attack.<key>` other than `preset`, `file`, `profile`) reach the inline profile
//! (`attack.profile.<key>`), which the campaign writes into the document first.

use std::fmt;

use anyhow::{bail, Result};

/// One step of a path.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Seg {
    Key(String),
    Index(usize),
}

/// A parsed field path, printed as written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldPath {
    pub text: String,
    pub segs: Vec<Seg>,
}

/// The keys of `[attack]` itself: every other key under `attack.` is one of the profile's.
const ATTACK_SOURCE_KEYS: [&str; 3] = ["preset", "file", "profile"];

impl fmt::Display for FieldPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

impl FieldPath {
    /// Parses `key(.key|[index])*`; keys are letters, digits, `_` and `-`.
    pub fn parse(text: &str) -> Result<Self> {
        let bad = |why: &str| anyhow::anyhow!("field path {text:?}: {why}");
        let mut segs = Vec::new();
        if text.is_empty() {
            return Err(bad("empty"));
        }
        for (n, part) in text.split('.').enumerate() {
            let (key, mut rest) = match part.find('[') {
                Some(b) => part.split_at(b),
                None => (part, ""),
            };
            if key.is_empty() {
                return Err(bad(if n == 0 && part.starts_with('[') {
                    "starts with an index: it must start with a key"
                } else {
                    "an empty key (two dots, or a dot at an end)"
                }));
            }
            if !key
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
            {
                return Err(bad(&format!(
                    "key {key:?} holds a character other than a letter, a digit, `_` or `-`"
                )));
            }
            segs.push(Seg::Key(key.to_string()));
            while !rest.is_empty() {
                let Some(inner) = rest.strip_prefix('[') else {
                    return Err(bad(&format!("{rest:?} after an index")));
                };
                let Some(end) = inner.find(']') else {
                    return Err(bad("an index without its `]`"));
                };
                let i = inner[..end].parse::<usize>().map_err(|_| {
                    bad(&format!(
                        "index {:?} is not a whole number ≥ 0",
                        &inner[..end]
                    ))
                })?;
                segs.push(Seg::Index(i));
                rest = &inner[end + 1..];
            }
        }
        Ok(Self {
            text: text.to_string(),
            segs,
        })
    }

    /// True for a path into the attack profile (`attack.channels…`, not `attack.preset`).
    pub fn is_in_attack_profile(&self) -> bool {
        matches!(self.segs.as_slice(), [Seg::Key(a), Seg::Key(k), ..]
            if a == "attack" && !ATTACK_SOURCE_KEYS.contains(&k.as_str()))
    }

    /// The steps this path takes through the document: a path into the attack profile
    /// (`attack.channels…`) goes through `attack.profile`, where the edit is made.
    fn target(&self) -> Vec<Seg> {
        let mut segs = self.segs.clone();
        if self.is_in_attack_profile() {
            segs.insert(1, Seg::Key("profile".into()));
        }
        segs
    }

    /// True when the two paths reach one value, or one reaches a value inside the other's
    /// (`agents[0].delay` and `agents[0].delay.offset_s`): an edit at one changes the other.
    pub fn overlaps(&self, other: &FieldPath) -> bool {
        self.holds(other) || other.holds(self)
    }

    /// True when `other` reaches the value this path does or a value inside it.
    pub fn holds(&self, other: &FieldPath) -> bool {
        other.target().starts_with(&self.target())
    }

    /// The path as written up to (not including) segment `n`.
    fn prefix(&self, n: usize) -> String {
        let mut s = String::new();
        for seg in &self.segs[..n] {
            match seg {
                Seg::Key(k) if s.is_empty() => s.push_str(k),
                Seg::Key(k) => {
                    s.push('.');
                    s.push_str(k);
                }
                Seg::Index(i) => s.push_str(&format!("[{i}]")),
            }
        }
        if s.is_empty() {
            "the scenario's top level".into()
        } else {
            format!("`{s}`")
        }
    }

    /// The value at this path in `doc`, for editing.
    fn locate<'a>(&self, doc: &'a mut toml::Table) -> Result<&'a mut toml::Value> {
        let redirect = self.is_in_attack_profile();
        let Some(Seg::Key(first)) = self.segs.first() else {
            bail!("field path {:?}: it must start with a key", self.text);
        };
        if !doc.contains_key(first.as_str()) {
            bail!(
                "field path `{}`: {} has no key `{first}`; its keys: {}",
                self.text,
                self.prefix(0),
                keys(doc)
            );
        }
        let mut cur = doc
            .get_mut(first.as_str())
            .ok_or_else(|| anyhow::anyhow!("field path `{}`: key `{first}` vanished", self.text))?;
        if redirect {
            cur = match cur.as_table_mut().and_then(|t| t.get_mut("profile")) {
                Some(p) => p,
                None => bail!(
                    "field path `{}`: the scenario's attack is not inline (internal: it is inlined before any edit)",
                    self.text
                ),
            };
        }
        for (n, seg) in self.segs.iter().enumerate().skip(1) {
            let here = self.prefix(n);
            cur = match seg {
                Seg::Key(k) => match cur {
                    toml::Value::Table(t) => {
                        if !t.contains_key(k.as_str()) {
                            bail!(
                                "field path `{}`: {here} has no key `{k}`; its keys: {} (a key the base scenario leaves at its default must be written into it to be swept)",
                                self.text,
                                keys(t)
                            );
                        }
                        t.get_mut(k.as_str()).ok_or_else(|| {
                            anyhow::anyhow!("field path `{}`: key `{k}` vanished", self.text)
                        })?
                    }
                    other => bail!(
                        "field path `{}`: {here} is {}, not a table: it has no key `{k}`",
                        self.text,
                        kind(other)
                    ),
                },
                Seg::Index(i) => match cur {
                    toml::Value::Array(a) => {
                        let len = a.len();
                        match a.get_mut(*i) {
                            Some(v) => v,
                            None => bail!(
                                "field path `{}`: {here} has {len} elements, no index {i} (indices from 0)",
                                self.text
                            ),
                        }
                    }
                    other => bail!(
                        "field path `{}`: {here} is {}, not an array: it has no index {i}",
                        self.text,
                        kind(other)
                    ),
                },
            };
        }
        Ok(cur)
    }

    /// The number at this path (for `factors`).
    pub fn number(&self, doc: &mut toml::Table) -> Result<f64> {
        match self.locate(doc)? {
            toml::Value::Integer(i) => Ok(*i as f64),
            toml::Value::Float(f) => Ok(*f),
            other => bail!(
                "field path `{}` holds {}, not a number: it cannot be scaled",
                self.text,
                kind(other)
            ),
        }
    }

    /// Replaces the value at this path by `value`. A number takes the type of the value it
    /// replaces (an integer where a float was becomes a float; a whole float where an integer
    /// was becomes an integer); any other change of type is refused.
    pub fn set(&self, doc: &mut toml::Table, value: &toml::Value) -> Result<()> {
        let slot = self.locate(doc)?;
        let new = match (&*slot, value) {
            (toml::Value::Float(_), toml::Value::Integer(i)) => toml::Value::Float(*i as f64),
            (toml::Value::Integer(_), toml::Value::Float(f)) => {
                if f.fract() != 0.0 || !f.is_finite() {
                    bail!(
                        "field path `{}` holds an integer; the value {f} is not a whole number",
                        self.text
                    )
                }
                // Every integer up to 2^53 is a float exactly; beyond, a float may stand for
                // another integer than the one written: write such values as integers.
                if f.abs() > 9.0e15 {
                    bail!(
                        "field path `{}` holds an integer; the value {f} is a float, exact as an integer only up to 9e15: write it as an integer",
                        self.text
                    )
                }
                toml::Value::Integer(*f as i64)
            }
            (old, new) if std::mem::discriminant(old) == std::mem::discriminant(new) => new.clone(),
            (old, new) => bail!(
                "field path `{}` holds {}; the value {new} is {}",
                self.text,
                kind(old),
                kind(new)
            ),
        };
        *slot = new;
        Ok(())
    }
}

fn keys(t: &toml::Table) -> String {
    if t.is_empty() {
        return "none".into();
    }
    t.keys().map(String::as_str).collect::<Vec<_>>().join(", ")
}

fn kind(v: &toml::Value) -> &'static str {
    match v {
        toml::Value::String(_) => "a string",
        toml::Value::Integer(_) => "an integer",
        toml::Value::Float(_) => "a float",
        toml::Value::Boolean(_) => "a boolean",
        toml::Value::Datetime(_) => "a date",
        toml::Value::Array(_) => "an array",
        toml::Value::Table(_) => "a table",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc() -> toml::Table {
        toml::from_str(
            r#"
            seed = 1
            [controller]
            beta = 30.0
            gain_k = 21.0
            [[agents]]
            id = 1
            delay = { kind = "sine", offset_s = 0.003 }
            [[agents]]
            id = 2
            delay = { kind = "sine", offset_s = 0.003 }
            [attack.profile]
            name = "p"
            channels = [{ agent = 1, segments = [{ from_s = 0.0 }, { from_s = 1.0, waveform = { kind = "constant", value = 1.0 } }] }]
            "#,
        )
        .expect("test document")
    }

    fn at(d: &toml::Table, dotted: &[&str]) -> toml::Value {
        let mut v = toml::Value::Table(d.clone());
        for k in dotted {
            v = match k.parse::<usize>() {
                Ok(i) => v.as_array().expect("array")[i].clone(),
                Err(_) => v.as_table().expect("table")[*k].clone(),
            };
        }
        v
    }

    #[test]
    fn paths_to_one_value_overlap() {
        let p = |t: &str| FieldPath::parse(t).expect("path");
        assert!(p("controller.beta").overlaps(&p("controller.beta")));
        assert!(p("controller").overlaps(&p("controller.beta")));
        assert!(p("agents[0].delay.offset_s").overlaps(&p("agents[0].delay")));
        assert!(p("attack.channels[0]").overlaps(&p("attack.profile.channels[0].agent")));
        assert!(!p("controller.beta").overlaps(&p("controller.gain_k")));
        assert!(!p("agents[0].delay").overlaps(&p("agents[1].delay")));
        assert!(!p("controller.beta").overlaps(&p("controller.beta2")));
        assert!(p("attack.profile.channels").holds(&p("attack.channels[0]")));
        assert!(!p("attack.channels[0]").holds(&p("attack.profile.channels")));
    }

    #[test]
    fn parses_keys_and_indices() {
        let p = FieldPath::parse("agents[2].delay.offset_s").expect("valid");
        assert_eq!(
            p.segs,
            vec![
                Seg::Key("agents".into()),
                Seg::Index(2),
                Seg::Key("delay".into()),
                Seg::Key("offset_s".into())
            ]
        );
        for bad in [
            "", "a..b", ".a", "a.", "[0].a", "a[x]", "a[1", "a[1]b", "a b", "a[-1]",
        ] {
            assert!(FieldPath::parse(bad).is_err(), "{bad:?} was accepted");
        }
    }

    #[test]
    fn sets_values_where_the_path_points() {
        let mut d = doc();
        FieldPath::parse("controller.beta")
            .expect("path")
            .set(&mut d, &toml::Value::Integer(10))
            .expect("set");
        assert_eq!(at(&d, &["controller", "beta"]), toml::Value::Float(10.0));
        FieldPath::parse("agents[1].delay.offset_s")
            .expect("path")
            .set(&mut d, &toml::Value::Float(0.03))
            .expect("set");
        assert_eq!(
            at(&d, &["agents", "1", "delay", "offset_s"]),
            toml::Value::Float(0.03)
        );
        assert_eq!(
            at(&d, &["agents", "0", "delay", "offset_s"]),
            toml::Value::Float(0.003)
        );
        FieldPath::parse("seed")
            .expect("path")
            .set(&mut d, &toml::Value::Float(7.0))
            .expect("set");
        assert_eq!(at(&d, &["seed"]), toml::Value::Integer(7));
        let attack = FieldPath::parse("attack.channels[0].segments[1].waveform.value").expect("p");
        assert!(attack.is_in_attack_profile());
        assert_eq!(attack.number(&mut d).expect("number"), 1.0);
        attack.set(&mut d, &toml::Value::Float(2.5)).expect("set");
        assert_eq!(
            at(
                &d,
                &["attack", "profile", "channels", "0", "segments", "1", "waveform", "value"]
            ),
            toml::Value::Float(2.5)
        );
        assert!(!FieldPath::parse("attack.profile.name")
            .expect("p")
            .is_in_attack_profile());
    }

    #[test]
    fn a_missing_path_names_itself_and_what_is_there() {
        let mut d = doc();
        let e = FieldPath::parse("controller.betta")
            .expect("path")
            .set(&mut d, &toml::Value::Float(1.0))
            .expect_err("no such key")
            .to_string();
        assert!(e.contains("controller.betta"), "{e}");
        assert!(e.contains("beta, gain_k"), "{e}");
        let e = FieldPath::parse("agents[5].id")
            .expect("path")
            .set(&mut d, &toml::Value::Integer(1))
            .expect_err("out of range")
            .to_string();
        assert!(
            e.contains("agents[5].id") && e.contains("2 elements"),
            "{e}"
        );
        let e = FieldPath::parse("contoller.beta")
            .expect("path")
            .set(&mut d, &toml::Value::Float(1.0))
            .expect_err("no such table")
            .to_string();
        assert!(e.contains("agents, attack, controller, seed"), "{e}");
        let e = FieldPath::parse("seed.x")
            .expect("path")
            .set(&mut d, &toml::Value::Float(1.0))
            .expect_err("not a table")
            .to_string();
        assert!(e.contains("an integer, not a table"), "{e}");
        let e = FieldPath::parse("controller.beta")
            .expect("path")
            .set(&mut d, &toml::Value::String("x".into()))
            .expect_err("wrong type")
            .to_string();
        assert!(e.contains("a float") && e.contains("a string"), "{e}");
        let e = FieldPath::parse("seed")
            .expect("path")
            .set(&mut d, &toml::Value::Float(1.5))
            .expect_err("not whole")
            .to_string();
        assert!(e.contains("not a whole number"), "{e}");
    }
}
