//! `fdi-launch bench latency|lockstep|transport`: the measurements of
//! `fdi_tables::bench`, printed as markdown (or JSON with `--json`).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::{Args, Subcommand};
use fdi_common::stop::Stop;
use fdi_orchestrator::run::runtime::Placement;
use fdi_tables::bench::floor::{self, PeerKind, PeerRole, PeerSpec};
use fdi_tables::bench::{
    self, LatencyOptions, LatencyReport, Lockstep, LockstepOptions, TransportOptions,
    TransportReport,
};

#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Per-hop latency, control-center compute time, end-to-end sensor → actuation latency,
    /// deadline misses and control-period jitter of a realtime run.
    Latency(LatencyArgs),
    /// Lockstep speed over IPC against the in-process engine, same scenario, same invocation.
    Lockstep(LockstepArgs),
    /// The transport floor (iceoryx2 ping-pong, a 3-hop chain, a Unix-socket ping-pong) with the
    /// runtime's wait strategy, and the runtime's per-hop latency as a ratio to it.
    Transport(TransportArgs),
}

#[derive(Debug, Args)]
pub struct TransportArgs {
    /// Round trips per transport.
    #[arg(long, default_value_t = 20_000, allow_negative_numbers = true)]
    pub iterations: u64,
    /// Spin before blocking, µs. Default 0: the realtime runtime's event-driven strategy, which
    /// the runtime's latency is measured with.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    pub spin_us: u64,
    /// Agents and seconds of the realtime run measured beside the floor.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    pub agents: usize,
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
    pub duration_s: f64,
    #[arg(long)]
    pub json: bool,
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
}

#[derive(Debug, Args)]
pub struct LatencyArgs {
    /// Number of agents (the paper's four robots, repeated).
    #[arg(long, default_value_t = 4, allow_negative_numbers = true)]
    pub agents: usize,
    /// Simulated (= wall-clock) duration, s.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    pub duration_s: f64,
    /// Control rate, Hz.
    #[arg(long, default_value_t = 1000.0, allow_negative_numbers = true)]
    pub rate_hz: f64,
    #[arg(long)]
    pub json: bool,
    /// Folder that receives the run directory.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Placement of the run's processes (and of the timer probe beside them).
    #[command(flatten)]
    pub placement: Placement,
    /// Split the measured run over hosts (a deployment file, docs/multi-host.md): the hops
    /// between hosts include the network, the stamps are moved to the coordinator's clock by
    /// the offset measured at the start, and end-to-end is one clock's (the agent's).
    #[arg(long, value_name = "FILE")]
    pub hosts: Option<PathBuf>,
    /// Serve the measured run live (as `run --live`), to measure what a viewer costs.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, require_equals = true, default_missing_value = fdi_live::Options::DEFAULT_ADDR)]
    pub live: Option<std::net::SocketAddr>,
    /// Start the measured run once a viewer subscribed (as `run --live-wait`), at most SECONDS.
    #[arg(long, value_name = "SECONDS", requires = "live")]
    pub live_wait: Option<f64>,
}

#[derive(Debug, Args)]
pub struct LockstepArgs {
    /// Agent counts to measure (repeat the flag or separate with commas).
    #[arg(long, value_delimiter = ',', default_values_t = vec![1usize, 4, 16, 64])]
    pub agents: Vec<usize>,
    /// Simulated duration of each run, s (the paper's experiment is 40 s).
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
    pub duration_s: f64,
    #[arg(long)]
    pub json: bool,
    /// Keep the traces of the measured runs (by default only their summaries stay).
    #[arg(long)]
    pub keep_traces: bool,
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Attack of the runs instead of the paper's: a preset name or a profile file for the
    /// paper's four robots (every copy of a robot gets its attack), e.g. `actuator-bias`, whose
    /// torques go through the attacker (the extra hop).
    #[arg(long)]
    pub attack: Option<String>,
}

