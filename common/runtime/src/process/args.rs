//! The launcher's arguments to a child process, one struct for both sides.

use std::path::PathBuf;

use super::placement::Placement;

/// Arguments the launcher passes to every process: the child parses them (clap), the launcher
/// builds a child's command line from the same struct ([`ProcessArgs::to_args`]).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct ProcessArgs {
    /// Run prefix (iceoryx2 `global.prefix`): isolates this run's services.
    #[cfg_attr(feature = "clap", arg(long))]
    pub prefix: String,
    /// Resolved scenario file of the run.
    #[cfg_attr(feature = "clap", arg(long))]
    pub scenario: PathBuf,
    /// Trace file this process writes.
    #[cfg_attr(feature = "clap", arg(long))]
    pub trace: PathBuf,
    /// Agent id (agents only).
    #[cfg_attr(feature = "clap", arg(long))]
    pub agent: Option<u32>,
    /// Pid of the launcher: the process stops when it dies.
    #[cfg_attr(feature = "clap", arg(long))]
    pub launcher_pid: Option<u32>,
    #[cfg_attr(feature = "clap", command(flatten))]
    pub placement: Placement,
    /// Lockstep runs: the agents measure tick k no sooner than t_k / FACTOR s of wall time
    /// after the start (`run --pace`, for watching; the run's numbers are the same).
    #[cfg_attr(feature = "clap", arg(long, value_name = "FACTOR"))]
    pub pace: Option<f64>,
}

impl ProcessArgs {
    /// The command line that parses back into `self`: what the launcher passes to a child.
    /// Checked against the parser by `process_args_round_trip_through_the_command_line`.
    pub fn to_args(&self) -> Vec<std::ffi::OsString> {
        let mut out: Vec<std::ffi::OsString> = vec![
            "--prefix".into(),
            self.prefix.clone().into(),
            "--scenario".into(),
            self.scenario.clone().into(),
            "--trace".into(),
            self.trace.clone().into(),
        ];
        if let Some(id) = self.agent {
            out.extend(["--agent".into(), id.to_string().into()]);
        }
        if let Some(pid) = self.launcher_pid {
            out.extend(["--launcher-pid".into(), pid.to_string().into()]);
        }
        if let Some(priority) = self.placement.rt_priority {
            out.extend(["--rt-priority".into(), priority.to_string().into()]);
        }
        if let Some(cpus) = &self.placement.cpus {
            out.extend(["--cpus".into(), cpus.to_string().into()]);
        }
        if let Some(pace) = self.pace {
            // Rust's shortest form that reads back to the same number.
            out.extend(["--pace".into(), pace.to_string().into()]);
        }
        out
    }
}

// The parser is the programs' (the `clap` feature, on in the workspace's test build).
#[cfg(all(test, feature = "clap"))]
mod args_tests {
    use super::ProcessArgs;
    use crate::process::{CpuList, Placement};
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Child {
        #[command(flatten)]
        args: ProcessArgs,
    }

    #[test]
    fn process_args_round_trip_through_the_command_line() {
        let base = ProcessArgs {
            prefix: "fdi12_ab_".into(),
            scenario: "run dir/scenario.toml".into(),
            trace: "run dir/traces/agent-3.trace".into(),
            agent: None,
            launcher_pid: None,
            placement: Placement::default(),
            pace: None,
        };
        let full = ProcessArgs {
            agent: Some(3),
            launcher_pid: Some(4242),
            placement: Placement {
                rt_priority: Some(20),
                cpus: Some("0,2-3".parse::<CpuList>().expect("list")),
            },
            pace: Some(0.1),
            ..base.clone()
        };
        for args in [base, full] {
            let mut line = vec![std::ffi::OsString::from("fdi-agent")];
            line.extend(args.to_args());
            let parsed = Child::try_parse_from(line).expect("parses").args;
            assert_eq!(parsed, args);
        }
    }
}
