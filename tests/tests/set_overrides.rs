//! `--set PATH=VALUE` (issue 33): one value of the scenario changed on the command line, in the
//! field-path language of campaigns. A run with `--set` is the run of a file with the same edit
//! (digest for digest, the saved scenario equal), named after the edit; a path or a value that
//! does not fit is refused naming both, before anything is created.

use std::path::Path;
use std::process::Output;
use std::time::Duration;

use fdi_common::scenario::PAPER_SCENARIO;
use fdi_tests::{json, launch, launch_plain, run_dir_of, Scratch};

const LIMIT: Duration = Duration::from_secs(300);

/// `run --engine inproc --duration-s 1 --json` with `extra` (a scenario file, `--set`s), its
/// output under `out`.
fn run(extra: &[&str], out: &Path) -> Output {
    let mut args = vec!["run", "--engine", "inproc", "--duration-s", "1", "--json"];
    args.extend(extra);
    launch(&args, out, LIMIT)
}

/// `text` with the `n`-th (from 0) occurrence of `from` replaced by `to`; the test fails when
/// there is no such occurrence.
fn replace_nth(text: &str, from: &str, to: &str, n: usize) -> String {
    let (at, _) = text
        .match_indices(from)
        .nth(n)
        .unwrap_or_else(|| panic!("no occurrence {n} of {from:?}"));
    format!("{}{to}{}", &text[..at], &text[at + from.len()..])
}

fn scenario_toml(summary: &serde_json::Value) -> String {
    let path = run_dir_of(summary).join("scenario.toml");
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

#[test]
fn a_run_with_set_is_the_run_of_a_file_with_the_same_edit() {
    let tmp = Scratch::new("set-digest");
    let set = run(
        &[
            "--set",
            "controller.beta=10",
            "--set",
            "agents[1].delay.offset_s=0.004",
        ],
        &tmp.0.join("set"),
    );
    let set = json(&set);
    let edited = replace_nth(
        &PAPER_SCENARIO.replace("beta = 30.0", "beta = 10.0"),
        "offset_s = 0.003",
        "offset_s = 0.004",
        1,
    );
    let file = tmp.0.join("edited.toml");
    std::fs::write(&file, edited).expect("write the edited scenario");
    let from_file = json(&run(
        &[file.to_str().expect("UTF-8 path")],
        &tmp.0.join("file"),
    ));
    let plain = json(&run(&[], &tmp.0.join("plain")));
    assert_eq!(
        set["trace_digest"], from_file["trace_digest"],
        "--set and the same edit in a file run differently"
    );
    assert_ne!(
        set["trace_digest"], plain["trace_digest"],
        "the edits changed nothing"
    );
    // The saved scenario holds the edits, as the file's run does.
    let saved = scenario_toml(&set);
    assert!(saved.contains("beta = 10.0"), "{saved}");
    assert_eq!(saved, scenario_toml(&from_file));
    // The run directory names the edits (made one path component by the rule of run folders).
    let name = run_dir_of(&set)
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .expect("a run directory name");
    assert!(
        name.ends_with("-paper-inproc-1s-controller_beta_10-agents_1__delay_offset_s_0_004"),
        "{name}"
    );
}

#[test]
fn table1_takes_set_names_it_and_refuses_what_it_sets_itself() {
    let tmp = Scratch::new("set-table");
    let out = tmp.0.to_str().expect("UTF-8 path");
    let table = launch_plain(
        &[
            "table1",
            "--engine",
            "inproc",
            "--duration-s",
            "1",
            "--json",
            "--set",
            "controller.beta=10",
            "--out",
            out,
        ],
        LIMIT,
    );
    let stdout = String::from_utf8_lossy(&table.stdout);
    assert!(
        table.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&table.stderr)
    );
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).expect("the table's JSON");
    assert_eq!(
        v["made_with"]["set"],
        serde_json::json!(["controller.beta=10"])
    );
    let folders: Vec<String> = std::fs::read_dir(&tmp.0)
        .expect("the table's folder")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        folders.len() == 1 && folders[0].ends_with("-table1-controller_beta_10"),
        "{folders:?}"
    );
    // Table I runs both controllers: an edit of the mode would be undone, so it is refused.
    let refused = launch_plain(
        &[
            "table1",
            "--engine",
            "inproc",
            "--set",
            "controller.mode=traditional",
            "--out",
            out,
        ],
        LIMIT,
    );
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success());
    assert!(
        err.contains("--set controller.mode=traditional: this table sets `controller.mode` itself"),
        "{err}"
    );
}