/// `bench …`.
pub fn bench(command: &BenchCommand, stop: &Stop) -> Result<ExitCode> {
    match command {
        BenchCommand::Latency(a) => latency(a, stop),
        BenchCommand::Lockstep(a) => lockstep(a, stop),
        BenchCommand::Transport(a) => transport(a, stop),
    }?;
    Ok(ExitCode::SUCCESS)
}

fn latency(a: &LatencyArgs, stop: &Stop) -> Result<()> {
    let report = bench::latency(
        &LatencyOptions {
            agents: a.agents,
            duration_s: a.duration_s,
            rate_hz: a.rate_hz,
            out: a.out.clone(),
            placement: a.placement.clone(),
            hosts: a.hosts.as_deref().map(fdi_split::hosts_file),
            live: a.live,
            live_wait: a.live_wait,
            progress: crate::terminal::progress(!a.json),
        },
        stop,
    )?;
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_latency(&report);
    }
    Ok(())
}

fn print_latency(r: &LatencyReport) {
    println!(
        "Realtime latency: {} agents at {} Hz for {} s ({} ticks), {}",
        r.agents, r.rate_hz, r.duration_s, r.ticks, r.scheduling
    );
    println!();
    println!("| µs | p50 | p90 | p99 | p99.9 | max |");
    println!("|---|---|---|---|---|---|");
    for (name, p) in bench::latency_rows(r) {
        println!(
            "| {name} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |",
            p.p50, p.p90, p.p99, p.p999, p.max
        );
    }
    println!();
    println!(
        "deadline misses {} of {} agent-ticks ({:.4} %), lost ticks {}",
        r.deadline_misses,
        r.ticks * r.agents as u64,
        100.0 * r.deadline_miss_ratio,
        r.lost_ticks
    );
    println!(
        "machine stalls: timer threads beside the run (one per CPU) woke >= 1 ms late {} \
         times; {} of the deadline misses fall in a stall of >= 0.5 ms (as do {:.2} % of all steps)",
        r.timer_probe_stalls_over_1ms,
        r.deadline_misses_in_machine_stalls,
        100.0 * r.steps_in_machine_stalls_ratio
    );
    println!("run directory {}", r.run_dir);
}

fn transport(a: &TransportArgs, stop: &Stop) -> Result<()> {
    let report = bench::transport(
        &TransportOptions {
            iterations: a.iterations,
            spin_us: a.spin_us,
            agents: a.agents,
            duration_s: a.duration_s,
            out: a.out.clone(),
        },
        stop,
    )?;
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_transport(a, &report);
    }
    Ok(())
}

fn print_transport(a: &TransportArgs, report: &TransportReport) {
    println!("{}", report.floor.to_markdown());
    let p = &report.paced_chain.per_hop;
    println!(
        "iceoryx2 3-hop chain at the runtime's rate (one round trip per 1 ms, {} round trips): per hop p50 {:.1}, p90 {:.1}, p99 {:.1}, p99.9 {:.1}, max {:.1} µs",
        report.paced_round_trips, p.p50_us, p.p90_us, p.p99_us, p.p999_us, p.max_us
    );
    println!();
    let base = report.floor.ipc_chain.per_hop.p50_us;
    let paced = p.p50_us;
    println!("Runtime (realtime, {} agent(s), {} s) per-hop p50 against the 3-hop chain's per-hop p50, back to back ({base:.1} µs) and at the runtime's rate ({paced:.1} µs):", a.agents, a.duration_s);
    println!();
    println!("| hop | runtime p50 (µs) | ratio to back-to-back floor | ratio to paced floor |");
    println!("|---|---|---|---|");
    for (i, name) in [
        "agent -> attacker",
        "attacker -> control center",
        "control center -> agent",
    ]
    .iter()
    .enumerate()
    {
        println!(
            "| {name} | {:.1} | {:.2} | {:.2} |",
            report.runtime_hops_p50_us[i],
            report.runtime_over_floor[i],
            report.runtime_over_paced_floor[i]
        );
    }
}

