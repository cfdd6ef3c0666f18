//! The scored benchmark's suite (docs/score.md): its version, teams and seeds, and the
//! `[suite]` table of a campaign file that names it ([`SuiteFile`]). [`crate::score`] plans its
//! runs and makes its row.

use anyhow::{anyhow, bail, Context, Result};
use fdi_common::control::ControllerMode;
use fdi_common::detect;
use fdi_common::scenario::{self, Resolved};
use serde::{Deserialize, Serialize};

/// The suite's version: a change of its teams, classes, seeds, scenarios or formula is a new
/// version, and rows of two versions are not compared.
pub const SUITE: &str = "fdi-mas-score-2";
/// The held-out seeds (the shipped scenarios run at seeds 1 and 7).
pub const SEEDS: [u64; 3] = [11, 12, 13];
/// The detector judged when the suite names none: the control center's own alarm (the
/// `gated` controller's gate).
pub const DEFAULT_DETECTOR: &str = "s_hat_norm";

/// A team of the suite: a shipped scenario, embedded with the URDF files its models name, so
/// that a run reads no file and its key is the same on every machine.
#[derive(Debug)]
pub struct Team {
    pub name: &'static str,
    /// The shipped file it is (for messages and docs).
    pub file: &'static str,
    text: &'static str,
    /// The URDF files its models name: `(path as written, text)`.
    urdf: &'static [(&'static str, &'static str)],
}

const PANDA: (&str, &str) = (
    "robots/panda.urdf",
    include_str!("../../../scenarios/robots/panda.urdf"),
);

/// The suite's teams, in its order.
pub const TEAMS: &[Team] = &[
    Team {
        name: "paper",
        file: "scenarios/paper.toml",
        text: scenario::PAPER_SCENARIO,
        urdf: &[],
    },
    Team {
        name: "panda",
        file: "scenarios/panda-team.toml",
        text: include_str!("../../../scenarios/panda-team.toml"),
        urdf: &[PANDA],
    },
    Team {
        name: "mixed",
        file: "scenarios/mixed-team.toml",
        text: include_str!("../../../scenarios/mixed-team.toml"),
        urdf: &[PANDA],
    },
];

impl Team {
    /// The team's scenario as shipped, its URDF texts carried in it.
    pub fn resolve(&self) -> Result<Resolved> {
        let mut doc: toml::Table =
            toml::from_str(self.text).with_context(|| format!("{}: not TOML", self.file))?;
        if !self.urdf.is_empty() {
            let files: toml::Table = (self.urdf.iter())
                .map(|(path, text)| ((*path).to_string(), toml::Value::String((*text).into())))
                .collect();
            doc.insert(
                fdi_common::urdf_files::KEY.into(),
                toml::Value::Table(files),
            );
        }
        let text = toml::to_string(&doc).context("a team's scenario as TOML")?;
        Ok(scenario::load_str(&text, self.file, None)?)
    }

    fn named(name: &str) -> Result<&'static Team> {
        TEAMS.iter().find(|t| t.name == name).ok_or_else(|| {
            let known: Vec<&str> = TEAMS.iter().map(|t| t.name).collect();
            anyhow!("`{name}` is not a team of the suite: {}", known.join(", "))
        })
    }
}

/// A campaign file's `[suite]`: the suite in place of axes.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SuiteFile {
    /// Must be [`SUITE`]: a row names the suite it is of.
    pub version: String,
    /// The controller scored.
    pub controller: ControllerMode,
    /// The detector whose alarms are judged ([`detect::names`]).
    #[serde(default = "default_detector")]
    pub detector: String,
    /// The teams run (default: every one of [`TEAMS`]); a row of some teams is compared only
    /// with rows of the same teams.
    #[serde(default = "all_teams")]
    pub teams: Vec<String>,
}

fn default_detector() -> String {
    DEFAULT_DETECTOR.into()
}

fn all_teams() -> Vec<String> {
    TEAMS.iter().map(|t| t.name.to_string()).collect()
}

impl SuiteFile {
    /// The suite of this launcher for `controller`, judged by `detector`, over `teams` (`None`:
    /// every team).
    pub fn new(controller: ControllerMode, detector: &str, teams: Option<&[String]>) -> Self {
        Self {
            version: SUITE.into(),
            controller,
            detector: detector.into(),
            // In the suite's order, whatever the order given: the same teams, the same file.
            teams: teams.map_or_else(all_teams, |given| {
                let mut t = given.to_vec();
                // A name that is no team last (the check names it).
                t.sort_by_key(|name| {
                    (TEAMS.iter().position(|u| u.name == name.as_str())).unwrap_or(usize::MAX)
                });
                t
            }),
        }
    }

    /// The suite as a campaign file named `name` (what `fdi-launch score` writes into its
    /// folder and `fdi-launch score --campaign` prints).
    pub fn campaign_text(&self, name: &str) -> Result<String> {
        #[derive(Serialize)]
        struct File<'a> {
            name: &'a str,
            suite: &'a SuiteFile,
        }
        Ok(format!(
            "# The scored benchmark (docs/score.md) of one controller as a campaign: `fdi-launch sweep`\n\
             # runs it whole or in shards (examples/cluster/), and its tables end with the row\n\
             # (score.json, score.md).\n{}",
            toml::to_string(&File { name, suite: self }).context("the suite as TOML")?
        ))
    }

    /// Checks the suite before anything is written or run: the errors `fdi-launch sweep` would
    /// give its campaign file, each naming the field.
    pub fn checked(&self) -> Result<()> {
        self.check(&|f| f.to_string()).map(drop)
    }

    /// Checks the suite; `at` names a field with its place in the campaign file.
    pub(crate) fn check(&self, at: &dyn Fn(&str) -> String) -> Result<Vec<&'static Team>> {
        if self.version != SUITE {
            bail!(
                "{}: `{}` is not this launcher's suite `{SUITE}` (a row is of one version)",
                at("suite.version"),
                self.version
            );
        }
        if self.controller == ControllerMode::External {
            bail!(
                "{}: `external` is a program the suite does not start, and the in-process engine cannot run it",
                at("suite.controller")
            );
        }
        if !detect::names().contains(&self.detector.as_str()) {
            bail!(
                "{}: unknown detector `{}` (known: {})",
                at("suite.detector"),
                self.detector,
                detect::names().join(", ")
            );
        }
        if self.teams.is_empty() {
            bail!("{}: names no team", at("suite.teams"));
        }
        let mut teams = Vec::new();
        for (i, name) in self.teams.iter().enumerate() {
            let team = Team::named(name).with_context(|| at(&format!("suite.teams[{i}]")))?;
            if teams.iter().any(|t: &&Team| t.name == team.name) {
                bail!("{}: `{name}` twice", at(&format!("suite.teams[{i}]")));
            }
            teams.push(team);
        }
        // The rows' order is the suite's, whatever the file's.
        teams.sort_by_key(|t| TEAMS.iter().position(|u| u.name == t.name));
        Ok(teams)
    }
}

/// What the plan of a suite keeps to score its results: the suite, and each job's team, class
/// and seed.
#[derive(Debug)]
pub(crate) struct SuitePlan {
    pub(crate) file: SuiteFile,
    pub(crate) teams: Vec<&'static Team>,
    pub(crate) runs: Vec<SuiteRun>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct SuiteRun {
    pub(crate) team: &'static str,
    pub(crate) class: &'static str,
    pub(crate) seed: u64,
}
