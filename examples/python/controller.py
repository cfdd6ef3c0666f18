"""A controller program for a scenario's [roles.controller]: the paper's traditional law.

Per agent and tick the control center asks (fdi/external/controller/in) with the measurement
in use (y, ẏ), the reference (q_d, q̇_d), e_u = ∫ u over the known delay and A = M(q_d)⁻¹; the
program answers (fdi/external/controller/out) the torque

    u = K (q̇_d − ẏ + β (q_d − y) − A e_u + Ŝ),   Ŝ = 0,

with the run's gains: β of [controller], K = k I, or K = k diag(M(q_d(0))) with
gain_scaling = "inertia" (k and the scaling of the agent's [agents.gains], else of
[controller]). Every operation is the one the built-in `traditional` controller does, in the
same order, on the same doubles, so a lockstep run gives the built-in's trace digest bit for
bit (examples/python/paper-python-controller.toml; docs/protocol.md, "The controller program").

--bad non-finite|dof|silent answers badly from tick --bad-from on (NaN torques, the wrong
number of joints, nothing at all): what the run does then (docs/protocol.md).
"""

import argparse
import math
import tomllib

import fdi_protocol as fdi


def gains_of(scenario_path):
    """Per agent id: (k, scaling) of its law, and β of the run."""
    with open(scenario_path, "rb") as f:
        s = tomllib.load(f)
    c = s["controller"]
    out = {}
    for a in s["agents"]:
        g = a.get("gains", {})
        out[a["id"]] = (g.get("gain_k", c["gain_k"]),
                        g.get("gain_scaling", c.get("gain_scaling", "unit")))
    return out, c["beta"]


class Law:
    """The traditional law of one agent."""

    def __init__(self, k, scaling, beta):
        self.k, self.scaling, self.beta = k, scaling, beta
        self.gains = None  # the diagonal of K, made at the first question (tick 0)

    def torque(self, q):
        n = q.dof
        if self.gains is None:
            if q.seq != 0:
                raise SystemExit(f"agent {q.agent}: first question is tick {q.seq}, not 0")
            if self.scaling == "inertia":  # M(q_d(0)) is the first question's M(q_d)
                self.gains = [q.inertia_ref[i * fdi.MAX_DOF + i] * self.k for i in range(n)]
            else:
                self.gains = [self.k] * n
        u = []
        for i in range(n):
            # (A e_u)_i, summed from the first column on, as the built-in's matrix product
            a_e = q.inverse_inertia_ref[i * fdi.MAX_DOF] * q.e_u[0]
            for j in range(1, n):
                a_e = a_e + q.inverse_inertia_ref[i * fdi.MAX_DOF + j] * q.e_u[j]
            psi1 = q.q_d[i] - q.y[i]
            psi1_dot = q.qd_d[i] - q.yd[i]
            r = psi1_dot + psi1 * self.beta - a_e + 0.0  # + Ŝ, which is 0 here
            u.append(r * self.gains[i])
        return u


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bad", choices=["non-finite", "dof", "silent"],
                    help="answer badly from tick --bad-from on (tests of the run's checks)")
    ap.add_argument("--bad-from", type=int, default=100)
    args = ap.parse_args()
    with fdi.Run("controller") as run:
        env = run.env
        per_agent, beta = gains_of(env.scenario)
        laws = {a: Law(*per_agent[a], beta) for a in env.agents}
        questions = run.subscriber("fdi/external/controller/in", fdi.ControllerInMsg)
        answers = run.publisher("fdi/external/controller/out", fdi.ControllerOutMsg)
        center = run.notifier("fdi/wake/center")
        run.ready_and_wait_for_start()
        answered = {a: 0 for a in env.agents}
        while any(n < env.ticks for n in answered.values()):
            batch = run.drain(questions, fdi.ControllerInMsg)
            if not batch:
                run.wait()
                continue
            for q in batch:
                u = laws[q.agent].torque(q)
                answered[q.agent] = q.seq + 1
                bad = args.bad if q.seq >= args.bad_from else None
                if bad == "silent":
                    continue
                if bad == "non-finite":
                    u = [math.nan] * len(u)
                a = fdi.ControllerOutMsg(seq=q.seq, agent=q.agent,
                                         dof=q.dof + (1 if bad == "dof" else 0),
                                         controller_sent_ns=fdi.monotonic_ns())
                a.u[:len(u)] = u
                answers.send_copy(a)
            center.notify()
        run.done_and_wait_for_stop()


if __name__ == "__main__":
    main()
