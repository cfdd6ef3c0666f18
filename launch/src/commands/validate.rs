//! `fdi-launch validate` and `fdi-launch schema`: the file formats, checked and described.

use std::path::Path;
use std::process::ExitCode;

use anyhow::Result;
use fdi_common::scenario;

use clap::ValueEnum;

/// A file format that `schema` describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SchemaFormat {
    /// A scenario file (`scenarios/*.toml`).
    Scenario,
    /// An attack-profile file (`scenarios/attacks/*.toml`).
    Attack,
}

/// `schema`: the JSON Schema of `format`, pretty-printed, on stdout.
pub fn schema(format: SchemaFormat) -> Result<ExitCode> {
    let schema = match format {
        SchemaFormat::Scenario => scenario::scenario_schema(),
        SchemaFormat::Attack => scenario::attack_schema(),
    };
    println!("{}", serde_json::to_string_pretty(&schema)?);
    Ok(ExitCode::SUCCESS)
}

/// `validate`: a scenario, or an attack profile on its own (what it holds decides).
pub fn validate(path: &Path) -> Result<ExitCode> {
    // A file that cannot be read is the scenario loader's to refuse (it says why).
    let kind = scenario::read_limited(path)
        .map_or(scenario::FileKind::Scenario, |t| scenario::file_kind(&t));
    if kind == scenario::FileKind::AttackProfile {
        return validate_attack(path);
    }
    match scenario::load_file(path) {
        Ok(r) => {
            println!(
                "{}: valid scenario ({} agents, {} ticks, attack `{}`)",
                path.display(),
                r.agent_count(),
                r.ticks(),
                r.attack.name
            );
            for w in r.scenario.warnings(&r.attack) {
                println!("  warning: {}: {}", w.path, w.message);
            }
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            eprintln!("{e}");
            Ok(ExitCode::from(2))
        }
    }
}

/// `validate` of an attack profile without a scenario: what it checks, and what it cannot.
fn validate_attack(path: &Path) -> Result<ExitCode> {
    match scenario::validate_attack_alone(path) {
        Ok(p) => {
            let agents: Vec<String> = p.agents().iter().map(u32::to_string).collect();
            println!(
                "{}: valid attack profile `{}` ({} channels, {} message attacks, {} covert)",
                path.display(),
                p.name,
                p.channels.len(),
                p.messages.len(),
                p.covert.len()
            );
            println!(
                "  not checked without a scenario: that {} and the links named exist, and the segments' start times against the run's duration (validate a scenario that names this file, or `run --attack {}`)",
                if agents.is_empty() {
                    "the agents".to_string()
                } else {
                    format!("agent(s) {}", agents.join(", "))
                },
                path.display()
            );
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            eprintln!("{e}");
            eprintln!("(validated as an attack profile: it has `channels`, `messages` or `covert` and no scenario key)");
            Ok(ExitCode::from(2))
        }
    }
}
