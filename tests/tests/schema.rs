//! The JSON Schemas of the file formats (`fdi-launch schema scenario|attack`): the shipped copies
//! in `scenarios/schema/` are the command's output, every shipped file carries the editors' hint
//! to its schema and passes it, files the loader refuses for a key or a type the schema refuses
//! too, and docs/scenarios.md names every key of both schemas.

use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};
use std::time::Duration;

use fdi_common::scenario;
use fdi_tests::launch_plain;
use serde_json::Value;

const WATCHDOG: Duration = Duration::from_secs(120);

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// `*.toml` directly in `dir`, sorted.
fn toml_files(dir: &Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.is_file() && p.extension().is_some_and(|x| x == "toml"))
        .collect();
    out.sort();
    out
}

fn scenario_files() -> Vec<PathBuf> {
    let files = toml_files(&repo().join("scenarios"));
    assert!(files.len() >= 5, "too few scenarios: {files:?}");
    files
}

fn attack_files() -> Vec<PathBuf> {
    let files = toml_files(&repo().join("scenarios/attacks"));
    assert!(files.len() >= 5, "too few attack files: {files:?}");
    files
}

fn read(path: &Path) -> String {
    fs::read_to_string(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

/// A TOML value as the JSON a schema validator checks. TOML's `nan` and `inf` literals, which
/// JSON lacks, become the strings "nan", "inf", "-inf" (the forms a `corrupt` value also
/// takes as text); dates become their text.
fn to_json(v: &toml::Value) -> Value {
    match v {
        toml::Value::String(s) => Value::String(s.clone()),
        toml::Value::Integer(i) => Value::from(*i),
        toml::Value::Float(f) if f.is_nan() => Value::String("nan".into()),
        toml::Value::Float(f) if f.is_infinite() => {
            Value::String(if *f > 0.0 { "inf" } else { "-inf" }.into())
        }
        toml::Value::Float(f) => Value::from(*f),
        toml::Value::Boolean(b) => Value::Bool(*b),
        toml::Value::Datetime(d) => Value::String(d.to_string()),
        toml::Value::Array(a) => Value::Array(a.iter().map(to_json).collect()),
        toml::Value::Table(t) => Value::Object(
            t.iter()
                .map(|(k, v)| (k.clone(), to_json(v)))
                .collect::<serde_json::Map<_, _>>(),
        ),
    }
}

fn toml_to_json(text: &str, what: &str) -> Value {
    let table: toml::Table = toml::from_str(text).unwrap_or_else(|e| panic!("{what}: {e}"));
    to_json(&toml::Value::Table(table))
}

fn validator(schema: &Value) -> jsonschema::Validator {
    jsonschema::validator_for(schema).expect("the schema compiles")
}

/// The schema's complaints about `instance`, one line each.
fn schema_errors(v: &jsonschema::Validator, instance: &Value) -> Vec<String> {
    v.iter_errors(instance)
        .map(|e| format!("{}: {e}", e.instance_path()))
        .collect()
}

#[test]
fn the_shipped_schemas_are_what_the_schema_command_prints() {
    for (format, file, generated) in [
        (
            "scenario",
            "scenario.schema.json",
            scenario::scenario_schema(),
        ),
        ("attack", "attack.schema.json", scenario::attack_schema()),
    ] {
        let out = launch_plain(&["schema", format], WATCHDOG);
        assert!(out.status.success(), "schema {format}: {out:?}");
        let printed = String::from_utf8(out.stdout).expect("UTF-8");
        let path = repo().join("scenarios/schema").join(file);
        assert!(
            read(&path) == printed,
            "{} differs from `fdi-launch schema {format}`: regenerate it with \
             `fdi-launch schema {format} > scenarios/schema/{file}`",
            path.display()
        );
        let parsed: Value = serde_json::from_str(&printed).expect("the output is JSON");
        assert_eq!(parsed, generated, "{format}");
        assert_eq!(
            parsed["$schema"], "http://json-schema.org/draft-07/schema#",
            "{format}: draft 7, which TOML editors read"
        );
    }
}

#[test]
fn every_shipped_file_starts_with_the_hint_to_its_schema() {
    for (files, hint, schema) in [
        (
            scenario_files(),
            "#:schema ./schema/scenario.schema.json",
            "scenario.schema.json",
        ),
        (
            attack_files(),
            "#:schema ../schema/attack.schema.json",
            "attack.schema.json",
        ),
    ] {
        for f in files {
            let text = read(&f);
            let first = text.lines().next().unwrap_or_default();
            assert_eq!(first, hint, "{}: first line", f.display());
            // The hint's path, relative to the file, names the shipped schema.
            let rel = hint.trim_start_matches("#:schema ");
            let target = f.parent().expect("folder").join(rel);
            assert!(
                target.is_file() && target.ends_with(schema),
                "{}: {} is not the schema",
                f.display(),
                target.display()
            );
        }
    }
    // The embedded default scenario is that file, hint and all, and still loads.
    assert!(scenario::PAPER_SCENARIO.starts_with("#:schema ./schema/scenario.schema.json\n"));
    scenario::paper().expect("the embedded scenario loads");
}

#[test]
fn every_shipped_scenario_and_attack_file_passes_its_schema() {
    let scenarios = validator(&scenario::scenario_schema());
    let attacks = validator(&scenario::attack_schema());
    let mut failures = Vec::new();
    for (v, files) in [(&scenarios, scenario_files()), (&attacks, attack_files())] {
        for f in files {
            let errors = schema_errors(v, &toml_to_json(&read(&f), &f.display().to_string()));
            if !errors.is_empty() {
                failures.push(format!("{}:\n  {}", f.display(), errors.join("\n  ")));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Each case changes a valid file in one place; the loader refuses it, and so must the schema,
/// at the path of the change.
#[test]
fn a_wrong_type_or_an_unknown_key_is_refused_by_the_schema_as_by_the_loader() {
    let scenarios = validator(&scenario::scenario_schema());
    let attacks = validator(&scenario::attack_schema());
    let paper = scenario::PAPER_SCENARIO;
    let attack = read(&repo().join("scenarios/attacks/paper.toml"));
    let scenario_cases = [
        ("duration_s = 40.0", "duration_s = \"forty\"", "/duration_s"),
        ("seed = 1\n", "seed = 1\nfrobnicate = true\n", ""),
        ("seed = 1\n", "seed = -1\n", "/seed"),
        (
            "gain_k = 21.0",
            "gain_k = 21.0\ngain_q = 1.0",
            "/controller",
        ),
        (
            "mode = \"proposed\"",
            "mode = \"clever\"",
            "/controller/mode",
        ),
        (
            "preset = \"paper\"",
            "preset = \"papers\"",
            "/attack/preset",
        ),
        (
            "preset = \"paper\"",
            "preset = \"paper\"\nfile = \"x.toml\"",
            "/attack",
        ),
    ];
    for (from, to, at) in scenario_cases {
        assert!(paper.contains(from), "the paper scenario has `{from}`");
        let text = paper.replacen(from, to, 1);
        assert!(
            scenario::load_str(&text, "case", None).is_err(),
            "the loader takes `{to}`"
        );
        let errors = schema_errors(&scenarios, &toml_to_json(&text, to));
        assert!(
            errors.iter().any(|e| e.starts_with(&format!("{at}:"))),
            "`{to}`: the schema says {errors:?}"
        );
    }
    // No agent names a model, and [defaults] does not either: the schema asks for it.
    let first_model = "model = { kind = \"two-link\" }\n";
    assert!(paper.contains(first_model));
    let text = paper.replace(first_model, "");
    assert!(scenario::load_str(&text, "case", None).is_err());
    let errors = schema_errors(&scenarios, &toml_to_json(&text, "no model"));
    assert!(
        errors.iter().any(|e| e.contains("\"model\" is a required")),
        "{errors:?}"
    );
    // With [defaults] model set, the agents may leave it out.
    let with_defaults = text.replacen(
        "[[agents]]",
        "[defaults]\nmodel = { kind = \"two-link\" }\n\n[[agents]]",
        1,
    );
    scenario::load_str(&with_defaults, "defaults", None).expect("valid with [defaults]");
    assert_eq!(
        schema_errors(&scenarios, &toml_to_json(&with_defaults, "defaults")),
        Vec::<String>::new()
    );

    let attack_cases = [
        (
            "units = \"deg\"",
            "units = \"furlong\"",
            "/channels/0/units",
        ),
        ("agent = 1", "agent = \"one\"", "/channels/0/agent"),
        (
            "links = [1, 2]",
            "links = [1, 2]\nstrength = 3",
            "/channels/0",
        ),
        (
            "kind = \"sine\"",
            "kind = \"sawtooth\"",
            "/channels/0/segments/0/waveform",
        ),
        ("name = \"paper\"", "name = \"paper\"\nchanels = []", ""),
    ];
    let dir = std::env::temp_dir().join(format!("fdi-schema-cases-{}", std::process::id()));
    fs::create_dir_all(&dir).expect("scratch folder");
    for (from, to, at) in attack_cases {
        assert!(attack.contains(from), "the paper attack has `{from}`");
        let text = attack.replacen(from, to, 1);
        let file = dir.join("case.toml");
        fs::write(&file, &text).expect("write");
        assert!(
            scenario::load_attack_file(&file).is_err(),
            "the loader takes `{to}`"
        );
        let errors = schema_errors(&attacks, &toml_to_json(&text, to));
        assert!(
            errors.iter().any(|e| e.starts_with(&format!("{at}:"))),
            "`{to}`: the schema says {errors:?}"
        );
    }
    let _ = fs::remove_dir_all(&dir);
}

/// Every property name of `schema`, anywhere in it (definitions, variants, conditions).
fn property_keys(schema: &Value, out: &mut BTreeSet<String>) {
    match schema {
        Value::Object(map) => {
            for (k, v) in map {
                if k == "properties" {
                    if let Value::Object(props) = v {
                        for (name, sub) in props {
                            out.insert(name.clone());
                            property_keys(sub, out);
                        }
                    }
                } else {
                    property_keys(v, out);
                }
            }
        }
        Value::Array(items) => items.iter().for_each(|v| property_keys(v, out)),
        _ => {}
    }
}

#[test]
fn docs_scenarios_md_names_every_key_of_both_schemas() {
    let doc = read(&repo().join("docs/scenarios.md"));
    let mut keys = BTreeSet::new();
    property_keys(&scenario::scenario_schema(), &mut keys);
    property_keys(&scenario::attack_schema(), &mut keys);
    assert!(keys.len() > 50, "the walk found only {keys:?}");
    let missing: Vec<&String> = keys
        .iter()
        .filter(|k| !doc.contains(&format!("`{k}`")))
        .collect();
    assert!(
        missing.is_empty(),
        "docs/scenarios.md does not name (as `key`): {missing:?}"
    );
}
