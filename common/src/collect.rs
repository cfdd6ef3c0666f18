//! A TOML document read into a type with every problem of it found in one pass: unknown keys,
//! missing keys and wrong values in every table, not only the first table that fails.
//!
//! serde stops at the first error. [`collect`] records it, changes the document so that
//! reading can go on (an unknown key is removed; a wrong or missing value is replaced by one of
//! the right kind) and reads again, until the document reads. A value put in place is never
//! the result of a load: it only lets the reading reach the other tables, and what is then
//! found at, in or above it is the replacement's, not the document's, so it is not reported.

use serde::de::DeserializeOwned;
use serde_path_to_error::Segment;

use crate::field_path::{segs_text, Seg};
use crate::problem::Problem;

/// Most readings of one document (each finds one problem).
const MAX_READINGS: usize = 4096;

/// What [`collect`] found: the value when the document (as changed) reads, every problem, and
/// the paths of the values put in place.
#[derive(Debug)]
pub struct Collected<T> {
    /// The value read: `Some` also when values were replaced to read on (then `problems` is
    /// not empty, and the value must not be used beyond its checks).
    pub value: Option<T>,
    /// Every problem found, each with its path, in the order read.
    pub problems: Vec<Problem>,
    /// Where values were put in place (`controller.learning_rate_w`), as paths are written.
    pub replaced: Vec<String>,
}

impl<T> Collected<T> {
    /// True when `path` is a value put in place, one inside it, or a table holding one: a
    /// check of the value read at `path` would judge the replacement, not the document.
    pub fn touches_replaced(&self, path: &str) -> bool {
        self.replaced
            .iter()
            .any(|r| nested(r, path) || nested(path, r))
    }
}

/// True when `inner` is `outer` or a path inside it (`a.b` and `a[0]` are inside `a`, `ab`
/// is not); every path is inside the top level (`<root>`).
fn nested(outer: &str, inner: &str) -> bool {
    outer == "<root>"
        || inner
            .strip_prefix(outer)
            .is_some_and(|rest| rest.is_empty() || rest.starts_with(['.', '[']))
}

/// What an error of serde says.
enum Kind {
    UnknownKey(String),
    MissingKey(String),
    WrongValue,
}

fn kind(message: &str) -> Kind {
    let key = message.split('`').nth(1).map(str::to_owned);
    match key {
        Some(k) if message.starts_with("unknown field") => Kind::UnknownKey(k),
        Some(k) if message.starts_with("missing field") => Kind::MissingKey(k),
        _ => Kind::WrongValue,
    }
}

/// The steps of a path of serde_path_to_error; `None` for a step it could not name.
fn steps(path: &serde_path_to_error::Path) -> Option<Vec<Seg>> {
    path.iter()
        .map(|s| match s {
            Segment::Seq { index } => Some(Seg::Index(*index)),
            Segment::Map { key } => Some(Seg::Key(key.clone())),
            Segment::Enum { variant } => Some(Seg::Key(variant.clone())),
            Segment::Unknown => None,
        })
        .collect()
}

/// The value at `steps` of `root`, if there is one.
fn value_at<'a>(root: &'a toml::Table, steps: &[Seg]) -> Option<&'a toml::Value> {
    let (first, rest) = steps.split_first()?;
    let Seg::Key(k) = first else { return None };
    let mut cur = root.get(k.as_str())?;
    for s in rest {
        cur = match (s, cur) {
            (Seg::Key(k), toml::Value::Table(t)) => t.get(k.as_str())?,
            (Seg::Index(i), toml::Value::Array(a)) => a.get(*i)?,
            _ => return None,
        };
    }
    Some(cur)
}

/// The table or array holding the last step of `steps`, for a change there.
fn parent_mut<'a>(root: &'a mut toml::Table, steps: &[Seg]) -> Option<&'a mut toml::Value> {
    let (_, above) = steps.split_last()?;
    let (first, rest) = above.split_first()?;
    let Seg::Key(k) = first else { return None };
    let mut cur = root.get_mut(k.as_str())?;
    for s in rest {
        cur = match (s, cur) {
            (Seg::Key(k), toml::Value::Table(t)) => t.get_mut(k.as_str())?,
            (Seg::Index(i), toml::Value::Array(a)) => a.get_mut(*i)?,
            _ => return None,
        };
    }
    Some(cur)
}

/// Removes the key at `steps`; false when it is not there.
fn remove(root: &mut toml::Table, steps: &[Seg]) -> bool {
    match steps {
        [Seg::Key(k)] => root.remove(k.as_str()).is_some(),
        [.., Seg::Key(k)] => parent_mut(root, steps)
            .and_then(toml::Value::as_table_mut)
            .is_some_and(|t| t.remove(k.as_str()).is_some()),
        _ => false,
    }
}

