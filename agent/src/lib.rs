//! The agent process: a thin shell around [`fdi_common::plant::Plant`], one [`Role`] of the
//! run (its lifecycle and process shell: [`fdi_runtime::role`]).
//!
//! Lockstep: publish measurement `k`, integrate `[t_k, t_{k+1}]` as soon as every command that
//! step looks up has arrived (with `τ > Δ` that is before torque `k` itself: lookahead), publish
//! `k + 1`, and so on. Realtime: at wall time `epoch + t_k` integrate `[t_{k−1}, t_k]` with
//! whatever commands have arrived (a command due but missing is a deadline miss: the last one is
//! held), then publish measurement `k`.

use std::time::Duration;

use fdi_common::engine::{agent_record, tick_time};
use fdi_common::model::Vector;
use fdi_common::plant::{Measurement, Plant};
use fdi_common::run_dir::Process;
use fdi_common::scenario::{AgentConfig, ClockMode, Resolved};
use fdi_common::trace::{HopStamps, TraceRecord, TraceWriter};
use fdi_runtime::ipc::msg::from_vector;
use fdi_runtime::ipc::{
    self, monotonic_ns, Bell as _, Inbox as _, MeasurementMsg, Outbox as _, StatusMsg, Stream,
    TorqueMsg, Transport, Wake, Waker as _,
};
use fdi_runtime::process::{
    self, Connection, ProcessArgs, WaitStrategy, PROGRESS_EVERY, WAIT_SLICE,
};
use fdi_runtime::role::{self, End, Opened, Role, Turn};

/// Errors of the agent process.
pub type AgentError = fdi_runtime::process::RoleError;

/// Agent `id` of a run; `pace`: a lockstep run slowed for watching (`run --pace`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Agent {
    pub id: u32,
    pub pace: Option<f64>,
}

impl Agent {
    /// This agent's entry in the scenario.
    fn config<'r>(&self, resolved: &'r Resolved) -> Result<&'r AgentConfig, AgentError> {
        (resolved.scenario.agents.iter())
            .find(|a| a.id == self.id)
            .ok_or(AgentError::NotInScenario(self.id))
    }
}

/// The agent's ports.
#[derive(Debug)]
pub struct Ports<X: Transport> {
    pub measurement: X::Outbox<MeasurementMsg>,
    pub torque: X::Inbox<TorqueMsg>,
    pub attacker: X::Bell,
}

impl Role for Agent {
    type Ports<X: Transport> = Ports<X>;
    type Running<'a, X: Transport + 'a> = role::Boxed<'a>;

    fn identity(&self) -> (ipc::Role, Wake) {
        (ipc::Role::Agent, Wake::Agent(self.id))
    }

    fn program(&self) -> String {
        format!("fdi-agent {}", self.id)
    }

    fn trace_name(&self) -> Option<String> {
        Some(Process::Agent(self.id).to_string())
    }

    fn open<X: Transport>(&self, transport: &X, _: &Resolved) -> Result<Ports<X>, AgentError> {
        Ok(Ports {
            measurement: transport.publisher(Stream::Measurement)?,
            torque: transport.subscriber(Stream::Torque(self.id))?,
            attacker: transport.notifier(Wake::Attacker)?,
        })
    }

    /// Its robot's state, with the robot's number of links.
    fn prepare<'a, X: Transport + 'a>(
        &'a self,
        resolved: &'a Resolved,
        opened: &'a Opened<X, Ports<X>>,
    ) -> Result<role::Boxed<'a>, AgentError> {
        let dof = self.config(resolved)?.model.dof();
        fdi_common::with_joint_count!(dof, N => self.running::<X, N>(resolved, opened).map(role::Boxed::new))
            .ok_or(AgentError::Dof(self.id))?
    }
}

