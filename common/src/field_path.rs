//! Field paths into a scenario's TOML document (`controller.beta`, `agents[2].delay.offset_s`,
//! `attack.channels[0].segments[1].waveform.amplitude`) and the edit of the value at one: the
//! one language of a campaign's `[set]` and axes and of the command line's `--set PATH=VALUE`.
//!
//! A path must name a value the document holds: a key that is not there is an error naming the
//! path and the keys that are there, an index out of range names the length. Paths into the
//! attack (`attack.<key>` other than `preset`, `file`, `profile`) reach the inline profile
//! (`attack.profile.<key>`), which the caller writes into the document first.

use std::fmt;

/// One step of a path.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Seg {
    Key(String),
    Index(usize),
}

/// The steps as a path writes them: keys joined by `.`, indices as `[i]` (empty for none).
pub fn segs_text(segs: &[Seg]) -> String {
    let mut s = String::new();
    for seg in segs {
        match seg {
            Seg::Key(k) if s.is_empty() => s.push_str(k),
            Seg::Key(k) => {
                s.push('.');
                s.push_str(k);
            }
            Seg::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// A parsed field path, printed as written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldPath {
    pub text: String,
    pub segs: Vec<Seg>,
}

/// Why a path cannot be parsed, or cannot be edited in a document.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PathError {
    #[error("field path {path:?}: {why}")]
    Syntax { path: String, why: String },
    #[error("field path `{path}`: {at} has no key `{key}`; its keys: {keys}")]
    NoKey {
        path: String,
        /// Where the key was looked for: `` `controller` `` or `the scenario's top level`.
        at: String,
        key: String,
        /// The keys that are there, comma-separated (`none` for an empty table).
        keys: String,
    },
    #[error("field path `{path}`: {at} has {len} elements, no index {index} (indices from 0)")]
    NoIndex {
        path: String,
        at: String,
        len: usize,
        index: usize,
    },
    #[error("field path `{path}`: {at} is {holds}, not a table: it has no key `{key}`")]
    NotTable {
        path: String,
        at: String,
        holds: &'static str,
        key: String,
    },
    #[error("field path `{path}`: {at} is {holds}, not an array: it has no index {index}")]
    NotArray {
        path: String,
        at: String,
        holds: &'static str,
        index: usize,
    },
    #[error("field path `{path}`: the scenario's attack is not inline (it must be written into `attack.profile` before an edit of the profile)")]
    AttackNotInline { path: String },
    #[error("field path `{path}` holds {holds}, not a number: it cannot be scaled")]
    NotNumber { path: String, holds: &'static str },
    #[error("field path `{path}` holds an integer; the value {value} is not a whole number")]
    NotWhole { path: String, value: f64 },
    #[error("field path `{path}` holds an integer; the value {value} is a float, exact as an integer only up to 9e15: write it as an integer")]
    InexactInteger { path: String, value: f64 },
    #[error("field path `{path}` holds {holds}; the value {value} is {kind}")]
    WrongType {
        path: String,
        holds: &'static str,
        value: String,
        kind: &'static str,
    },
}

/// The keys of `[attack]` itself: every other key under `attack.` is one of the profile's.
const ATTACK_SOURCE_KEYS: [&str; 3] = ["preset", "file", "profile"];

impl fmt::Display for FieldPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

impl std::str::FromStr for FieldPath {
    type Err = PathError;

    fn from_str(s: &str) -> Result<Self, PathError> {
        Self::parse(s)
    }
}

impl FieldPath {
    /// Parses `key(.key|[index])*`; keys are letters, digits, `_` and `-`.
    pub fn parse(text: &str) -> Result<Self, PathError> {
        let bad = |why: &str| PathError::Syntax {
            path: text.to_string(),
            why: why.to_string(),
        };
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
    pub fn target(&self) -> Vec<Seg> {
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
        let s = segs_text(&self.segs[..n]);
        if s.is_empty() {
            "the scenario's top level".into()
        } else {
            format!("`{s}`")
        }
    }

    /// The value at this path in `doc`, for editing.
    fn locate<'a>(&self, doc: &'a mut toml::Table) -> Result<&'a mut toml::Value, PathError> {
        let path = || self.text.clone();
        let Some(Seg::Key(first)) = self.segs.first() else {
            return Err(PathError::Syntax {
                path: path(),
                why: "it must start with a key".into(),
            });
        };
        let keys_of_doc = keys(doc);
        let mut cur = doc
            .get_mut(first.as_str())
            .ok_or_else(|| PathError::NoKey {
                path: path(),
                at: self.prefix(0),
                key: first.clone(),
                keys: keys_of_doc,
            })?;
        if self.is_in_attack_profile() {
            cur = cur
                .as_table_mut()
                .and_then(|t| t.get_mut("profile"))
                .ok_or_else(|| PathError::AttackNotInline { path: path() })?;
        }
        for (n, seg) in self.segs.iter().enumerate().skip(1) {
            let at = self.prefix(n);
            cur = match (seg, cur) {
                (Seg::Key(k), toml::Value::Table(t)) => {
                    let keys = keys(t);
                    t.get_mut(k.as_str()).ok_or_else(|| PathError::NoKey {
                        path: path(),
                        at,
                        key: k.clone(),
                        keys,
                    })?
                }
                (Seg::Index(i), toml::Value::Array(a)) => {
                    let len = a.len();
                    a.get_mut(*i).ok_or(PathError::NoIndex {
                        path: path(),
                        at,
                        len,
                        index: *i,
                    })?
                }
                (Seg::Key(k), other) => {
                    return Err(PathError::NotTable {
                        path: path(),
                        at,
                        holds: kind(other),
                        key: k.clone(),
                    })
                }
                (Seg::Index(i), other) => {
                    return Err(PathError::NotArray {
                        path: path(),
                        at,
                        holds: kind(other),
                        index: *i,
                    })
                }
            };
        }
        Ok(cur)
    }

    /// The number at this path (for `factors`).
    pub fn number(&self, doc: &mut toml::Table) -> Result<f64, PathError> {
        match self.locate(doc)? {
            toml::Value::Integer(i) => Ok(*i as f64),
            toml::Value::Float(f) => Ok(*f),
            other => Err(PathError::NotNumber {
                path: self.text.clone(),
                holds: kind(other),
            }),
        }
    }

    /// Replaces the value at this path by `value`. A number takes the type of the value it
    /// replaces (an integer where a float was becomes a float; a whole float where an integer
    /// was becomes an integer); any other change of type is refused.
    pub fn set(&self, doc: &mut toml::Table, value: &toml::Value) -> Result<(), PathError> {
        let path = self.text.clone();
        let slot = self.locate(doc)?;
        let new = match (&*slot, value) {
            (toml::Value::Float(_), toml::Value::Integer(i)) => toml::Value::Float(*i as f64),
            (toml::Value::Integer(_), toml::Value::Float(f)) => {
                if f.fract() != 0.0 || !f.is_finite() {
                    return Err(PathError::NotWhole { path, value: *f });
                }
                // Every integer up to 2^53 is a float exactly; beyond, a float may stand for
                // another integer than the one written: write such values as integers.
                if f.abs() > 9.0e15 {
                    return Err(PathError::InexactInteger { path, value: *f });
                }
                toml::Value::Integer(*f as i64)
            }
            (old, new) if std::mem::discriminant(old) == std::mem::discriminant(new) => new.clone(),
            (old, new) => {
                return Err(PathError::WrongType {
                    path,
                    holds: kind(old),
                    value: new.to_string(),
                    kind: kind(new),
                })
            }
        };
        *slot = new;
        Ok(())
    }
}

/// A value as a table or a label shows it: a string without its quotes, anything else as TOML.
pub fn show(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// One edit of the command line, `--set PATH=VALUE`: the value at a field path replaced.
#[derive(Debug, Clone, PartialEq)]
pub struct Edit {
    pub path: FieldPath,
    /// A TOML value (`10`, `0.5`, `"x"`, `[1, 2]`, `{ kind = "constant", value_s = 0.003 }`);
    /// text that is not one (`traditional`) is a string.
    pub value: toml::Value,
}

/// Why `PATH=VALUE` cannot be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EditError {
    #[error("{0:?}: expected PATH=VALUE (a field path, `=`, a value), e.g. controller.beta=10")]
    NoEquals(String),
    #[error("{text:?}: {source}")]
    Path {
        text: String,
        #[source]
        source: PathError,
    },
}

impl std::str::FromStr for Edit {
    type Err = EditError;

    /// `PATH=VALUE`, split at the first `=` (a path holds none).
    fn from_str(s: &str) -> Result<Self, EditError> {
        let Some((path, value)) = s.split_once('=') else {
            return Err(EditError::NoEquals(s.to_string()));
        };
        let path = FieldPath::parse(path.trim()).map_err(|source| EditError::Path {
            text: s.to_string(),
            source,
        })?;
        let value = value.trim();
        let value = value
            .parse::<toml::Value>()
            .unwrap_or_else(|_| toml::Value::String(value.to_string()));
        Ok(Self { path, value })
    }
}

impl fmt::Display for Edit {
    /// `PATH=VALUE`, the value as [`show`] shows it.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}={}", self.path, show(&self.value))
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
    fn an_edit_is_a_path_an_equals_sign_and_a_toml_value_or_a_word() {
        let e = |t: &str| t.parse::<Edit>();
        let beta = e("controller.beta=10").expect("edit");
        assert_eq!(beta.path.text, "controller.beta");
        assert_eq!(beta.value, toml::Value::Integer(10));
        assert_eq!(beta.to_string(), "controller.beta=10");
        assert_eq!(
            e("controller.mode=traditional").expect("edit").value,
            toml::Value::String("traditional".into())
        );
        assert_eq!(
            e("name=\"a=b\"").expect("edit").value,
            toml::Value::String("a=b".into())
        );
        let delay = e("agents[0].delay={ kind = \"constant\", value_s = 0.003 }").expect("edit");
        assert!(delay.value.is_table(), "{delay:?}");
        let no_equals = e("controller.beta").expect_err("no =").to_string();
        assert!(
            no_equals.contains("controller.beta") && no_equals.contains("PATH=VALUE"),
            "{no_equals}"
        );
        let bad_path = e("controller..beta=1").expect_err("bad path").to_string();
        assert!(
            bad_path.contains("controller..beta=1") && bad_path.contains("empty key"),
            "{bad_path}"
        );
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