/// Puts `value` at `steps` (a key of a table that is there, or an element of an array that is
/// there); false when there is no such place.
fn put(root: &mut toml::Table, steps: &[Seg], value: toml::Value) -> bool {
    match steps {
        [Seg::Key(k)] => {
            root.insert(k.clone(), value);
            true
        }
        [.., last] => match (last, parent_mut(root, steps)) {
            (Seg::Key(k), Some(toml::Value::Table(t))) => {
                t.insert(k.clone(), value);
                true
            }
            (Seg::Index(i), Some(toml::Value::Array(a))) => {
                a.get_mut(*i).map(|v| *v = value).is_some()
            }
            _ => false,
        },
        [] => false,
    }
}

/// The values to try in place of the one at `steps`, best first: the names serde expects
/// (`expected `a``, `expected `a` or `b``, `expected one of `a`, `b`, `c``), the nearest to
/// the one written first; the reference document's value there; then one value of each kind.
fn candidates(message: &str, reference: Option<&toml::Table>, steps: &[Seg]) -> Vec<toml::Value> {
    let written = message
        .strip_prefix("unknown variant `")
        .and_then(|s| s.split('`').next())
        .unwrap_or_default();
    let mut names: Vec<&str> = message
        .split_once(", expected ")
        .map_or("", |(_, list)| list)
        .split('`')
        .skip(1)
        .step_by(2)
        .collect();
    names.sort_by_key(|n| strsim::levenshtein(n, written));
    let mut out: Vec<toml::Value> = names
        .into_iter()
        .map(|n| toml::Value::String(n.into()))
        .collect();
    out.extend(reference.and_then(|r| value_at(r, steps)).cloned());
    out.extend([
        toml::Value::Integer(1),
        toml::Value::String(String::new()),
        toml::Value::Boolean(false),
        toml::Value::Array(Vec::new()),
        toml::Value::Table(toml::Table::new()),
    ]);
    out
}

/// The name serde expects that is [`nearest`] to an unknown key or variant it names, among
/// those not `present` already (a key beside its misspelling is a line to delete, not a name
/// to suggest).
fn did_you_mean<'a>(message: &'a str, present: &[&str]) -> Option<&'a str> {
    let written = ["unknown field `", "unknown variant `"]
        .iter()
        .find_map(|p| message.strip_prefix(p))?
        .split('`')
        .next()?;
    let (_, list) = message.split_once(", expected ")?;
    nearest(
        written,
        list.split('`')
            .skip(1)
            .step_by(2)
            .filter(|n| !present.contains(n)),
    )
}

/// The keys of the table that holds the last step of `at` in `doc`.
fn keys_beside<'a>(doc: &'a toml::Table, at: &[Seg]) -> Vec<&'a str> {
    let table = match at.split_last() {
        Some((_, [])) | None => Some(doc),
        Some((_, above)) => value_at(doc, above).and_then(toml::Value::as_table),
    };
    table.map_or_else(Vec::new, |t| t.keys().map(String::as_str).collect())
}

/// The name of `names` nearest to `written` when it is near enough to be a misspelling of it:
/// at most a third of its letters are added, removed, changed or swapped (at least one).
pub fn nearest<'a>(written: &str, names: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let near = names
        .into_iter()
        .min_by_key(|n| strsim::osa_distance(n, written))?;
    let most = (written.chars().count() / 3).max(1);
    (strsim::osa_distance(near, written) <= most).then_some(near)
}

/// serde's message with `(did you mean `near`?)` after the name written.
fn with_suggestion(message: &str, near: &str) -> String {
    match message.split_once(", expected ") {
        Some((head, list)) => format!("{head} (did you mean `{near}`?), expected {list}"),
        None => format!("{message} (did you mean `{near}`?)"),
    }
}

/// The problem an error of serde names, and the steps of its path (`None` when a step of it
/// has no name).
fn problem_of(err: &serde_path_to_error::Error<toml::de::Error>) -> (Problem, Option<Vec<Seg>>) {
    // The toml error appends a location line; the path already says where.
    let message = err
        .inner()
        .to_string()
        .lines()
        .next()
        .unwrap_or_default()
        .trim_end()
        .to_string();
    let path = match err.path().to_string() {
        p if p == "." => "<root>".to_string(),
        p => p,
    };
    (Problem { path, message }, steps(err.path()))
}

