//! Which streams go out of and into each host of a split run, from where each process runs.

use std::collections::{BTreeMap, BTreeSet};

use fdi_runtime::ipc::{Stream, Wake};

/// Where the processes of a split run are: which host each process's wake-up event (its
/// identity in the run) belongs to. [`Wake::Launcher`] is on the coordinating host.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Layout {
    pub host_of: BTreeMap<Wake, String>,
    /// The agents whose torques the run attacks: the attacker publishes theirs on
    /// `fdi/torque/<id>`, the control center everyone else's.
    pub attacked_torques: BTreeSet<u32>,
}

impl Layout {
    /// The layout `host_of` of the run `resolved`.
    pub fn new(host_of: BTreeMap<Wake, String>, resolved: &fdi_common::scenario::Resolved) -> Self {
        let attacked_torques = resolved
            .scenario
            .agents
            .iter()
            .map(|a| a.id)
            .filter(|&id| resolved.attack.attacks_torque_of(id))
            .collect();
        Self {
            host_of,
            attacked_torques,
        }
    }
}

/// What the bridge of one host carries.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct HostPlan {
    /// Streams published on this host for processes elsewhere.
    pub outbound: Vec<Stream>,
    /// The wake-up events of those processes: the bridge listens on them in their place.
    pub remote_wakes: Vec<Wake>,
    /// Streams published elsewhere for processes here.
    pub inbound: Vec<Inbound>,
}

/// A stream that comes into a host.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Inbound {
    pub stream: Stream,
    /// The local wake-up events rung after each arrival.
    pub ring: Vec<Wake>,
    /// The hosts that send it: a frame on its key from any other is refused.
    pub from: Vec<String>,
}

impl HostPlan {
    pub fn is_empty(&self) -> bool {
        self.outbound.is_empty() && self.inbound.is_empty()
    }
}

/// The streams of a run whose processes are `procs` and whose attacker forges the torques of
/// `attacked_torques`: (stream, publishers, consumers).
pub fn streams(
    procs: &[Wake],
    attacked_torques: &BTreeSet<u32>,
) -> Vec<(Stream, Vec<Wake>, Vec<Wake>)> {
    let has = |w: Wake| procs.contains(&w);
    let only = |ws: &[Wake]| ws.iter().copied().filter(|w| has(*w)).collect::<Vec<_>>();
    let agents: Vec<u32> = procs
        .iter()
        .filter_map(|w| match w {
            Wake::Agent(id) => Some(*id),
            _ => None,
        })
        .collect();
    let agent_wakes: Vec<Wake> = agents.iter().map(|&id| Wake::Agent(id)).collect();
    let processes: Vec<Wake> = procs
        .iter()
        .copied()
        .filter(|w| *w != Wake::Launcher)
        .collect();
    let mut out = vec![
        (
            Stream::Measurement,
            agent_wakes.clone(),
            only(&[Wake::Attacker]),
        ),
        (
            Stream::Tampered,
            only(&[Wake::Attacker]),
            only(&[Wake::Center, Wake::Monitor]),
        ),
        (
            Stream::Actuation,
            only(&[Wake::Center]),
            only(&[Wake::Attacker]),
        ),
        (Stream::Control, only(&[Wake::Launcher]), processes.clone()),
        (Stream::Status, processes, only(&[Wake::Launcher])),
        (
            Stream::ExternalIn,
            only(&[Wake::Attacker]),
            only(&[Wake::ExternalAttacker]),
        ),
        (
            Stream::ExternalOut,
            only(&[Wake::ExternalAttacker]),
            only(&[Wake::Attacker]),
        ),
        (Stream::Alarm, only(&[Wake::Monitor]), only(&[Wake::Center])),
        (
            Stream::ControllerIn,
            only(&[Wake::Center]),
            only(&[Wake::ExternalController]),
        ),
        (
            Stream::ControllerOut,
            only(&[Wake::ExternalController]),
            only(&[Wake::Center]),
        ),
    ];
    for &id in &agents {
        // The control center publishes an agent's torques, or, when the run attacks them, the
        // attacker does (the center then sends them on `fdi/actuation`).
        let publisher = if attacked_torques.contains(&id) {
            Wake::Attacker
        } else {
            Wake::Center
        };
        out.push((
            Stream::Torque(id),
            only(&[publisher]),
            only(&[Wake::Agent(id), Wake::Monitor]),
        ));
    }
    out.retain(|(_, p, c)| !p.is_empty() && !c.is_empty());
    out
}

