"""The paper's Fig. 3 (position tracking error q_d − q of each robot's links over time) from the
CSV export alone: `fdi-launch trace export RUN_DIR --format csv`, then

    python fig3.py RUN_DIR/export fig3.png
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd

export, out = Path(sys.argv[1]), sys.argv[2]
center = pd.read_csv(export / "control-center.csv")  # q<i>_des_rad: the desired trajectory
agents = pd.concat(pd.read_csv(f) for f in sorted(export.glob("agent-*.csv")))  # q<i>_rad: true
df = agents.merge(center, on=["k", "agent", "t_s"], validate="one_to_one")

links = [c[1:-4] for c in agents.columns if c.startswith("q") and c.endswith("_rad") and c[1:-4].isdigit()]
robots = sorted(df["agent"].unique())
fig, axes = plt.subplots(len(robots), 1, sharex=True, figsize=(7, 2 * len(robots)), squeeze=False)
for ax, (agent, r) in zip(axes[:, 0], df.groupby("agent")):
    for link in links:
        ax.plot(r["t_s"], r[f"q{link}_des_rad"] - r[f"q{link}_rad"], label=f"e{link} = q{link},d − q{link}")
    ax.set_ylabel(f"robot {agent}\nerror (rad)")
    ax.legend(loc="upper right")
axes[-1, 0].set_xlabel("t (s)")
fig.savefig(out, dpi=120, bbox_inches="tight")
print(f"{out}: position error of {len(robots)} robots, {len(df)} rows")
