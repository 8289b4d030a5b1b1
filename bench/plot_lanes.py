#!/usr/bin/python3
# Plots bench_lanes paper's samples (recording pace, vector fields per lane, memory over the run) from
# its output on stdin (the shipped run-paper.yaml's run):
#   build/bin/bench_lanes paper | /usr/bin/python3 bench/plot_lanes.py docs/lanes_paper.png
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

VARIANT = "paper_run_paper_yaml"  # the shipped config, both lanes
samples = []
for line in sys.stdin:
    if line.startswith("bench=lanes_sample "):
        fields = dict(f.split("=", 1) for f in line.split()[1:])
        if fields.pop("variant", VARIANT) == VARIANT:
            samples.append({k: float(v) for k, v in fields.items()})
if len(samples) < 2:
    sys.exit(f"plot_lanes.py: no samples (bench=lanes_sample variant={VARIANT} ...) on stdin")
t = [s["t_s"] for s in samples]


def rate(key, window=10):
    """Per second over the last `window` samples (one a second)."""
    return [(samples[i][key] - samples[max(i - window, 0)][key]) /
            max(samples[i]["t_s"] - samples[max(i - window, 0)]["t_s"], 1e-9) for i in range(len(samples))]


fig, axes = plt.subplots(3, 1, figsize=(7, 6), sharex=True)
axes[0].plot(t, rate("recorded"), lw=0.8, label="recorded")
axes[0].set_ylabel("pairs/s", fontsize=8)
axes[1].plot(t, rate("live_fields"), lw=0.8, label="live lane")
axes[1].plot(t, rate("quality_fields"), lw=0.8, label="quality lane")
axes[1].set_ylabel("vector fields/s", fontsize=8)
axes[1].legend(fontsize=7)
axes[2].plot(t, [s["rss_gb"] for s in samples], lw=0.8)
axes[2].set_ylabel("resident memory, GB", fontsize=8)
for ax in axes:
    ax.set_ylim(0, None)
    ax.grid(alpha=0.3)
axes[-1].set_xlabel("time since acquisition started, s")
lost = int(samples[-1]["frames_lost"])
fig.suptitle(f"run-paper.yaml on paper-scale replay frames: {int(samples[-1]['recorded'])} pairs recorded, "
             f"{lost} raw frames lost", fontsize=9)
fig.tight_layout()
fig.savefig(sys.argv[1] if len(sys.argv) > 1 else "lanes_paper.png", dpi=110)
print(f"plot_lanes.py: wrote {sys.argv[1] if len(sys.argv) > 1 else 'lanes_paper.png'}")