#[test]
fn a_set_that_does_not_fit_is_refused_naming_its_path_and_value() {
    let tmp = Scratch::new("set-refused");
    let out = tmp.0.join("runs");
    for (edits, said) in [
        (
            &["--set", "controller.betta=10"][..],
            &["--set controller.betta=10: field path `controller.betta`: `controller` has no key `betta`; its keys: beta,"][..],
        ),
        (
            &["--set", "seed=x"],
            &["--set seed=x: field path `seed` holds an integer; the value \"x\" is a string"],
        ),
        (
            &["--set", "controller.beta=-1"],
            &[
                "command-line overrides (--set controller.beta=-1)",
                "controller.beta: must be finite and > 0, got -1",
            ],
        ),
        (
            &["--set", "controller.mode=traditonal"],
            &["controller.mode: unknown variant `traditonal` (did you mean `traditional`?), expected one of `proposed`, `traditional`, `computed-torque`, `gated`, `pd`"],
        ),
        (
            &["--set", "agents[7].id=8"],
            &["--set agents[7].id=8: field path `agents[7].id`: `agents` has 4 elements, no index 7"],
        ),
        (
            &["--set", "duration_s=2"],
            &["--set duration_s=2: --duration-s sets `duration_s` too: give the value once"],
        ),
        (
            &["--set", "controller.beta=10", "--set", "controller=1"],
            &["--set controller.beta=10: --set controller=1 reaches the same value: give it once"],
        ),
        (
            &["--set", "controller.beta"],
            &["'controller.beta' for '--set <PATH=VALUE>'", "expected PATH=VALUE"],
        ),
        (
            &["--set", "controller..beta=1"],
            &["\"controller..beta=1\": field path \"controller..beta\": an empty key"],
        ),
    ] {
        let refused = run(edits, &out);
        let err = String::from_utf8_lossy(&refused.stderr);
        assert!(!refused.status.success(), "{edits:?} was run");
        for fragment in said {
            assert!(err.contains(fragment), "{edits:?}: lacks `{fragment}`:\n{err}");
        }
    }
    assert!(
        !out.exists() || std::fs::read_dir(&out).expect("runs").next().is_none(),
        "a refused run left a run directory"
    );
}

/// A resolved scenario holds a copy of `[defaults]` in every agent that inherits it, and the
/// run reads the agents': an edit of `defaults.…` reaches the agents that inherit the value
/// (not one given its own by another edit, in either order) as the same edit in the file
/// does, and an edit of `[defaults]` that no agent inherits is refused instead of changing
/// nothing.
#[test]
fn a_set_of_defaults_reaches_the_agents_that_inherit_them() {
    let tmp = Scratch::new("set-defaults");
    let robots = tmp.0.join("robots");
    std::fs::create_dir_all(&robots).expect("robots folder");
    std::fs::copy(
        fdi_tests::repo_path("scenarios/robots/panda.urdf"),
        robots.join("panda.urdf"),
    )
    .expect("copy the Panda's URDF");
    let mixed = std::fs::read_to_string(fdi_tests::repo_path("scenarios/mixed-team.toml"))
        .expect("read the mixed team");
    let plain_file = tmp.0.join("mixed.toml");
    std::fs::write(&plain_file, &mixed).expect("write the mixed team");
    let plain_file = plain_file.to_str().expect("UTF-8 path");
    // In the file: the defaults' delay at 4 ms, robot 2 with its own at 5 ms.
    let edited = replace_nth(&mixed, "offset_s = 0.003", "offset_s = 0.004", 0).replace(
        "id = 2\n",
        "id = 2\ndelay = { kind = \"sine\", amplitude_s = 0.002, offset_s = 0.005, rate_rad_s = 0.5 }\n",
    );
    assert_ne!(edited, mixed);
    let file = tmp.0.join("edited.toml");
    std::fs::write(&file, edited).expect("write the edited scenario");
    let from_file = json(&run(
        &[file.to_str().expect("UTF-8 path")],
        &tmp.0.join("file"),
    ));
    let defaults = "defaults.delay.offset_s=0.004";
    let own = "agents[1].delay.offset_s=0.005";
    for (order, edits) in [
        ("defaults first", [defaults, own]),
        ("the agent first", [own, defaults]),
    ] {
        let set = json(&run(
            &[plain_file, "--set", edits[0], "--set", edits[1]],
            &tmp.0.join(order.replace(' ', "-")),
        ));
        assert_eq!(
            set["trace_digest"], from_file["trace_digest"],
            "{order}: --set of [defaults] and the same edit in the file run differently"
        );
    }
    let plain = json(&run(&[plain_file], &tmp.0.join("plain")));
    assert_ne!(plain["trace_digest"], from_file["trace_digest"]);

    // Every agent with a delay of its own: an edit of the defaults' would change nothing.
    let own_delays = mixed
        .replace(
            "delay = { kind = \"sine\", amplitude_s = 0.002, offset_s = 0.003",
            "delay = { kind = \"sine\", amplitude_s = 0.002, offset_s = 0.009",
        )
        .replace(
            "id = 1\n",
            "id = 1\ndelay = { kind = \"constant\", value_s = 0.003 }\n",
        )
        .replace(
            "id = 2\n",
            "id = 2\ndelay = { kind = \"constant\", value_s = 0.003 }\n",
        )
        .replace(
            "id = 3\n",
            "id = 3\ndelay = { kind = \"constant\", value_s = 0.003 }\n",
        )
        .replace(
            "id = 4\n",
            "id = 4\ndelay = { kind = \"constant\", value_s = 0.003 }\n",
        );
    let file = tmp.0.join("own-delays.toml");
    std::fs::write(&file, own_delays).expect("write the scenario");
    let out = tmp.0.join("refused");
    let refused = run(
        &[
            file.to_str().expect("UTF-8 path"),
            "--set",
            "defaults.delay.offset_s=0.004",
        ],
        &out,
    );
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "an edit of nothing was run");
    assert!(
        err.contains("--set defaults.delay.offset_s=0.004: no agent inherits `defaults.delay`"),
        "{err}"
    );
    assert!(!out.exists(), "a refused run left a run directory");
    let whole = run(
        &[
            plain_file,
            "--set",
            "defaults={ delay = { kind = \"constant\", value_s = 0.004 } }",
        ],
        &out,
    );
    let err = String::from_utf8_lossy(&whole.stderr);
    assert!(
        !whole.status.success(),
        "an edit of [defaults] whole was run"
    );
    assert!(
        err.contains("edits `[defaults]` whole: set one of its keys"),
        "{err}"
    );
    assert!(!out.exists(), "a refused run left a run directory");
}
