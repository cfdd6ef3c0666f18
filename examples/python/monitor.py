"""A monitor program for a scenario's [roles.monitor]: a kinematic-consistency detector.

Honest sensors measure a position and its derivative, so over a window of W ticks the finite
difference of the measured position, (y_k - y_{k-W}) / (W Δ), matches the measured velocity
averaged over the window (trapezoid rule) up to sensor noise. False data that moves the two
inconsistently (the paper's attack, the onset and end of a position bias, a replayed
recording's loop seam) breaks that. Per agent and tick the statistic is the largest
|difference| over the links, in units of the noise it has without attack,
σ = sqrt(2 σ_y² / (W Δ)² + σ_ẏ² / W), with σ_y, σ_ẏ the [noise] of the run's scenario; the
alarm is on while it stays above --threshold for at least --hold-s.

Also alarmed: a tick whose message is a replay (an older tick again: honest senders never
repeat one) or has non-finite values, and the tick of a non-finite torque on fdi/torque/<id>
(the next tick judged when the torque is read after its own tick was judged). A gap marker
(the tick's message was dropped) keeps the alarm as it was; the window starts anew after it.
"""

import argparse
import math
import sys
import tomllib
from collections import deque

import fdi_protocol as fdi


class Agent:
    """The detector's state for one agent."""

    def __init__(self, dt, window, sigma, threshold, hold):
        self.dt, self.window, self.sigma = dt, window, sigma
        self.threshold, self.hold = threshold, hold
        self.next = 0  # next tick to judge
        self.history = deque(maxlen=window + 1)  # (y, yd) of the last consecutive ticks
        self.above = 0  # consecutive ticks above the threshold
        self.alarm = False
        self.replayed = False  # a replay came since the last verdict
        self.bad_torque = None  # the earliest tick not yet judged with a non-finite torque
        self.torques = self.bad_torques = self.replays = self.gaps = 0

    def judge(self, m):
        """The verdict (alarm, statistic) on the message of tick m.seq (data or gap)."""
        suspect, self.replayed = self.replayed, False
        if self.bad_torque is not None and self.bad_torque <= m.seq:
            suspect, self.bad_torque = True, None
        if m.flags & fdi.GAP:
            self.gaps += 1
            self.history.clear()
            return self.alarm or suspect, math.nan
        n = m.dof
        y, yd = list(m.y[:n]), list(m.yd[:n])
        if not all(map(math.isfinite, y + yd)):
            self.history.clear()
            return True, math.inf
        self.history.append((y, yd))
        if len(self.history) <= self.window:
            return self.alarm or suspect, math.nan
        (y0, _), (yk, _) = self.history[0], self.history[-1]
        stat = 0.0
        for i in range(n):
            v = [h[1][i] for h in self.history]
            mean_v = (sum(v) - 0.5 * (v[0] + v[-1])) / self.window
            diff = (yk[i] - y0[i]) / (self.window * self.dt) - mean_v
            stat = max(stat, abs(diff) / self.sigma)
        self.above = self.above + 1 if stat > self.threshold else 0
        self.alarm = self.above >= self.hold
        return self.alarm or suspect, stat


def noise_of(scenario_path):
    """(σ_y, σ_ẏ) of the run's scenario ([noise]; 0 without)."""
    with open(scenario_path, "rb") as f:
        noise = tomllib.load(f).get("noise", {})
    return noise.get("position_std_rad", 0.0), noise.get("velocity_std_rad_s", 0.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--window-s", type=float, default=0.05, help="window W Δ, s (0.05)")
    ap.add_argument("--threshold", type=float, default=6.0,
                    help="alarm level of the statistic, in noise standard deviations (6)")
    ap.add_argument("--hold-s", type=float, default=0.01,
                    help="how long the statistic must stay above it, s (0.01)")
    ap.add_argument("--min-std", type=float, default=1e-6,
                    help="floor of σ_y and σ_ẏ, for scenarios without noise (1e-6)")
    args = ap.parse_args()
    with fdi.Run("monitor") as run:
        env = run.env
        window = max(1, round(args.window_s / env.dt))
        sy, syd = (max(s, args.min_std) for s in noise_of(env.scenario))
        sigma = math.sqrt(2 * sy**2 / (window * env.dt) ** 2 + syd**2 / window)
        hold = max(1, round(args.hold_s / env.dt))
        agents = {a: Agent(env.dt, window, sigma, args.threshold, hold) for a in env.agents}
        tampered = run.subscriber("fdi/tampered", fdi.MeasurementMsg)
        torques = {a: run.subscriber(f"fdi/torque/{a}", fdi.TorqueMsg) for a in env.agents}
        alarms = run.publisher("fdi/alarm", fdi.AlarmMsg)
        center = run.notifier("fdi/wake/center")
        run.ready_and_wait_for_start()
        while any(a.next < env.ticks for a in agents.values()):
            for agent, sub in torques.items():  # never waited for: read what is there
                a = agents[agent]
                for u in run.drain(sub, fdi.TorqueMsg):
                    a.torques += 1
                    if not u.flags & fdi.GAP and not all(map(math.isfinite, u.u[:u.dof])):
                        a.bad_torques += 1
                        if a.bad_torque is None:  # torques come in tick order
                            a.bad_torque = u.seq
            batch = run.drain(tampered)
            if not batch:
                run.wait()
                continue
            for m in batch:
                a = agents.get(m.agent)
                if a is None or m.seq >= env.ticks:
                    continue
                if m.seq < a.next:  # a replay under its original header
                    a.replays += 1
                    a.replayed = True
                    continue
                while a.next < m.seq:  # ticks never seen (a full buffer): no statistic
                    a.history.clear()
                    send(alarms, a.next, m.agent, a.alarm, math.nan)
                    a.next += 1
                alarm, stat = a.judge(m)
                send(alarms, m.seq, m.agent, alarm, stat)
                a.next = m.seq + 1
            center.notify()
        for agent, a in agents.items():
            print(f"agent {agent}: {a.torques} torques ({a.bad_torques} non-finite), "
                  f"{a.replays} replays, {a.gaps} gaps", flush=True)
        run.done_and_wait_for_stop()


def send(alarms, k, agent, alarm, stat):
    alarms.send_copy(fdi.AlarmMsg(seq=k, agent=agent, alarm=int(alarm), statistic=stat,
                                  monitor_sent_ns=fdi.monotonic_ns()))


if __name__ == "__main__":
    main()