impl Agent {
    /// Its state over a run whose robot has `N` links.
    fn running<'a, X: Transport + 'a, const N: usize>(
        &'a self,
        resolved: &'a Resolved,
        opened: &'a Opened<X, Ports<X>>,
    ) -> Result<Running<'a, X, N>, AgentError> {
        let s = &resolved.scenario;
        let agent = self.config(resolved)?;
        let plant = Plant::<N>::new(s.plant_params(agent)).ok_or(AgentError::Dof(self.id))?;
        let ticks = resolved.ticks();
        Ok(Running {
            ports: &opened.ports,
            conn: &opened.conn,
            plant,
            inflow: Inflow {
                next: 0,
                refused: 0,
                ticks,
                dt: s.control_period_s,
                clock: s.clock,
            },
            pace: self.pace,
            duration_s: s.duration_s,
            epoch_ns: 0,
            k: 0,
            published: None,
            unrung: false,
            strategy: WaitStrategy::for_clock(s.clock),
            due_ns: None,
        })
    }
}

/// State of the torque stream.
#[derive(Debug)]
struct Inflow {
    /// Sequence number of the next torque due.
    next: u64,
    refused: u64,
    /// The run's tick count: no torque is numbered beyond.
    ticks: u64,
    dt: f64,
    clock: ClockMode,
}

/// A tick measured and published but not yet integrated.
#[derive(Debug, Clone, Copy)]
struct Published<const N: usize> {
    k: u64,
    state: (Vector<N>, Vector<N>),
    measurement: Measurement<N>,
}

/// An agent over a run.
#[derive(Debug)]
pub struct Running<'a, X: Transport, const N: usize> {
    ports: &'a Ports<X>,
    conn: &'a Connection<X>,
    plant: Plant<N>,
    inflow: Inflow,
    /// Lockstep runs slowed for watching: tick k is measured no sooner than `t_k / pace` s
    /// after the start.
    pace: Option<f64>,
    duration_s: f64,
    epoch_ns: u64,
    /// Lockstep: the next tick to integrate. Realtime: the tick whose deadline comes next
    /// (`[t_{k−1}, t_k]` is integrated then).
    k: u64,
    /// The tick measured and published but not yet integrated.
    published: Option<Published<N>>,
    /// Lockstep: measurements published since the attacker was last rung.
    unrung: bool,
    strategy: WaitStrategy,
    /// Lockstep: a paced tick not yet due (its wall-clock time, ns); `None`: waiting for
    /// torques.
    due_ns: Option<u64>,
}

impl<X: Transport, const N: usize> role::Running for Running<'_, X, N> {
    fn begin(&mut self, epoch_ns: u64, _: &mut TraceWriter) -> Result<(), AgentError> {
        self.epoch_ns = epoch_ns;
        if self.inflow.clock == ClockMode::Realtime {
            self.published = Some(self.publish(0, true)?);
            self.k = 1;
        }
        Ok(())
    }

    fn turn(&mut self, trace: &mut TraceWriter) -> Result<Turn, AgentError> {
        match self.inflow.clock {
            ClockMode::Lockstep => self.lockstep_turn(trace),
            ClockMode::Realtime => self.realtime_turn(trace),
        }
    }

    fn wait(&mut self) -> Result<(), AgentError> {
        let waker = &self.conn.waker;
        match (self.inflow.clock, self.due_ns) {
            (ClockMode::Lockstep, None) => {
                self.strategy.wait(waker, &self.ports.torque)?;
            }
            (ClockMode::Lockstep, Some(due)) => {
                let left = due.saturating_sub(monotonic_ns());
                std::thread::sleep(Duration::from_nanos(left).min(WAIT_SLICE));
            }
            // Wait for the deadline with a high-resolution timeout (ppoll), waking at every
            // torque arrival to stamp it: the event wait's own timeout has scheduler-tick
            // granularity (4–10 ms), far too coarse for 1 kHz.
            (ClockMode::Realtime, _) => {
                let left = self.deadline_ns().saturating_sub(monotonic_ns());
                if left > 0 {
                    waker.wait_precise(Duration::from_nanos(left).min(WAIT_SLICE))?;
                }
            }
        }
        Ok(())
    }

    fn end(self, _: &mut TraceWriter) -> Result<End, AgentError> {
        let (inflow, plant) = (&self.inflow, &self.plant);
        let note = (inflow.refused > 0 || plant.missing_commands > 0).then(|| {
            let message = format!(
                "{} torque messages refused (wrong agent, dof, sequence or stamp), {} ticks \
                 without a usable command (dropped, forged, replayed or refused by the delay \
                 line; the one before held)",
                inflow.refused, plant.missing_commands
            );
            (self.duration_s, message)
        });
        Ok(End {
            ticks: inflow.ticks,
            note,
        })
    }
}

