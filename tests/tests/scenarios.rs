//! The shipped scenarios load, and every invalid case in `tests/scenario-cases/` is refused with
//! the field paths its `.expect` file names.
//!
//! A case is `NAME.toml` (a scenario that must fail to load) with a sibling `NAME.expect`: one
//! fragment per line (blank lines and lines starting with `#` are ignored), each of which must
//! appear in the error text (the `Display` of `ScenarioError`). Attack files that cases refer to
//! live in `tests/scenario-cases/attacks/` and are not cases themselves.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use fdi_common::scenario::{self, MAX_FILE_BYTES, PAPER_SCENARIO};

/// Fewest invalid cases the suite accepts (guards against a glob that silently finds nothing).
const MIN_CASES: usize = 10;

fn scenarios_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios")
}

fn cases_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenario-cases")
}

/// Files directly in `dir` whose name ends with `.{ext}`, sorted.
fn files_with_ext(dir: &Path, ext: &str) -> Vec<PathBuf> {
    let entries =
        fs::read_dir(dir).unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()));
    let mut out: Vec<PathBuf> = entries
        .map(|e| e.unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display())))
        .map(|e| e.path())
        .filter(|p| p.is_file() && p.extension().is_some_and(|x| x == ext))
        .collect();
    out.sort();
    out
}

#[test]
fn every_shipped_scenario_loads_and_validates() {
    let files = files_with_ext(&scenarios_dir(), "toml");
    assert!(
        files.iter().any(|f| f.ends_with("paper.toml")),
        "scenarios/paper.toml not found among {files:?}"
    );
    let failures: Vec<String> = files
        .iter()
        .filter_map(|f| scenario::load_file(f).err().map(|e| e.to_string()))
        .collect();
    assert!(
        failures.is_empty(),
        "{} of {} scenario(s) do not load:\n{}",
        failures.len(),
        files.len(),
        failures.join("\n")
    );
}

#[test]
fn shipped_scenarios_have_the_names_and_attacks_they_claim() {
    let dir = scenarios_dir();
    let load = |f: &str| {
        scenario::load_file(&dir.join(f)).unwrap_or_else(|e| panic!("{f} does not load: {e}"))
    };
    for (file, name, attack, agents) in [
        ("paper.toml", "paper", "paper", 4),
        ("paper-linkwise.toml", "paper-linkwise", "paper-linkwise", 4),
        ("no-attack.toml", "no-attack", "none", 4),
        ("table2-small-fast.toml", "table2-small-fast", "paper", 1),
        ("table2-large-fast.toml", "table2-large-fast", "paper", 1),
        ("table2-small-slow.toml", "table2-small-slow", "paper", 1),
        ("table2-large-slow.toml", "table2-large-slow", "paper", 1),
        ("paper-long-horizon.toml", "paper-long-horizon", "none", 4),
        (
            "example-custom-attack.toml",
            "example-custom-attack",
            "example-ramp-and-noise",
            2,
        ),
    ] {
        let r = load(file);
        assert_eq!(r.scenario.name, name, "{file}");
        assert_eq!(r.attack.name, attack, "{file}");
        assert_eq!(r.agent_count(), agents, "{file}");
    }
    assert!(load("no-attack.toml").attack.channels.is_empty());

    // The variants differ from the paper only where they say they do.
    let paper = load("paper.toml").scenario;
    for file in ["paper-linkwise.toml", "no-attack.toml"] {
        let mut s = load(file).scenario;
        s.name = paper.name.clone();
        s.attack = paper.attack.clone();
        assert_eq!(
            s, paper,
            "{file} differs from paper.toml beyond name and attack"
        );
    }

    // The long-horizon scenario: the paper's, 300 s without attack, with a robust update law
    // and the sampled observer input.
    let mut s = load("paper-long-horizon.toml").scenario;
    assert_eq!(s.duration_s, 300.0);
    assert!(!s.controller.update_law.is_paper());
    s.name = paper.name.clone();
    s.attack = paper.attack.clone();
    s.duration_s = paper.duration_s;
    s.controller.update_law = paper.controller.update_law;
    s.controller.observer_input = paper.controller.observer_input;
    assert_eq!(
        s, paper,
        "paper-long-horizon.toml differs from paper.toml beyond name, duration, attack, update law and observer input"
    );

    // Table II: robot 1 of the paper with the delays of the table (ms → s).
    for (case, amplitude_ms, offset_ms, rate) in [
        ("small-fast", 2.0, 3.0, 0.5),
        ("large-fast", 20.0, 30.0, 0.5),
        ("small-slow", 2.0, 3.0, 0.05),
        ("large-slow", 20.0, 30.0, 0.05),
    ] {
        let file = format!("table2-{case}.toml");
        let s = load(&file).scenario;
        let mut want = paper.clone();
        want.name = format!("table2-{case}");
        want.agents.retain(|a| a.id == 1);
        want.agents[0].delay = fdi_common::delay::DelayProfile::Sine {
            amplitude_s: amplitude_ms * 1e-3,
            offset_s: offset_ms * 1e-3,
            rate_rad_s: rate,
        };
        assert_eq!(s, want, "{file}");
    }
}