/// Reads `doc` into a `T`, collecting every problem (see the module's documentation).
/// `reference` is a valid document whose values are tried first in place of wrong or missing
/// ones (its value at the same path); `quiet` are paths whose problems are reported elsewhere
/// (values copied from another table, which is read too): they are read on past, not reported.
pub fn collect<T: DeserializeOwned>(
    mut doc: toml::Table,
    reference: Option<&toml::Table>,
    quiet: &[Vec<Seg>],
) -> Collected<T> {
    let mut problems = Vec::new();
    let mut replaced: Vec<Vec<Seg>> = Vec::new();
    let mut tried: Vec<(Vec<Seg>, Vec<toml::Value>)> = Vec::new();
    let mut stopped = false;
    // Keys meant by an unknown key that is near one of them (`duraton_s` → `duration_s`).
    let mut misspelt: Vec<Vec<Seg>> = Vec::new();
    for _ in 0..MAX_READINGS {
        let err = match serde_path_to_error::deserialize::<_, T>(toml::Value::Table(doc.clone())) {
            Ok(value) => {
                return Collected {
                    value: Some(value),
                    problems,
                    replaced: replaced.iter().map(|r| segs_text(r)).collect(),
                }
            }
            Err(err) => err,
        };
        let (problem, at) = problem_of(&err);
        let Some(mut at) = at else {
            problems.push(problem);
            stopped = true;
            break;
        };
        let message = problem.message.clone();
        let kind = kind(&message);
        match &kind {
            Kind::UnknownKey(k) if at.last() != Some(&Seg::Key(k.clone())) => {
                at.push(Seg::Key(k.clone()));
            }
            Kind::MissingKey(k) => at.push(Seg::Key(k.clone())),
            Kind::WrongValue | Kind::UnknownKey(_) => {}
        }
        let mut problem = problem;
        let present = match kind {
            Kind::UnknownKey(_) => keys_beside(&doc, &at),
            Kind::MissingKey(_) | Kind::WrongValue => Vec::new(),
        };
        if let Some(near) = did_you_mean(&message, &present) {
            problem.message = with_suggestion(&message, near);
            if let (Kind::UnknownKey(_), Some((_, table))) = (&kind, at.split_last()) {
                // The key meant is then missing: that is this problem, not a second one.
                misspelt.push([table, &[Seg::Key(near.to_string())]].concat());
            }
        }
        let follows = replaced.iter().chain(quiet).any(|r| at.starts_with(r));
        let read_on = match kind {
            Kind::UnknownKey(_) => remove(&mut doc, &at),
            Kind::MissingKey(_) | Kind::WrongValue => replace(
                &mut doc,
                &at,
                &message,
                reference,
                &mut tried,
                &mut replaced,
            ),
        };
        // A problem that follows from a replacement is left out, unless reading stops at it;
        // so is a key reported missing that an unknown key near its name was meant to be.
        let meant = matches!(kind, Kind::MissingKey(_)) && misspelt.contains(&at);
        if (!follows && !meant) || !read_on {
            problems.push(problem);
        }
        if !read_on {
            stopped = true;
            break;
        }
    }
    if !stopped {
        problems.push(Problem {
            path: "<file>".into(),
            message: format!(
                "reading stopped after {MAX_READINGS} errors: the problems after them are not listed"
            ),
        });
    }
    Collected {
        value: None,
        problems,
        replaced: Vec::new(),
    }
}