/// What the bridge of host `here` carries in the run laid out as `layout`. Errors when a
/// stream would have to go both out of and into one host (a loop the bridges could not break).
pub fn plan(layout: &Layout, here: &str) -> Result<HostPlan, String> {
    let procs: Vec<Wake> = layout.host_of.keys().copied().collect();
    let on = |w: &Wake, host: &str| layout.host_of.get(w).is_some_and(|h| h == host);
    let mut plan = HostPlan::default();
    let mut remote: BTreeSet<Wake> = BTreeSet::new();
    for (stream, pubs, cons) in streams(&procs, &layout.attacked_torques) {
        let out = pubs.iter().any(|p| on(p, here)) && cons.iter().any(|c| !on(c, here));
        let inb = cons.iter().any(|c| on(c, here)) && pubs.iter().any(|p| !on(p, here));
        if out && inb {
            return Err(format!(
                "`{}` would go both out of and into host `{here}`: its publishers and its \
                 receivers are each split over hosts",
                stream.service_name()
            ));
        }
        if out {
            plan.outbound.push(stream);
            remote.extend(cons.iter().copied().filter(|c| !on(c, here)));
        }
        if inb {
            let ring: Vec<Wake> = cons.iter().copied().filter(|c| on(c, here)).collect();
            let from: BTreeSet<String> = pubs
                .iter()
                .filter_map(|p| layout.host_of.get(p))
                .filter(|h| *h != here)
                .cloned()
                .collect();
            plan.inbound.push(Inbound {
                stream,
                ring,
                from: from.into_iter().collect(),
            });
        }
    }
    plan.remote_wakes = remote.into_iter().collect();
    Ok(plan)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) fn layout(entries: &[(Wake, &str)]) -> Layout {
        Layout {
            host_of: entries.iter().map(|(w, h)| (*w, h.to_string())).collect(),
            attacked_torques: BTreeSet::new(),
        }
    }

    fn split() -> Layout {
        layout(&[
            (Wake::Launcher, "control"),
            (Wake::Center, "control"),
            (Wake::Attacker, "control"),
            (Wake::Agent(1), "cell-a"),
            (Wake::Agent(2), "cell-a"),
            (Wake::Agent(3), "cell-b"),
            (Wake::Agent(4), "control"),
        ])
    }

    #[test]
    fn every_stream_between_hosts_goes_out_of_its_publishers_host_into_its_receivers() {
        let l = split();
        let hosts = ["control", "cell-a", "cell-b"];
        let plans: BTreeMap<&str, HostPlan> = hosts
            .iter()
            .map(|h| (*h, plan(&l, h).expect("plan")))
            .collect();
        let procs: Vec<Wake> = l.host_of.keys().copied().collect();
        for (stream, pubs, cons) in streams(&procs, &l.attacked_torques) {
            for p in &pubs {
                for c in &cons {
                    let (hp, hc) = (&l.host_of[p], &l.host_of[c]);
                    if hp == hc {
                        continue;
                    }
                    assert!(
                        plans[hp.as_str()].outbound.contains(&stream),
                        "{stream:?} out of {hp}"
                    );
                    assert!(
                        plans[hp.as_str()].remote_wakes.contains(c),
                        "{c:?} listened on {hp}"
                    );
                    let inbound = &plans[hc.as_str()].inbound;
                    assert!(
                        inbound.iter().any(|i| i.stream == stream
                            && i.ring.contains(c)
                            && i.from.contains(hp)),
                        "{stream:?} into {hc} rings {c:?}, from {hp}"
                    );
                }
            }
        }
        // Nothing crosses where nothing needs to.
        let cell_b = &plans["cell-b"];
        assert!(!cell_b.inbound.iter().any(|i| i.stream == Stream::Torque(1)));
        assert!(!plans["control"].outbound.contains(&Stream::Torque(4)));
        assert_eq!(cell_b.remote_wakes, vec![Wake::Attacker, Wake::Launcher]);
    }

    #[test]
    fn a_run_on_one_host_carries_nothing() {
        let l = layout(&[
            (Wake::Launcher, "h"),
            (Wake::Center, "h"),
            (Wake::Attacker, "h"),
            (Wake::Agent(1), "h"),
        ]);
        assert!(plan(&l, "h").expect("plan").is_empty());
    }

    #[test]
    fn an_attacker_on_a_host_of_its_own_gets_the_measurements_and_the_actuation() {
        let mut l = split();
        l.host_of.insert(Wake::Attacker, "adversary".into());
        let p = plan(&l, "adversary").expect("plan");
        let inbound: Vec<Stream> = p.inbound.iter().map(|i| i.stream).collect();
        assert!(inbound.contains(&Stream::Measurement));
        assert!(inbound.contains(&Stream::Actuation));
        assert!(inbound.contains(&Stream::Control));
        assert_eq!(p.outbound, vec![Stream::Tampered, Stream::Status]);
        // When the run attacks agent 3's torques, the attacker forges them and sends them to
        // its host; the center no longer does.
        l.attacked_torques.insert(3);
        let p = plan(&l, "adversary").expect("plan");
        assert_eq!(
            p.outbound,
            vec![Stream::Tampered, Stream::Status, Stream::Torque(3)]
        );
        assert!(!plan(&l, "control")
            .expect("plan")
            .outbound
            .contains(&Stream::Torque(3)));
        let cell_b = plan(&l, "cell-b").expect("plan");
        assert!(cell_b.inbound.iter().any(|i| i.stream == Stream::Torque(3)
            && i.ring == [Wake::Agent(3)]
            && i.from == ["adversary"]));
    }
}