#[test]
fn every_shipped_attack_file_parses() {
    let files = files_with_ext(&scenarios_dir().join("attacks"), "toml");
    assert!(files.len() >= 3, "too few attack files: {files:?}");
    let failures: Vec<String> = files
        .iter()
        .filter_map(|f| scenario::load_attack_file(f).err().map(|e| e.to_string()))
        .collect();
    assert!(
        failures.is_empty(),
        "{} attack file(s) do not parse:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn scenarios_paper_toml_is_the_embedded_paper_scenario() {
    let path = scenarios_dir().join("paper.toml");
    let bytes = fs::read(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    assert!(
        bytes == PAPER_SCENARIO.as_bytes(),
        "{} differs from fdi_common::scenario::PAPER_SCENARIO",
        path.display()
    );
}

#[test]
fn every_invalid_case_is_refused_with_the_expected_messages() {
    let dir = cases_dir();
    let cases = files_with_ext(&dir, "toml");
    let mut failures = Vec::new();
    for case in &cases {
        let name = case.file_name().map_or_else(
            || case.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        let expect_path = case.with_extension("expect");
        let expected = match fs::read_to_string(&expect_path) {
            Ok(text) => text,
            Err(e) => {
                failures.push(format!(
                    "{name}: no readable {} ({e})",
                    expect_path.display()
                ));
                continue;
            }
        };
        let fragments: Vec<&str> = expected
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with('#'))
            .collect();
        if fragments.is_empty() {
            failures.push(format!("{name}: {} is empty", expect_path.display()));
            continue;
        }
        match scenario::load_file(case) {
            Ok(r) => failures.push(format!(
                "{name}: loaded, but must be refused (scenario `{}`, {} agent(s))",
                r.scenario.name,
                r.agent_count()
            )),
            Err(e) => {
                let text = e.to_string();
                let missing: Vec<&str> = fragments
                    .iter()
                    .copied()
                    .filter(|f| !text.contains(f))
                    .collect();
                if !missing.is_empty() {
                    failures.push(format!(
                        "{name}: error text lacks {missing:?}; actual error:\n{text}"
                    ));
                }
            }
        }
    }
    let orphans: Vec<PathBuf> = files_with_ext(&dir, "expect")
        .into_iter()
        .filter(|e| !e.with_extension("toml").is_file())
        .collect();
    for o in &orphans {
        failures.push(format!("{}: .expect without a .toml", o.display()));
    }
    assert!(
        failures.is_empty(),
        "{} of {} invalid case(s) failed:\n\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n\n")
    );
    assert!(
        cases.len() >= MIN_CASES,
        "only {} invalid case(s) in {}, need at least {MIN_CASES}",
        cases.len(),
        dir.display()
    );
}

/// A fresh, empty directory under the system temp dir, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> Self {
        let nanos = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        let dir =
            std::env::temp_dir().join(format!("fdi-tests-{tag}-{}-{nanos}", std::process::id()));
        fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("cannot create {}: {e}", dir.display()));
        Self(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

#[test]
fn oversized_scenario_and_attack_files_are_refused_with_the_limit() {
    let tmp = TempDir::new("oversized");
    // A valid scenario padded with a comment to just over the limit: only the size is wrong.
    let limit = usize::try_from(MAX_FILE_BYTES).expect("limit fits in usize");
    let mut text = String::from(PAPER_SCENARIO);
    text.push('#');
    text.push_str(&"x".repeat(limit + 1 - text.len()));
    text.push('\n');
    assert!(text.len() as u64 > MAX_FILE_BYTES);
    let limit_text = format!("{MAX_FILE_BYTES} byte limit");

    let path = tmp.0.join("huge.toml");
    fs::write(&path, &text).unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
    let err = scenario::load_file(&path).expect_err("an oversized scenario must be refused");
    let msg = err.to_string();
    assert!(msg.contains(&limit_text), "{msg}");
    assert!(msg.contains("huge.toml"), "{msg}");

    let attack = tmp.0.join("huge-attack.toml");
    let attack_text = format!("name = \"huge\"\nchannels = []\n#{}\n", "x".repeat(limit));
    fs::write(&attack, attack_text)
        .unwrap_or_else(|e| panic!("cannot write {}: {e}", attack.display()));
    let err = scenario::load_attack_file(&attack).expect_err("an oversized attack file");
    assert!(err.to_string().contains(&limit_text), "{err}");

    // A scenario of normal size pointing to the oversized attack file.
    let small = tmp.0.join("points-to-huge.toml");
    fs::write(
        &small,
        PAPER_SCENARIO.replace("preset = \"paper\"", "file = \"huge-attack.toml\""),
    )
    .unwrap_or_else(|e| panic!("cannot write {}: {e}", small.display()));
    let err = scenario::load_file(&small).expect_err("scenario with an oversized attack file");
    let msg = err.to_string();
    assert!(msg.contains("attack.file(huge-attack.toml)"), "{msg}");
    assert!(msg.contains(&limit_text), "{msg}");
}

/// `fdi-launch validate FILE`, its exit status, stdout and stderr.
fn validate(file: &Path) -> (Option<i32>, String, String) {
    let out = fdi_tests::launch_plain(
        &["validate", file.to_str().expect("UTF-8 path")],
        std::time::Duration::from_secs(120),
    );
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Regression (issue 33): `validate` reported only the first table that failed to read. A
/// file with five problems in three tables (a wrong type at the top level, an unknown key in
/// `[controller]`, three misspelt shapes in `[[agents]]`) lists all five, each with its path,
/// line and column, and nothing else.
#[test]
fn validate_lists_every_problem_of_every_table_with_its_line_and_column() {
    let file = cases_dir().join("five-problems-in-three-tables.toml");
    let (code, out, err) = validate(&file);
    assert_eq!(code, Some(2), "{out}{err}");
    let problems: Vec<&str> = err.lines().filter_map(|l| l.strip_prefix("  - ")).collect();
    let expected = [
        (
            "agents[0].trajectory.links[0].shape: unknown variant `cosin`",
            "(line 47, column 12)",
        ),
        (
            "agents[0].trajectory.links[1].shape: unknown variant `cosin`",
            "(line 47, column 70)",
        ),
        (
            "agents[2].trajectory.links[0].shape: unknown variant `cosin`",
            "(line 66, column 12)",
        ),
        (
            "controller.learning_rate_W: unknown field `learning_rate_W`",
            "(line 20, column 1)",
        ),
        (
            "duration_s: invalid type: string \"40\", expected f64",
            "(line 7, column 1)",
        ),
    ];
    assert_eq!(problems.len(), expected.len(), "{err}");
    for (problem, (what, place)) in problems.iter().zip(expected) {
        assert!(
            problem.starts_with(what) && problem.ends_with(place),
            "expected `{what} … {place}`, got `{problem}`:\n{err}"
        );
    }
    assert!(err.contains(": 5 problem(s):"), "{err}");
    assert!(out.is_empty(), "nothing is said valid: {out}");
}

#[test]
fn validate_takes_an_attack_profile_on_its_own_and_says_what_it_cannot_check() {
    let file = scenarios_dir().join("attacks/paper.toml");
    let (code, out, err) = validate(&file);
    assert_eq!(code, Some(0), "{out}{err}");
    assert!(
        out.contains("valid attack profile `paper` (8 channels, 0 message attacks, 0 covert)")
            && out.contains("not checked without a scenario: that agent(s) 1, 2, 3, 4 and the links named exist"),
        "{out}"
    );
    // A scenario is still validated as one.
    let (code, out, _) = validate(&scenarios_dir().join("paper.toml"));
    assert_eq!(code, Some(0));
    assert!(out.contains("valid scenario (4 agents"), "{out}");

    // An attack profile with problems that need no scenario: each with its path and place.
    let tmp = TempDir::new("validate-attack");
    let bad = tmp.0.join("bad.toml");
    fs::write(
        &bad,
        "name = \"bad\"\n[[channels]]\nagent = 12\nsignal = \"position\"\nlinks = [0]\nunits = \"deg/s\"\nsegments = [{ from_s = -1.0, waveform = { kind = \"none\" } }]\n",
    )
    .expect("write");
    let (code, out, err) = validate(&bad);
    assert_eq!(code, Some(2), "{out}{err}");
    for fragment in [
        "channels[0].links[0]: link 0 does not exist (links are 1-based) (line 5, column 10)",
        "channels[0].units: a position channel's units are \"deg\" or \"rad\", got \"deg/s\" (line 6, column 1)",
        "channels[0].segments[0].from_s: must be finite and ≥ 0, got -1 (line 7, column 15)",
        "validated as an attack profile",
    ] {
        assert!(err.contains(fragment), "lacks `{fragment}`:\n{err}");
    }
    // Agent 12 is not refused: that needs a scenario.
    assert!(!err.contains("agent 12"), "{err}");
}

#[test]
fn an_included_attack_file_s_problems_name_the_file_line_and_column_and_the_valid_agents() {
    let tmp = TempDir::new("included-attack");
    fs::create_dir_all(tmp.0.join("attacks")).expect("attacks/");
    fs::write(
        tmp.0.join("attacks/a.toml"),
        "name = \"a\"\n\n[[channels]]\nagent = 1\nsignal = \"velocity\"\nlinks = [1, 3]\nunits = \"deg/s\"\nsegments = [{ from_s = 0.0, waveform = { kind = \"constant\", value = 1.0 } }]\n\n[[messages]]\nagent = 5\npath = \"torque\"\nsegments = [{ from_s = 0.0, effect = { kind = \"drop\", probability = 2.0 } }]\n",
    )
    .expect("write");
    let scenario = tmp.0.join("s.toml");
    fs::write(
        &scenario,
        PAPER_SCENARIO.replace("preset = \"paper\"", "file = \"attacks/a.toml\""),
    )
    .expect("write");
    let (code, out, err) = validate(&scenario);
    assert_eq!(code, Some(2), "{out}{err}");
    for fragment in [
        "attack.file(attacks/a.toml).messages[0].agent: agent 5 is not in the scenario (its agents: 1, 2, 3, 4) (line 11, column 1 of attacks/a.toml)",
        "attack.file(attacks/a.toml).messages[0].segments[0].effect.probability: must be a probability in [0, 1], got 2 (line 13, column",
        "attack.file(attacks/a.toml).channels[0].links[1]: link 3 does not exist (links are 1-based, agent 1 has 2 links) (line 6, column 13 of attacks/a.toml)",
    ] {
        assert!(err.contains(fragment), "lacks `{fragment}`:\n{err}");
    }
    // A wrong type in the included file: named, with its place.
    fs::write(
        tmp.0.join("attacks/a.toml"),
        "name = \"a\"\n[[channels]]\nagent = \"one\"\nsignal = \"position\"\nlinks = [1]\nunits = \"rad\"\nsegments = []\n",
    )
    .expect("write");
    let (code, _, err) = validate(&scenario);
    assert_eq!(code, Some(2));
    assert!(
        err.contains("attack.file(attacks/a.toml).channels[0].agent: invalid type: string \"one\", expected u32 (line 3, column 1 of attacks/a.toml)"),
        "{err}"
    );
}

#[test]
fn validate_warns_about_attack_segments_after_the_run_s_end_and_still_accepts() {
    let tmp = TempDir::new("late-segment");
    let scenario = tmp.0.join("short.toml");
    fs::write(
        &scenario,
        PAPER_SCENARIO.replace("duration_s = 40.0", "duration_s = 8.0"),
    )
    .expect("write");
    let (code, out, err) = validate(&scenario);
    assert_eq!(code, Some(0), "{out}{err}");
    // The paper's attack switches at 10, 25 and 30 s: after an 8 s run.
    assert!(
        out.contains("warning: attack.channels[0].segments[1].from_s: starts at 10 s, at or after the end of the run (duration_s = 8 s): it never acts"),
        "{out}"
    );
}