/// Puts at `at` the first candidate not tried there yet; false when every one was.
fn replace(
    doc: &mut toml::Table,
    at: &[Seg],
    message: &str,
    reference: Option<&toml::Table>,
    tried: &mut Vec<(Vec<Seg>, Vec<toml::Value>)>,
    replaced: &mut Vec<Vec<Seg>>,
) -> bool {
    let n = match tried.iter().position(|(p, _)| p == at) {
        Some(n) => n,
        None => {
            tried.push((at.to_vec(), Vec::new()));
            tried.len() - 1
        }
    };
    let done = &mut tried[n].1;
    let Some(next) = candidates(message, reference, at)
        .into_iter()
        .find(|c| !done.contains(c))
    else {
        return false;
    };
    done.push(next.clone());
    if !put(doc, at, next) {
        return false;
    }
    if !replaced.iter().any(|r| r == at) {
        replaced.push(at.to_vec());
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Inner {
        gain: f64,
        #[serde(default)]
        mode: Mode,
    }

    #[derive(Debug, Default, serde::Deserialize)]
    #[serde(rename_all = "kebab-case")]
    #[allow(dead_code)]
    enum Mode {
        #[default]
        Proposed,
        Traditional,
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Outer {
        a: Inner,
        b: Vec<Inner>,
        duration_s: f64,
    }

    fn read(text: &str) -> Collected<Outer> {
        collect(toml::from_str(text).expect("TOML"), None, &[])
    }

    #[test]
    fn every_table_s_problems_are_found_and_none_twice() {
        let c = read(
            r#"
            duraton_s = 1.0
            [a]
            gain = "high"
            extra = 1
            [[b]]
            gain = 1.0
            mode = "traditonal"
            [[b]]
            gain = 2.0
            mode = "propsed"
            [[b]]
            gain = 3.0
            mode = 5
            "#,
        );
        let said: Vec<String> = c.problems.iter().map(ToString::to_string).collect();
        assert_eq!(said.len(), 6, "{said:#?}");
        assert!(
            !said
                .iter()
                .any(|s| s.contains("missing field `duration_s`")),
            "the misspelt key is reported once: {said:#?}"
        );
        for (path, what) in [
            ("a.gain", "invalid type"),
            ("a.extra", "unknown field `extra`"),
            ("b[0].mode", "unknown variant `traditonal`"),
            ("b[1].mode", "unknown variant `propsed`"),
            ("b[2].mode", "invalid type"),
            (
                "duraton_s",
                "unknown field `duraton_s` (did you mean `duration_s`?)",
            ),
        ] {
            assert!(
                said.iter().any(|s| s.starts_with(path) && s.contains(what)),
                "{path}: {what} not in {said:#?}"
            );
        }
        assert!(c.value.is_some(), "read on to the end");
        assert!(c.touches_replaced("a.gain") && c.touches_replaced("a"));
        assert!(c.touches_replaced("duration_s") && !c.touches_replaced("b[0].gain"));
    }

    #[test]
    fn a_near_name_is_suggested_and_a_far_one_is_not() {
        let c = read(
            "duration_s = 1\n[a]\ngian = 1.0\nmode = \"tradition\"\n[[b]]\ngain = 1.0\nzzz = 1\n",
        );
        let said: Vec<String> = c.problems.iter().map(ToString::to_string).collect();
        assert_eq!(
            said,
            [
                "a.gian: unknown field `gian` (did you mean `gain`?), expected `gain` or `mode`",
                "a.mode: unknown variant `tradition` (did you mean `traditional`?), expected `proposed` or `traditional`",
                "b[0].zzz: unknown field `zzz`, expected `gain` or `mode`",
            ],
            "{said:#?}"
        );
    }

    #[test]
    fn a_key_beside_its_misspelling_is_not_suggested() {
        let c = read("duration_s = 1\n[a]\ngain = 1.0\ngains = 2.0\n[[b]]\ngain = 2.0\n");
        let said: Vec<String> = c.problems.iter().map(ToString::to_string).collect();
        assert_eq!(
            said,
            ["a.gains: unknown field `gains`, expected `gain` or `mode`"],
            "{said:#?}"
        );
    }

    #[test]
    fn a_missing_key_that_no_unknown_key_is_near_is_still_reported() {
        let c = read("period = 1\n[a]\ngain = 1.0\n[[b]]\ngain = 2.0\n");
        let said: Vec<String> = c.problems.iter().map(ToString::to_string).collect();
        assert!(
            said.iter()
                .any(|s| s == "<root>: missing field `duration_s`"),
            "{said:#?}"
        );
        let c = read("[a]\ngain = 1.0\n[[b]]\ngain = 2.0\n");
        let said: Vec<String> = c.problems.iter().map(ToString::to_string).collect();
        assert_eq!(said, ["<root>: missing field `duration_s`"], "{said:#?}");
    }

    #[test]
    fn a_valid_document_reads_with_nothing_replaced() {
        let c = read("duration_s = 1\n[a]\ngain = 1.0\n[[b]]\ngain = 2.0\n");
        assert!(c.problems.is_empty() && c.replaced.is_empty());
        assert!(c.value.is_some());
    }

    #[test]
    fn a_missing_table_is_one_problem_not_one_per_key_inside_it() {
        let c = read("duration_s = 1\nb = []\n");
        let said: Vec<String> = c.problems.iter().map(ToString::to_string).collect();
        assert_eq!(said, ["<root>: missing field `a`"], "{said:#?}");
    }

    #[test]
    fn nested_paths_are_told_apart_from_names_that_share_a_start() {
        assert!(nested("a", "a.b") && nested("a", "a[0]") && nested("a", "a"));
        assert!(!nested("a", "ab") && !nested("a.b", "a"));
        assert!(nested("<root>", "x"));
    }
}
