"""Draws what a live viewer received: the JSON file `tests/python/live_client.py --out FILE`
writes, as the first tabs of the shipped layouts arrange it (the robots' position errors with
the paper's bound, the attack estimate against the true attack term).

    python examples/live/plot_capture.py capture.json live.png

The capture must hold /agent<id>/tracking_error of robots 1-4 and /agent<id>/estimate and
/agent<id>/attack of robots 1 and 4 (docs/traces.md, "Live", shows the commands).
"""

import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

BOUND_RAD = 0.02  # the paper's bound on the position error (Section VII)


def series(capture, topic, field, link):
    """(t, value) of a field's link over the messages received on a topic."""
    msgs = capture["messages"].get(topic)
    if not msgs:
        raise SystemExit(f"{topic}: nothing received (subscribe to it)")
    t, v = [], []
    for stamp, text in msgs:
        m = json.loads(text)
        x = m[field][link] if m[field] else None
        t.append(stamp / 1e9)
        v.append(float("nan") if x is None else x)
    return t, v


def main():
    capture = json.load(open(sys.argv[1], encoding="utf-8"))
    fig, axes = plt.subplots(3, 2, figsize=(11, 9), sharex=True)
    for i, robot in enumerate([1, 2, 3, 4]):
        ax = axes[i // 2][i % 2]
        for link in (0, 1):
            t, e = series(capture, f"/agent{robot}/tracking_error", "e_rad", link)
            ax.plot(t, e, lw=0.8, label=f"link {link + 1}")
        for b in (BOUND_RAD, -BOUND_RAD):
            ax.axhline(b, color="0.5", ls="--", lw=0.8)
        ax.set_title(f"robot {robot}: position error q_d − q (rad), paper's bound ±{BOUND_RAD}")
        ax.legend(loc="upper right", fontsize=8)
    for j, robot in enumerate([1, 4]):
        ax = axes[2][j]
        for link in (0, 1):
            t, s = series(capture, f"/agent{robot}/attack", "s_true_rad_s", link)
            ax.plot(t, s, lw=1.5, alpha=0.5, label=f"S link {link + 1}")
            t, s = series(capture, f"/agent{robot}/estimate", "s_hat_rad_s", link)
            ax.plot(t, s, lw=0.8, label=f"Ŝ link {link + 1}")
        ax.set_title(f"robot {robot}: attack estimate Ŝ against the true S (rad/s)")
        ax.set_xlabel("simulated time (s)")
        ax.legend(loc="upper right", fontsize=8)
    n = len(capture["messages"][f"/agent1/tracking_error"])
    fig.suptitle(f"What a live viewer received ({n} ticks per robot, decimated)")
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=90)
    print(f"{sys.argv[2]}: {n} ticks per robot")


if __name__ == "__main__":
    main()
