#!/usr/bin/python3
# Plots bench_e2e's sweep (time against RMS error, Pareto front marked) from its output on stdin:
#   build/bin/bench_e2e reduced | /usr/bin/python3 bench/plot_e2e.py docs/e2e_pareto.png
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import matplotlib.ticker

rows = []
for line in sys.stdin:
    fields = dict(f.split("=", 1) for f in line.split() if "=" in f)
    if "pareto" in fields:
        rows.append(fields)
if not rows:
    sys.exit("plot_e2e.py: no sweep rows (pareto=...) on stdin")
fig, ax = plt.subplots(figsize=(7, 4.5))
front = sorted((float(r["total_s"]), float(r["rms"])) for r in rows if r["pareto"] == "yes")
ax.plot([t for t, _ in front], [e for _, e in front], "-", color="tab:red", label="Pareto front")
# Labels alternate above and below their points (neighbouring settings sit close together).
for k, r in enumerate(sorted(rows, key=lambda r: float(r["total_s"]))):
    t, e = float(r["total_s"]), float(r["rms"])
    ax.plot(t, e, "o", color="tab:red" if r["pareto"] == "yes" else "tab:gray")
    label = {"paper": "paper", "iterations": f"it {r['iterations']}", "mu": f"mu {r['mu']}, it {r['iterations']}",
             "acceleration": f"accelerated, it {r['iterations']}",
             "no_depth_guard": "no depth guard", "dark_cutoff": f"cutoff {r.get('value')}",
             "noise_threshold": f"floor {r.get('value')}",
             "angular_sampling": f"angular {r.get('value', '').split(',')[0]}", "binning": f"binning {r.get('value')}",
             "final_window": f"{r['final_window']}³",
             "passes": f"{r['passes']} passes",
             "intensity_threshold": f"ghost floor {r.get('value')}x mean",
             "depth_prefilter": f"depth prefilter {r.get('value')}",
             "mart_floor": r.get("value", "").replace("_", " ")}[r["variant"]]
    ax.annotate(label, (t, e), textcoords="offset points", xytext=(4, 4 if k % 2 == 0 else -11), fontsize=8)
ax.set_xlabel("time per pair, s (2 reconstructions + correlation; shared machine)")
ax.set_ylabel("RMS error, voxels (|u, v, w|)")
errors = [float(r["rms"]) for r in rows]
if max(errors) > 3 * min(errors):  # one slow-converging row would flatten the rest
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%.1f"))
    ax.yaxis.set_minor_formatter(matplotlib.ticker.FormatStrFormatter("%.1f"))
ax.set_title(f"bench_e2e {rows[0]['case']}: ring vortex, time against error")
ax.grid(alpha=0.3)
ax.legend()
fig.tight_layout()
fig.savefig(sys.argv[1] if len(sys.argv) > 1 else "e2e_pareto.png", dpi=110)
