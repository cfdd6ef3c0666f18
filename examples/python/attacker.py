"""An attacker program for a scenario's [roles.attacker]: a bias and a replay on the measurements.

    --bias AGENT:SIGNAL:LINK:VALUE:FROM_S:TO_S
        adds VALUE (rad for SIGNAL=position, rad/s for velocity) to link LINK (1-based) of
        AGENT's measurements for FROM_S <= t_k < TO_S (t_k = k Δ).
    --replay AGENT:FROM_S:RECORD_FROM_S:RECORD_FOR_S[:TO_S]
        records AGENT's clean position and velocity (every link) over
        [RECORD_FROM_S, RECORD_FROM_S + RECORD_FOR_S) and plays the recording back in a loop in
        their place from FROM_S (until TO_S, or to the end of the run).

Both may be repeated; attacks on the same signal and link add up, in the order given. The
values the control center gets are bit for bit those of the run's own attacker under the
equivalent attack profile (bias-replay.toml for the README example): each option is a
channel of that profile (a bias: a `constant` segment from FROM_S and a `none` segment from
TO_S; a replay: a position and a velocity channel with a `replay` segment), evaluated operation
by operation as common/src/attack/mod.rs does.
"""

import argparse
import bisect
import math
import sys

import fdi_protocol as fdi


def round_half_away(x):
    """Rust's f64::round: halves away from zero (Python's round() rounds them to even)."""
    r = math.floor(abs(x))
    if abs(x) - r >= 0.5:
        r += 1.0
    return math.copysign(r, x)


class LinkChannel:
    """One signal of one link of one agent: segments (from_s, kind, params), each in force
    from its from_s until the next one begins (before the first one: nothing)."""

    def __init__(self, signal, link, segments):
        self.signal, self.link = signal, link - 1
        self.segments = sorted(segments, key=lambda s: s[0])
        self.starts = [s[0] for s in self.segments]
        self.recordings = [([], []) for _ in self.segments]  # (times, values) of a replay
        self.clean = 0.0

    def observe(self, t, v):
        self.clean = v
        for (_, kind, p), (times, values) in zip(self.segments, self.recordings):
            if kind == "replay" and p[0] <= t < p[0] + p[1]:
                times.append(t)
                values.append(v)

    def injection(self, t):
        i = bisect.bisect_right(self.starts, t) - 1
        if i < 0:
            return None
        from_s, kind, p = self.segments[i]
        if kind == "constant":
            return 1.0 * p[0]  # the units' factor, 1 for rad and rad/s
        if kind == "replay":
            times, values = self.recordings[i]
            if not values:
                return 0.0
            return self.played(times, values, t - from_s) - self.clean
        return 0.0  # "none"

    @staticmethod
    def played(times, values, elapsed):
        n = len(values)
        spacing = 0.0 if n < 2 else (times[-1] - times[0]) / (n - 1)
        if n == 1 or math.isnan(spacing) or spacing <= 0.0 or not math.isfinite(elapsed) \
                or elapsed <= 0.0:
            return values[0]
        return values[int(math.fmod(round_half_away(elapsed / spacing), float(n)))]


def tamper(channels, t, y, yd):
    """y + α and yd + α of one measurement (lists of dof floats) at time t: every channel
    observes its clean value first, then the injections are summed from 0.0 in channel order
    and added to every entry (α = 0.0 where nothing is injected), as the Rust attacker does."""
    for ch in channels:
        ch.observe(t, (y if ch.signal == "position" else yd)[ch.link])
    ay, ayd = [0.0] * len(y), [0.0] * len(yd)
    for ch in channels:
        v = ch.injection(t)
        if v is not None:
            (ay if ch.signal == "position" else ayd)[ch.link] += v
    return [a + b for a, b in zip(y, ay)], [a + b for a, b in zip(yd, ayd)]


def options():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    # One list for both options, so that their order is kept.
    ap.add_argument("--bias", action="append", default=[], dest="attacks",
                    type=lambda s: ("bias", s), metavar="AGENT:SIGNAL:LINK:VALUE:FROM_S:TO_S")
    ap.add_argument("--replay", action="append", default=[], dest="attacks",
                    type=lambda s: ("replay", s),
                    metavar="AGENT:FROM_S:RECORD_FROM_S:RECORD_FOR_S[:TO_S]")
    return ap


def need(condition):
    if not condition:
        raise ValueError()


def channels_of(ap, attacks, dof):
    """The channels of the options, per agent, in the order given."""
    channels = {}
    for kind, spec in attacks:
        f = spec.split(":")
        try:
            agent = int(f[0])
            if kind == "bias":
                signal, link = f[1], int(f[2])
                value, start, end = map(float, f[3:])
                need(signal in ("position", "velocity") and 1 <= link <= dof and 0 <= start < end)
                segments = [(start, "constant", (value,)), (end, "none", ())]
                links = [(signal, link)]
            else:
                start, rec_from, rec_for, *end = map(float, f[1:])
                need(0 <= rec_from and 0 < rec_for and rec_from + rec_for <= start)
                need(len(end) <= 1 and all(e > start for e in end))
                segments = [(start, "replay", (rec_from, rec_for))]
                segments += [(e, "none", ()) for e in end]
                links = [(s, l) for s in ("position", "velocity") for l in range(1, dof + 1)]
        except (ValueError, IndexError):
            ap.error(f"--{kind} {spec}: see --help (links 1..{dof}; times: 0 <= FROM_S < TO_S, "
                     "a replay starts at or after the end of its recording)")
        for signal, link in links:
            channels.setdefault(agent, []).append(LinkChannel(signal, link, segments))
    return channels


def main():
    ap = options()
    attacks = ap.parse_args().attacks
    with fdi.Run("attacker") as run:
        env = run.env
        channels = channels_of(ap, attacks, env.dof)
        if set(channels) - set(env.agents):
            ap.error(f"agents {sorted(set(channels) - set(env.agents))} are not in the run "
                     f"(FDI_AGENTS={','.join(map(str, env.agents))})")
        inbox = run.subscriber("fdi/external/attacker/in", fdi.MeasurementMsg)
        outbox = run.publisher("fdi/external/attacker/out", fdi.MeasurementMsg)
        relay = run.notifier("fdi/wake/attacker")  # the run's attacker relays our answers
        run.ready_and_wait_for_start()
        left = {a: env.ticks for a in env.agents}  # ticks still to answer, per agent
        while any(left.values()):
            batch = run.drain(inbox)
            if not batch:
                run.wait()
                continue
            for m in batch:  # every clean measurement, in tick order per agent
                if m.agent not in left:
                    continue
                if not m.flags & fdi.GAP:
                    n = m.dof
                    t = env.tick_time(m.seq)  # t_k = k Δ, not the stamp m.t
                    m.y[:n], m.yd[:n] = tamper(channels.get(m.agent, []), t, m.y[:n], m.yd[:n])
                outbox.send_copy(m)  # the answer for (agent, seq): same header and stamp
                left[m.agent] = max(0, env.ticks - 1 - m.seq)
            relay.notify()
        run.done_and_wait_for_stop()


if __name__ == "__main__":
    main()
