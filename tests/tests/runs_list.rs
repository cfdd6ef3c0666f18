//! `fdi-launch runs list`: every kind of output folder the commands make, each with its kind,
//! and sizes as `du` counts them (checked against `du -sk` itself), through the real binary.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use fdi_tests::{json, launch, launch_plain, run_dir_of, Scratch};
use serde_json::Value;

const WATCHDOG: Duration = Duration::from_secs(600);

/// `du -sk PATH`: KiB, rounded up.
fn du_k(path: &Path) -> u64 {
    let out = Command::new("du")
        .arg("-sk")
        .arg(path)
        .output()
        .expect("running du");
    assert!(out.status.success(), "du -sk {}", path.display());
    String::from_utf8_lossy(&out.stdout)
        .split_whitespace()
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("du's output: {}", String::from_utf8_lossy(&out.stdout)))
}

/// Bytes as `du -k` shows them.
fn kib(bytes: &Value) -> u64 {
    bytes.as_u64().expect("bytes").div_ceil(1024)
}

fn ok(out: &std::process::Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// One folder of each kind, made by its command, and what no command made.
fn make_outputs(root: &Path) -> BTreeMap<String, &'static str> {
    let mut want = BTreeMap::new();
    let short = ["--engine", "inproc", "--duration-s", "0.2"];
    let run = json(&launch(
        &[&["run", "--json"][..], &short].concat(),
        root,
        WATCHDOG,
    ));
    let run_dir = run_dir_of(&run);
    let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
    want.insert(name(&run_dir).expect("a name"), "run");
    for table in ["table1", "table2"] {
        ok(
            &launch(&[&[table][..], &short].concat(), root, WATCHDOG),
            table,
        );
    }
    ok(
        &launch_plain(
            &[
                "attacks",
                "--duration-s",
                "11",
                "--json",
                "--out",
                &root.join("my-attacks").to_string_lossy(),
            ],
            WATCHDOG,
        ),
        "attacks",
    );
    want.insert("my-attacks".into(), "attacks");
    ok(
        &launch(
            &[
                "bench",
                "lockstep",
                "--agents",
                "1",
                "--duration-s",
                "0.2",
                "--json",
            ],
            root,
            WATCHDOG,
        ),
        "bench lockstep",
    );
    let campaign = root.join("small.toml");
    std::fs::write(
        &campaign,
        "name = \"small\"\nmode = \"product\"\n[set]\nduration_s = 0.2\n\
         [[axes]]\npath = \"seed\"\nvalues = [1, 2]\n",
    )
    .expect("campaign file");
    ok(
        &launch(
            &[
                "sweep",
                &campaign.to_string_lossy(),
                "--engine",
                "inproc",
                "--jobs",
                "1",
            ],
            &root.join("campaigns/small"),
            WATCHDOG,
        ),
        "sweep",
    );
    want.insert("campaigns/small".into(), "campaign");
    ok(
        &launch_plain(
            &[
                "detect",
                &run_dir.to_string_lossy(),
                "--points",
                "5",
                "--out",
                &root.join("roc-of-the-run").to_string_lossy(),
            ],
            WATCHDOG,
        ),
        "detect",
    );
    want.insert("roc-of-the-run".into(), "detect");
    // Not made by fdi-launch: a file, and a folder holding a hard link to a trace of the run
    // (`du` counts a file with two links once in a total).
    std::fs::write(root.join("notes.txt"), "mine").expect("notes");
    std::fs::create_dir(root.join("mine")).expect("mine");
    std::fs::hard_link(
        fdi_common::run_dir::RunDir::new(&run_dir)
            .traces()
            .join("agent-1.trace"),
        root.join("mine/agent-1.trace"),
    )
    .expect("a hard link");
    // The tables' and the bench's folders are named by their commands.
    for e in std::fs::read_dir(root).expect("root").flatten() {
        let n = e.file_name().to_string_lossy().into_owned();
        for (suffix, kind) in [
            ("-table1", "table1"),
            ("-table2", "table2"),
            ("-bench-lockstep", "bench-lockstep"),
        ] {
            if n.ends_with(suffix) {
                want.insert(n.clone(), kind);
            }
        }
    }
    want
}

#[test]
fn runs_list_names_every_kind_of_output_folder_and_counts_sizes_as_du_does() {
    let scratch = Scratch::new("runs-list");
    let root = scratch.0.join("runs");
    std::fs::create_dir_all(&root).expect("root");
    let want = make_outputs(&root);
    // run, table1, table2, attacks, bench-lockstep, campaign, detect.
    assert_eq!(want.len(), 7, "{want:?}");
    let root_s = root.to_string_lossy().into_owned();
    let o = launch_plain(&["runs", "list", "--out", &root_s, "--json"], WATCHDOG);
    ok(&o, "runs list --json");
    let listing: Value = serde_json::from_slice(&o.stdout).expect("JSON");
    let outputs = listing["outputs"].as_array().expect("outputs");
    let got: BTreeMap<String, String> = outputs
        .iter()
        .map(|x| {
            (
                x["name"].as_str().expect("name").to_string(),
                x["kind"].as_str().expect("kind").to_string(),
            )
        })
        .collect();
    let want_s: BTreeMap<String, String> = want
        .iter()
        .map(|(k, v)| (k.clone(), v.to_string()))
        .collect();
    // The bench's and the table's run directories are inside their folders, not listed apart.
    assert_eq!(got, want_s);
    for x in outputs {
        let path = Path::new(x["path"].as_str().expect("path"));
        assert_eq!(kib(&x["bytes"]), du_k(path), "{}", path.display());
    }
    let other: Vec<&str> = listing["other"]
        .as_array()
        .expect("other")
        .iter()
        .map(|x| x["path"].as_str().expect("path"))
        .collect();
    for name in ["mine", "notes.txt", "small.toml"] {
        assert!(
            other.iter().any(|p| p.ends_with(&format!("/{name}"))),
            "{name} not in {other:?}"
        );
    }
    for x in listing["other"].as_array().expect("other") {
        let path = Path::new(x["path"].as_str().expect("path"));
        assert_eq!(kib(&x["bytes"]), du_k(path), "{}", path.display());
    }
    assert_eq!(kib(&listing["bytes"]), du_k(&root), "the total");
    assert!(listing["unreadable"].as_array().is_some_and(Vec::is_empty));

    // The table: a header, every row's columns where the header's are.
    let o = launch_plain(&["runs", "list", "--out", &root_s], WATCHDOG);
    ok(&o, "runs list");
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let lines: Vec<&str> = text.lines().collect();
    let head = lines[0];
    assert!(head.starts_with("NAME "), "{text}");
    let at = |column: &str| {
        head.find(column)
            .unwrap_or_else(|| panic!("{column}: {text}"))
    };
    let (kind_at, date_at) = (at("KIND"), at("MODIFIED (UTC)"));
    for (name, kind) in &want {
        let line = lines
            .iter()
            .find(|l| l.starts_with(&format!("{name} ")))
            .unwrap_or_else(|| panic!("{name} not listed:\n{text}"));
        assert_eq!(line[kind_at..].split(' ').next(), Some(*kind), "{line}");
        assert!(line[date_at..].starts_with("20"), "{line}");
    }
    assert!(
        text.contains("3 other entries")
            && text.contains(&format!(
                "7 output folders in {root_s} (1 run, 1 table1, 1 table2, 1 attacks, \
                 1 bench-lockstep, 1 campaign, 1 detect)"
            )),
        "{text}"
    );
}