fn lockstep(a: &LockstepArgs, stop: &Stop) -> Result<()> {
    let measured = bench::lockstep(
        &LockstepOptions {
            agents: a.agents.clone(),
            duration_s: a.duration_s,
            keep_traces: a.keep_traces,
            out: a.out.clone(),
            attack: a.attack.clone(),
            progress: crate::terminal::progress(!a.json),
        },
        stop,
    )?;
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "duration_s": a.duration_s, "rows": measured.rows, "dir": measured.dir.display().to_string() })
        );
    } else {
        print_lockstep(a.duration_s, &measured);
    }
    Ok(())
}

/// The lockstep table, as markdown.
fn print_lockstep(duration_s: f64, measured: &Lockstep) {
    println!(
        "Lockstep speed, {} s simulated per run (both engines write their traces)",
        duration_s
    );
    println!();
    println!("| agents | processes | in-process wall (s) | IPC wall (s) | IPC / in-process | IPC × real time | IPC ticks/s | bit-identical |");
    println!("|---|---|---|---|---|---|---|---|");
    for r in &measured.rows {
        println!(
            "| {} | {} | {:.3} | {:.3} | {:.2} | {:.1} | {:.0} | {} |",
            r.agents,
            r.processes,
            r.inproc_wall_s,
            r.ipc_wall_s,
            r.ipc_over_inproc,
            r.ipc_realtime_factor,
            r.ipc_ticks_per_s,
            r.bit_identical
        );
    }
    println!();
    println!("results in {}", measured.dir.display());
}

/// The arguments of the hidden `bench-peer` (a peer process of `bench transport`, started by
/// `fdi_tables::bench::floor` with [`PeerSpec::to_args`]).
#[derive(Debug, clap::Parser)]
#[command(name = "bench-peer", no_binary_name = true)]
struct PeerArgs {
    #[arg(value_parser = super::values::one_of(PeerKind::ALL, PeerKind::name, |_| None))]
    kind: PeerKind,
    #[arg(value_parser = super::values::one_of(PeerRole::ALL, PeerRole::name, |_| None))]
    role: PeerRole,
    /// iceoryx2 run prefix (ipc kinds).
    #[arg(long)]
    prefix: Option<String>,
    /// Folder of the sockets (uds-pair).
    #[arg(long)]
    dir: Option<PathBuf>,
    /// Spin budget of the wait strategy, µs.
    #[arg(long, default_value_t = fdi_runtime::process::DEFAULT_SPIN_US)]
    spin_us: u64,
    /// Stop when this process is no longer the parent.
    #[arg(long)]
    parent_pid: Option<u32>,
}

impl PeerArgs {
    fn spec(self) -> PeerSpec {
        PeerSpec {
            kind: self.kind,
            role: self.role,
            prefix: self.prefix,
            dir: self.dir,
            spin_us: self.spin_us,
            parent_pid: self.parent_pid,
        }
    }
}

/// `bench-peer ARGS…`.
pub fn peer(args: &[String]) -> Result<ExitCode> {
    use clap::Parser as _;
    let a = PeerArgs::try_parse_from(args).map_err(|e| anyhow::anyhow!("bench-peer: {e}"))?;
    floor::peer_main(&a.spec())?;
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser as _;

    /// What the floor starts a peer with parses back into what it meant, for every kind and
    /// role; the default spin is the runtime's, an unknown kind is refused.
    #[test]
    fn a_peer_s_arguments_parse_back_into_its_spec() {
        for kind in PeerKind::ALL {
            for role in PeerRole::ALL {
                let spec = PeerSpec {
                    kind,
                    role,
                    prefix: Some("fdi1_fl0_".into()),
                    dir: Some("/tmp/x".into()),
                    spin_us: 7,
                    parent_pid: Some(42),
                };
                let back = PeerArgs::try_parse_from(spec.to_args()).expect("parses");
                assert_eq!(back.spec(), spec);
            }
        }
        let d = PeerArgs::try_parse_from(["uds-pair", "pong", "--dir", "/tmp/x"]).expect("parses");
        assert_eq!(d.spin_us, fdi_runtime::process::DEFAULT_SPIN_US);
        assert!(PeerArgs::try_parse_from(["tcp", "pong"]).is_err());
    }
}
