#!/usr/bin/python3
# Plots bench_soak's samples (recording pace, memory, file descriptors, threads over the run) from its
# output on stdin:  build/bin/bench_soak 10000 15 | /usr/bin/python3 bench/plot_soak.py docs/soak.png
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

samples = []
for line in sys.stdin:
    if line.startswith("bench=soak_sample "):
        samples.append({k: float(v) for k, v in (f.split("=", 1) for f in line.split()[1:])})
if len(samples) < 2:
    sys.exit("plot_soak.py: no samples (bench=soak_sample ...) on stdin")
t = [s["t_s"] / 60 for s in samples]
# Pairs recorded per second over the last 10 samples (one a second).
pace = [(samples[i]["recorded"] - samples[max(i - 10, 0)]["recorded"]) /
        max(samples[i]["t_s"] - samples[max(i - 10, 0)]["t_s"], 1e-9) for i in range(len(samples))]
fig, axes = plt.subplots(4, 1, figsize=(7, 7), sharex=True)
for ax, values, label in zip(axes, [pace, [s["rss_gb"] * 1024 for s in samples], [s["fds"] for s in samples],
                                    [s["threads"] for s in samples]],
                             ["recorded, pairs/s", "resident memory, MB", "open file descriptors", "threads"]):
    ax.plot(t, values, lw=0.8)
    ax.set_ylabel(label, fontsize=8)
    ax.set_ylim(0, max(values) * 1.2 + 1)
    ax.grid(alpha=0.3)
axes[-1].set_xlabel("time since acquisition started, min")
lost = int(samples[-1]["frames_lost"])
fig.suptitle(f"bench_soak: {int(samples[-1]['recorded'])} pairs recorded, {lost} raw frames lost", fontsize=10)
fig.tight_layout()
fig.savefig(sys.argv[1], dpi=110)
print(f"plot_soak.py: {sys.argv[1]}")