impl<X: Transport, const N: usize> Running<'_, X, N> {
    /// Lockstep. Lookahead (conservative parallel simulation): step k runs as soon as the next
    /// command not yet received (stamp t_n) would not be in force at the step's latest query
    /// t − τ(t). The step then looks up exactly the commands it looks up in strict lockstep,
    /// so the trace is bit-identical; with τ > Δ the agent runs ticks ahead and the processes
    /// exchange batches instead of single messages.
    fn lockstep_turn(&mut self, trace: &mut TraceWriter) -> Result<Turn, AgentError> {
        self.take_torques(trace, false)?;
        let (ticks, dt) = (self.inflow.ticks, self.inflow.dt);
        while self.k < ticks {
            let k = self.k;
            let t = tick_time(k, dt);
            let p = match self.published.take() {
                Some(p) if p.k == k => p,
                _ => {
                    if let Some(due) = self.paced_due(t) {
                        // What was measured is announced before the pause.
                        self.ring_if_unrung()?;
                        self.due_ns = Some(due);
                        return Ok(Turn::Pending);
                    }
                    self.unrung = true;
                    self.publish(k, false)?
                }
            };
            if self
                .plant
                .can_advance_without(k, tick_time(self.inflow.next, dt))
            {
                self.integrate(&p, trace)?;
                self.k += 1;
                continue;
            }
            self.published = Some(p);
            self.ring_if_unrung()?;
            self.due_ns = None;
            return Ok(Turn::Pending);
        }
        // The last measurements may have gone out without a ring (the final steps needed
        // no further torque): announce them, or the attacker only sees them on a timeout.
        self.ring_if_unrung()?;
        Ok(Turn::Done)
    }

    /// Realtime, paced from the start: at tick k's deadline, `[t_{k−1}, t_k]` is integrated
    /// with the torques arrived, then measurement k is published.
    fn realtime_turn(&mut self, trace: &mut TraceWriter) -> Result<Turn, AgentError> {
        self.take_torques(trace, true)?;
        if self.k > self.inflow.ticks {
            return Ok(Turn::Done);
        }
        if monotonic_ns() < self.deadline_ns() {
            return Ok(Turn::Pending);
        }
        let (k, ticks) = (self.k, self.inflow.ticks);
        if let Some(p) = self.published.take() {
            self.integrate(&p, trace)?;
        }
        if k < ticks {
            self.published = Some(self.publish(k, true)?);
        }
        // A robot that fell behind its clock (an overloaded machine) goes on after the control
        // center is done: its reports tell the launcher it is not stalled.
        if k % PROGRESS_EVERY == 0 {
            self.conn.launcher.report(StatusMsg::PROGRESS, k)?;
        }
        self.k += 1;
        Ok(if self.k > ticks {
            Turn::Done
        } else {
            Turn::Pending
        })
    }

    /// Realtime: the wall-clock time of tick `k`.
    fn deadline_ns(&self) -> u64 {
        self.epoch_ns + (tick_time(self.k, self.inflow.dt) * 1e9) as u64
    }

    /// A paced lockstep tick at `t` s not yet due: when it is.
    fn paced_due(&self, t: f64) -> Option<u64> {
        let due = self.epoch_ns + (t / self.pace? * 1e9) as u64;
        (due > monotonic_ns()).then_some(due)
    }

    fn ring_if_unrung(&mut self) -> Result<(), AgentError> {
        if self.unrung {
            self.ports.attacker.ring()?;
            self.unrung = false;
        }
        Ok(())
    }

    /// Integrates the tick `p` measured, on record.
    fn integrate(&mut self, p: &Published<N>, trace: &mut TraceWriter) -> Result<(), AgentError> {
        let step = self.plant.advance(p.k);
        trace.write(&TraceRecord::Agent(agent_record(
            p.k,
            self.plant.agent_id(),
            tick_time(p.k, self.inflow.dt),
            (&p.state.0, &p.state.1),
            &p.measurement,
            &step,
        )))?;
        Ok(())
    }

    /// Measures and publishes tick `k` (realtime rings the attacker at every tick, `ring`;
    /// lockstep once per batch).
    fn publish(&mut self, k: u64, ring: bool) -> Result<Published<N>, AgentError> {
        let state = (self.plant.q, self.plant.qd);
        let m = self.plant.measure();
        self.ports.measurement.send(MeasurementMsg {
            seq: k,
            agent: self.plant.agent_id(),
            dof: N as u32,
            t: tick_time(k, self.inflow.dt),
            y: from_vector(&m.y),
            yd: from_vector(&m.yd),
            agent_sent_ns: monotonic_ns(),
            attacker_received_ns: 0,
            attacker_sent_ns: 0,
            flags: 0,
            reserved: 0,
        })?;
        if ring {
            self.ports.attacker.ring()?;
        }
        Ok(Published {
            k,
            state,
            measurement: m,
        })
    }

    /// Takes every waiting torque into the plant's delay line, in order; a torque for a tick
    /// already passed (duplicate, replay) or malformed is refused and counted; one that stands
    /// for its tick without a usable command (gap marker, forged stamp) leaves the tick's
    /// command missing ([`Plant::take_command`]). With `stamps`, the per-hop latency of every
    /// torque is recorded (realtime: in lockstep latencies say nothing).
    fn take_torques(&mut self, trace: &mut TraceWriter, stamps: bool) -> Result<(), AgentError> {
        let (plant, inflow) = (&mut self.plant, &mut self.inflow);
        let id = plant.agent_id();
        let mut err = None;
        self.ports.torque.drain(|m| {
            let received = monotonic_ns();
            let admitted = process::admit_torque::<N>(
                &m,
                id,
                inflow.next,
                (inflow.ticks, inflow.dt),
                inflow.clock,
            );
            let Ok(command) = admitted else {
                inflow.refused += 1;
                return;
            };
            // A refused value or stamp is counted by the plant, as a missing command.
            let _ = plant.take_command(command.stamp, command.torque);
            inflow.next = m.seq + 1;
            if !stamps || command.torque.is_none() {
                return;
            }
            let stamps = HopStamps {
                agent_sent_ns: m.agent_sent_ns,
                attacker_received_ns: m.attacker_received_ns,
                attacker_sent_ns: m.attacker_sent_ns,
                center_received_ns: m.center_received_ns,
                center_sent_ns: m.center_sent_ns,
                agent_received_ns: received,
            };
            if let Err(e) = trace.write(&TraceRecord::Latency {
                k: m.seq,
                agent: id,
                stamps,
            }) {
                err = Some(e);
            }
        })?;
        err.map_or(Ok(()), |e| Err(e.into()))
    }
}

/// The process of the `fdi-agent` binary (and of `fdi-launch process agent`).
pub fn run_process(args: ProcessArgs) -> Result<role::Ended, role::Failed> {
    match args.agent {
        Some(id) => role::run_process(
            &Agent {
                id,
                pace: args.pace,
            },
            &args,
        ),
        None => {
            process::print_failure(format_args!("fdi-agent ?: {}", AgentError::MissingId));
            Err(role::Failed)
        }
    }
}
