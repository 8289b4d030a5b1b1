#!/usr/bin/python3
"""Regenerates the tables of docs/benchmarks.md and docs/paper-figures.md from the benchmarks' machine-readable lines.

  /usr/bin/python3 scripts/bench_tables.py               tables from the saved results
  /usr/bin/python3 scripts/bench_tables.py --run quick   rerun the quick benchmarks first (~5 min)
  /usr/bin/python3 scripts/bench_tables.py --run paper   rerun the paper-scale ones (~30 min, nice 10)
  /usr/bin/python3 scripts/bench_tables.py --run all     both
  /usr/bin/python3 scripts/bench_tables.py --run e2e-full piv   named results only
  /usr/bin/python3 scripts/bench_tables.py --list        the results, their commands and sets

--run builds the bench targets in build/ (configured as the README says), runs each benchmark from
the repository root and saves its standard output, headed by the command, date, commit, machine
and load average, as docs/bench-results/<name>.txt. Then every table between
`<!-- generated: NAME -->` and `<!-- end: NAME -->` in docs/benchmarks.md is rewritten from those
files, and the time-against-error plots (docs/e2e_pareto*.png) are redrawn by bench/plot_e2e.py.
"""
import argparse
import datetime
import os
import re
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "bench-results"
DOC = ROOT / "docs" / "benchmarks.md"
# The pages with generated tables: the benchmarks page, the paper's figures reproduced, and the
# accuracy and reconstruction pages' measured tables.
DOCS = [DOC, ROOT / "docs" / "paper-figures.md", ROOT / "docs" / "accuracy.md", ROOT / "docs" / "recon.md"]

# The shipped full settings' MART, ghost floor and final smoothing as bench_e2e's flags, with
# `iterations` (run-paper.yaml's 8, process.yaml's 20).
def shipped_mart(iterations):
    return ["--mu", "1", "--accelerate", "--iterations", str(iterations), "--prune-threshold", "0.01", "--prune-scope",
            "slice", "--intensity-threshold", "3", "--final-smoothing", "1"]


# run-paper.yaml's MART: process.yaml's with 8 iterations, and a cut against each voxel's neighbourhood.
RUN_PAPER_MART = shipped_mart(8) + ["--prune-local-threshold", "0.05"]
# run-paper.yaml's reconstruction and correlation settings.
RUN_PAPER_PASSES = "32x32x16@50,16x16x8@50+2,16x16x8@50,16x16x8@50,16x16x8@75"


# process.yaml's: run-paper.yaml's with two more 2 mm @50 % passes before the last.
PROCESS_PASSES = "32x32x16@50,16x16x8@50+2,16x16x8@50,16x16x8@50,16x16x8@50,16x16x8@50,16x16x8@75"


# `mart` on the shipped voxels (0.25 mm deep) with the shipped correlation (`passes`; the passes
# before the last whitened).
def shipped(mart, passes=RUN_PAPER_PASSES):
    return (["--voxel-z-factor", "2"] + mart
            + ["--depth-prefilter", "1", "--passes", passes, "--early-interpolation", "cubic",
               "--spectral-whitening", "0.5", "--whitened-peak-sigma", "1,1,2"])


# run-paper.yaml's full tier computes the per-vector sigma every second node per axis and looks for
# the last pass's peaks at the predictor first. Its w through MART's depth response as well
# (RUN_PAPER_RESPONSE) in the headline; the sweeps compare MART and correlation settings without it
# (it rescales w afterwards, and its minutes of set-up would be measured again for every variant).
RUN_PAPER = shipped(RUN_PAPER_MART) + ["--uncertainty-stride", "2", "--final-peak-search", "near_predictor"]
RUN_PAPER_RESPONSE = ["--depth-response-ppm", "0.5"]
# process.yaml's: run-paper.yaml's settings with 20 iterations and seven passes.
PROCESS = shipped(shipped_mart(20), PROCESS_PASSES)
# process-paper.yaml's: run-paper.yaml's box and correlation in mm on voxels half a lens pitch
# across (windows and the whitened peak in those voxels), 12 iterations, w through the depth response.
PROCESS_PAPER = (["--voxel-z-factor", "2", "--voxel-xy-divisor", "2"] + shipped_mart(12)
                 + ["--depth-prefilter", "1", "--passes", "64x64x16@50,32x32x8@50+2,32x32x8@50,32x32x8@50,32x32x8@75",
                    "--early-interpolation", "cubic", "--spectral-whitening", "0.5", "--whitened-peak-sigma", "2,2,2",
                    "--uncertainty-stride", "2", "--final-peak-search", "near_predictor", "--depth-response-ppm", "0.5"])
# run.yaml's (the live preview on the small camera).
RUN = ["--voxel-z-factor", "2", "--mu", "1", "--iterations", "4", "--intensity-threshold", "4", "--final-smoothing",
       "1", "--depth-prefilter", "1", "--passes", "16x16x8@50+2,8x8x4@50", "--spectral-whitening", "0.5",
       "--whitened-peak-sigma", "1,1,2"]

# Live tiers at the paper's scale, bench_e2e --live B,K,N,P: voxels B times as large, pixels binned
# K x K, N MART iterations, passes P (BzDpF: D times as deep, F depth prefilter passes; the cubes'
# tiers take 4). RUN_PAPER_LIVE is run-paper.yaml's `live:` tier.
RUN_PAPER_LIVE = "3z6p1,4,4,16x16x8@50+2,8x8x4@50"
# Its MART's prune cut (of each depth slice's peak), which every live tier here takes.
RUN_PAPER_LIVE_PRUNE = "0.1"
LIVE_TIERS = ["4,4,5,16@50+4,8@50", "4,4,8,16@50+4,8@50", "3,4,3,16@50+4,8@50", "3,4,4,16@50+4,8@50", RUN_PAPER_LIVE,
              "2z4p2,4,4,24x24x12@50+3,12x12x6@50",
              "3,4,5,16@50+4,8@50", "3,2,3,16@50+4,8@50", "3,1,3,16@50+4,8@50", "2,2,3,16@50+4,8@50"]

# MART's prune thresholds the sparse sweeps compare.
SPARSE_VARIANTS = ("off,zeros,1e-2,slice-1e-2,slice-3e-2,slice-1e-1,slice-1e-1-reach2,slice-2e-1,slice-2e-1-reach2,"
                   "slice-1e-2-local-5e-2,slice-1e-2-local-1e-1")

# The paper ring through other sensors (bench/sensor_cases.sh SENSOR/BLACK_LEVEL[/EXTRA]): the
# simulator's one count per ray; a 100-count pedestal with 2 electrons of read noise (a cooled
# camera); the simulated camera's `noise=1` (4 electrons per ray, 8 of read noise, 20 counts). Each
# with the black level taken off and left on; the noisy one also with a threshold at its pedestal
# plus one sigma of read noise, and with dark_weight_cutoff 0.99. The same sensor exposed four
# times longer, and with its right half read out 30 counts higher (a second tap's offset).
SENSOR_CASES = ["clean/between_images", "4,2,100/between_images", "4,2,100/none", "4,8,20/between_images",
                "4,8,20/none", "4,8,20/none/--noise-threshold+28", "4,8,20/between_images/--dark-cutoff+0.99",
                "16,8,20/between_images", "16,8,20/between_images/--tap-offset+30"]

# name: (set, command from the repository root, plot or None); a plot is drawn by bench/plot_e2e.py from
# sweep rows (pareto=), or by the script PLOTTERS names from the samples it names
BENCHES = {
    "e2e-reduced": ("quick", ["build/bin/bench_e2e", "reduced"], "e2e_pareto.png"),
    "e2e-full": ("paper", ["build/bin/bench_e2e", "full", "--no-sweep", "--steady"] + RUN_PAPER + RUN_PAPER_RESPONSE
                 + ["--compare-passes", RUN_PAPER_PASSES], None),
    "e2e-full-live": ("paper", ["build/bin/bench_e2e", "full", "--no-sweep"] + RUN_PAPER
                      + ["--live-depth-prefilter", "4", "--live-prune-threshold", RUN_PAPER_LIVE_PRUNE,
                         "--live-prune-local-threshold", "0"]
                      + [a for tier in LIVE_TIERS for a in ("--live", tier)], None),
    "rotated-shear": ("paper", ["build/bin/bench_rotated_shear", "0.1"], None),
    "rotated-shear-paper-accuracy": ("paper", ["build/bin/bench_rotated_shear", "0.1", "0.5", "full",
                                               "systemd/config/process-paper.yaml"], None),
    "e2e-full-sweep": ("paper", ["build/bin/bench_e2e", "full", "--no-sweep", "--time-sweep", "--time-repeats", "5"]
                       + RUN_PAPER,
                       "e2e_pareto_full.png"),
    "e2e-full-sparse": ("paper", ["build/bin/bench_e2e", "full", "--no-sweep", "--sparse-sweep", "--sparse-repeats",
                                  "1", "--sparse-variants", SPARSE_VARIANTS] + RUN_PAPER, None),
    "e2e-full-sparse-spread": ("paper", ["build/bin/bench_e2e", "full", "--no-sweep", "--brightness-spread", "0.7",
                                         "--sparse-sweep", "--sparse-repeats", "1", "--sparse-variants",
                                         SPARSE_VARIANTS] + RUN_PAPER, None),
    "e2e-full-sensors": ("paper", ["bench/sensor_cases.sh"] + SENSOR_CASES + ["--"] + RUN_PAPER, None),
    "e2e-full-process": ("paper", ["build/bin/bench_e2e", "full", "--no-sweep", "--steady"] + PROCESS,
                         None),
    "e2e-full-paper-accuracy": ("paper", ["build/bin/bench_e2e", "full", "--no-sweep", "--steady"] + PROCESS_PAPER,
                                None),
    "e2e-reduced-process": ("quick", ["build/bin/bench_e2e", "reduced", "--no-sweep", "--steady"] + PROCESS,
                            None),
    "e2e-reduced-live": ("quick", ["build/bin/bench_e2e", "reduced", "--no-sweep", "--steady"] + RUN, None),
    "recon-small": ("quick", ["build/bin/bench_recon", "small"], None),
    "recon-paper": ("paper", ["build/bin/bench_recon", "paper"], None),
    "recon-mid": ("quick", ["build/bin/bench_recon", "mid"], None),
    "recon-volume-paper": ("paper", ["bench/recon_volume.sh", "3"], None),
    "recon-figures": ("quick", ["build/bin/bench_recon", "figures", "0.9"], None),
    "recon-fig22": ("quick", ["build/bin/bench_recon", "fig22", "0.9"], None),
    "recon-fig22-accurate": ("quick", ["build/bin/bench_recon", "fig22", "0.9", "20", "1", "nesterov",
                                       "0.0052"], None),
    "piv": ("paper", ["build/bin/bench_piv"], None),
    "uncertainty": ("paper", ["build/bin/bench_uncertainty", "--with-paper-ring"], None),
    "daemon": ("quick", ["build/bin/bench_daemon", "6", "1.0"], None),
    "lanes": ("quick", ["build/bin/bench_lanes", "200", "10"], None),
    "lanes-paper": ("paper", ["build/bin/bench_lanes", "paper", "600", "10"], "lanes_paper.png"),
    "soak": ("paper", ["build/bin/bench_soak", "10000", "15"], "soak.png"),
    "recording": ("quick", ["build/bin/bench_recording", "100", "3", "10"], None),
    "sim": ("quick", ["build/bin/bench_sim"], None),
    "calib": ("quick", ["build/bin/bench_calib"], None),
    "resampling": ("quick", ["build/bin/bench_resampling"], None),
    "oneshot": ("paper", ["bench/oneshot_cli.sh"], None),
    "oneshot-paper-accuracy": ("paper", ["bench/oneshot_cli.sh", "1", "systemd/config/process-paper.yaml"], None),
}

# The build targets of the benchmarks that are scripts (the others: their binary's name).
SCRIPT_TARGETS = {"oneshot": ["plenopiv"], "oneshot-paper-accuracy": ["plenopiv"], "e2e-full-sensors": ["bench_e2e"],
                  "recon-volume-paper": ["bench_recon"]}

# Benchmarks of the daemon's thread priorities: never run under nice.
OWN_PRIORITIES = {"lanes-paper"}

# plot: (script, the sample lines it reads)
PLOTTERS = {"soak.png": ("bench/plot_soak.py", "bench=soak_sample"),
            "lanes_paper.png": ("bench/plot_lanes.py", "bench=lanes_sample")}

# ---------------------------------------------------------------------------------------------
# Running


def machine():
    """Cores, CPU model and its widest vector instructions (the kernels' build: AVX-512, AVX2 or
    baseline SSE), Debian release."""
    model, flags = "unknown CPU", set()
    for line in open("/proc/cpuinfo"):
        if line.startswith("model name") and model == "unknown CPU":
            model = line.split(":", 1)[1].strip()
        if line.startswith("flags"):
            flags = set(line.split(":", 1)[1].split())
            break
    isa = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "SSE"
    debian = Path("/etc/debian_version")
    system = f"Debian {debian.read_text().strip()}" if debian.exists() else "Linux"
    return f"{os.cpu_count()} cores ({model}, {isa}), {system}"


def run(name):
    scale, command, _ = BENCHES[name]
    commit = subprocess.run(["git", "rev-parse", "--short=7", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip()
    # Uncommitted changes outside docs/ may change what was measured: say so.
    changed = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".",
                              ":(exclude)docs"], cwd=ROOT, capture_output=True, text=True).stdout
    if changed.strip():
        commit += " with uncommitted changes"
    load = open("/proc/loadavg").read().split()[:3]
    start = datetime.datetime.now(datetime.timezone.utc)
    # Long runs yield to the machine's other work; a daemon bench keeps its own priorities (recording
    # above processing), which a nice of the whole process would flatten.
    argv = (["nice", "-n", "10"] if scale == "paper" and name not in OWN_PRIORITIES else []) + command
    print(f"bench_tables: {name}: {' '.join(argv)}", file=sys.stderr, flush=True)
    out = subprocess.run(argv, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    if out.returncode != 0:
        sys.exit(f"bench_tables: {name} failed (exit {out.returncode}); nothing saved")
    minutes = (datetime.datetime.now(datetime.timezone.utc) - start).total_seconds() / 60
    header = [f"# command: {' '.join(command)}",
              f"# date: {start:%Y-%m-%d %H:%M} UTC ({minutes:.1f} min)",
              f"# commit: {commit}",
              f"# machine: {machine()}",
              f"# load: {' '.join(load)} (load average at the start, 1 / 5 / 15 min)"]
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{name}.txt").write_text("\n".join(header) + "\n" + out.stdout)


def build(names):
    targets = sorted({t for n in names for t in SCRIPT_TARGETS.get(n, [Path(BENCHES[n][1][0]).name])})
    subprocess.run(["cmake", "--build", "build", "-j2", "--target", *targets], cwd=ROOT, check=True)


# ---------------------------------------------------------------------------------------------
# Reading


class Result:
    """One saved run: its header and its `bench=` lines as dictionaries of strings."""

    def __init__(self, name):
        self.name = name
        self.meta, self.lines = {}, []
        path = RESULTS / f"{name}.txt"
        self.exists = path.exists()
        if not self.exists:
            return
        for line in path.read_text().splitlines():
            if line.startswith("# ") and ":" in line and not self.lines:
                key, value = line[2:].split(":", 1)
                self.meta[key.strip()] = value.strip()
            elif line.startswith("bench="):
                self.lines.append(dict(t.split("=", 1) for t in line.split() if "=" in t))

    def find(self, **match):
        return [d for d in self.lines if all(d.get(k) == v for k, v in match.items())]

    def one(self, **match):
        found = self.find(**match)
        return found[0] if found else None

    def provenance(self):
        carried = self.meta.get("carried over")
        if carried:
            m = self.meta
            # Why it was carried over stays in the results file; the page says when and where.
            return (f"*Not rerun since {m.get('date', '?')} (commit {m.get('commit', '?')}, "
                    f"{m.get('machine', '?')}; why: docs/bench-results/{self.name}.txt). "
                    f"Rerun: `/usr/bin/python3 scripts/bench_tables.py --run {self.name}`.*")
        if not self.exists:
            command = " ".join(BENCHES[self.name][1])
            return f"*Not measured yet: `/usr/bin/python3 scripts/bench_tables.py --run {self.name}` " \
                   f"(runs `{command}`).*"
        m = self.meta
        return (f"*`{m.get('command', '?')}` · {m.get('date', '?')} · commit {m.get('commit', '?')} · "
                f"{m.get('machine', '?')} · load {m.get('load', '?').split(' (')[0]}*")


def uvw(d, prefix="rms_", keys=("u", "v", "w")):
    return " / ".join(d.get(prefix + k, "?") for k in keys)


def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return out


def pct(x):
    return f"{100 * float(x):.1f} %"


# ---------------------------------------------------------------------------------------------
# Tables: each takes the results it needs and returns markdown lines (provenance included).

HEADLINE_ROWS = [
    # (result, shipped config, what it ran, paper, targets); the time-sweep row with the same settings
    ("e2e-full", "run-paper.yaml",
     "sec 6.4 ring vortex: paper camera, 37.5 x 25 x 25 mm in 300x200x100 voxels (0.125 mm across, 0.25 mm deep), "
     "0.5 ppm",
     "0.165 / 0.23 / 0.98; 30 min per image on 12 cores",
     "<= 0.10 / 0.10 / 0.50 and <= 30 s per pair (#7); <= 10 s per pair in a run (#21)"),
    ("e2e-full-process", "process.yaml's MART and correlation",
     "the same pair and voxels", "as above", "as above"),
    ("e2e-full-paper-accuracy", "process-paper.yaml",
     "the same pair on voxels half a lens pitch across: 600x400x100 (0.0625 mm across, 0.25 mm deep)", "as above",
     "<= 0.08 / 0.08 / 0.30 off the axis band within 15 s one-shot (#28)"),
    ("e2e-reduced-process", "process.yaml's MART and correlation",
     "the ring scaled to camera-small: a 6 mm cube across the focal plane in 48 x 48 x 24 voxels (0.125 mm across, "
     "0.25 mm deep)", "—", "—"),
    ("e2e-reduced-live", "run.yaml's MART and correlation",
     "the same small pair", "—", "keep up with the laser (#22: every pair at 1 Hz)"),
]


def t_headline(R):
    rows = []
    for name, config, case, paper, target in HEADLINE_ROWS:
        r = R(name)
        rec = r.one(variant="reconstructed") or {}
        steady = r.one(variant="steady_state") or {}
        time = f"{steady.get('pair_s', '?')} s" if r.exists else "—"
        if "pair_min_s" in steady:  # the median of `repeats` pairs, and their range
            time += f" ({steady['pair_min_s']}-{steady['pair_max_s']})"
        if name == "e2e-full-paper-accuracy":  # with its one-shot call through the CLI
            oneshot = R("oneshot-paper-accuracy")
            once = oneshot.one(array="rotated", cache="read")
            first = oneshot.one(array="rotated", cache="built")
            if once and first:
                time += (f"; one-shot {once['wall_s']} s (a 0.1 deg rotated array, the cache read back; its first "
                         f"call, tables and depth response made: {first['wall_s']} s)")
        rows.append([config, case, f"{uvw(rec)} ({uvw(rec, 'off_axis_band_rms_')})" if r.exists else "—",
                     time, paper, target, r.meta.get("date", "—").split(" (")[0],
                     r.meta.get("commit", "—")])
    r = R("oneshot")
    rotated, nominal = r.one(array="rotated", cache="read"), r.one(array="nominal", cache="read")
    built = r.one(array="rotated", cache="built")
    # The one-shot's and MART's own rows go after process.yaml's on the same pair (the live tier's
    # row goes in above them).
    after = [n for n, *_ in HEADLINE_ROWS].index("e2e-full-process") + 1
    if rotated and nominal and built:
        rows.insert(after, ["run-paper.yaml's processing, once: `plenopiv process`",
                            "the sec 6.4 ring, 0.5 ppm, through a lens array rotated 0.1 deg (frames resampled): "
                            "TIFFs read, MART, correlation, HDF5 / .vti / PNG written", "—",
                            f"one-shot {rotated['wall_s']} s (tables built: {built['wall_s']} s); the camera file's "
                            f"array {nominal['wall_s']} s", "—", "<= 15 s one-shot (#21)",
                            r.meta.get("date", "—").split(" (")[0], r.meta.get("commit", "—")])
        after += 1
    r = R("recon-volume-paper")
    volumes = r.find(bench="recon_prune", variant="slice-1e-2-local-5e-2")
    if volumes:
        def median_range(key):
            v = sorted(float(d[key]) for d in volumes)
            return f"{statistics.median(v):.2f} s ({v[0]:.2f}-{v[-1]:.2f})"
        skipped = pct(statistics.median(float(d["updates_skipped"]) for d in volumes))
        # The memory the first frame faults in (bench_recon's fresh_memory_gb): what a first frame
        # pays for beyond a kept workspace.
        fresh = [float(d["fresh_memory_gb"]) for d in volumes if "fresh_memory_gb" in d]
        faulted = f", {statistics.median(fresh):.2f} GB faulted in" if fresh else ""
        rows.insert(after, ["run-paper.yaml's MART alone, 5 iterations",
                            "#21's volume: the paper camera's 300x200x200 voxels of 0.125 mm, 0.5 ppm, one frame",
                            "—", f"first frame {median_range('seconds')}{faulted}; kept workspace "
                            f"{median_range('kept_seconds')}; {skipped} of the updates skipped",
                            "30 min per image",
                            "<= 5 s (#21)", r.meta.get("date", "—").split(" (")[0], r.meta.get("commit", "—")])
    r = R("e2e-full-live")
    live = r.one(variant="live", tier=RUN_PAPER_LIVE)
    if live:
        b, db, k, n = live["binning"], live["depth_binning"], live["pixel_binning"], live["iterations"]
        rows.insert(1, ["run-paper.yaml's `live:` tier", f"the same pair: {0.125 * int(b):g} x {0.125 * int(db):g} mm "
                        f"voxels, pixels binned {k} x {k}, {n} it", f"{uvw(live)} ({uvw(live, 'off_axis_band_rms_')})",
                        f"{live['pair_s']} s", "—", "<= 1 s per pair (#22)", r.meta.get("date", "—").split(" (")[0],
                        r.meta.get("commit", "—")])
    out = table(["config", "case", "RMS u / v / w, voxels (off the axis band)", "time per pair in a run",
                 "paper", "target (issue)", "measured", "commit"], rows)
    names = [n for n, *_ in HEADLINE_ROWS] + ["e2e-full-live", "oneshot", "oneshot-paper-accuracy",
                                              "recon-volume-paper"]
    machines = {R(n).meta.get("machine") for n in names if R(n).exists}
    loads = ", ".join(f"{n} {R(n).meta.get('load', '?').split(' (')[0]}" for n in names if R(n).exists)
    out.append("")
    out.append(f"*Machine: {'; '.join(sorted(m for m in machines if m)) or '—'}; load average at the "
               f"start: {loads or '—'}. Commands: the End to end section; one-shot: `bench/oneshot_cli.sh`; MART alone: "
               f"`bench/recon_volume.sh` (medians of 3 processes, range).*")
    return out


def e2e_row(r, label):
    rec = r.one(variant="reconstructed")
    ex = r.one(variant="exact_volumes")
    steady = r.one(variant="steady_state")
    if not rec:
        return [label] + ["—"] * 6
    times = f"{rec.get('recon_a_s', '?')} + {rec.get('recon_b_s', '?')} + {rec.get('correlate_s', '?')}"
    if steady:
        times += f"; in a run {steady['pair_s']} (first {steady['first_pair_s']})"
    mart = f"{rec['iterations']} it, mu {float(rec['mu']):g}" + (", accelerated" if rec["accelerate"] == "1" else "")
    if float(rec.get("prune_threshold", "0")) > 0:
        mart += f", pruned below {float(rec['prune_threshold']):g} of each {rec.get('prune_scope', 'volume')}'s peak"
    if float(rec.get("prune_local_threshold", "0")) > 0:
        mart += f" and {float(rec['prune_local_threshold']):g} of each neighbourhood's"
    skipped = pct(rec["skipped_a"]) if "skipped_a" in rec else "?"
    if "updates_skipped_a" in rec:
        skipped += f" of the box, {pct(rec['updates_skipped_a'])} of the updates"
    return [label, mart, times, f"**{uvw(rec)}** ({rec['rms']})", uvw(rec, "off_axis_band_rms_"),
            f"{uvw(ex)}" if ex else "—", f"{skipped}, {rec.get('peak_rss_gb', '?')} GB"]


def t_e2e_cases(R):
    cases = (("e2e-full", "full, run-paper.yaml's"), ("e2e-full-process", "full, process.yaml's"),
             ("e2e-full-paper-accuracy", "full, process-paper.yaml's (0.0625 mm across)"),
             ("e2e-reduced-process", "reduced, process.yaml's"), ("e2e-reduced-live", "reduced, run.yaml's"))
    rows = [e2e_row(R(name), label) for name, label in cases]
    out = table(["case, settings", "MART", "s: recon A + B + correlate", "RMS u / v / w (all)",
                 "off the axis band", "exact-particle volumes", "skipped, peak memory"], rows)
    out.append("")
    out += [R(n).provenance() + "  " for n, _ in cases]
    return out


VARIANT_LABELS = {
    "no_depth_margin": "no depth margin", "no_intensity_threshold": "no ghost floor",
    "intensity_threshold_4": "ghost floor 4", "final_smoothing_0": "no final smoothing",
    "depth_prefilter_0": "no depth prefilter", "depth_prefilter_4": "depth prefilter 4",
    "previous_default_3pass_window_mean": "32/50, 16/50, 16/75, window-mean predictor, unsmoothed",
    "centre_3pass": "32/50, 16/50, 16/75, centre predictor",
    "early_interpolation_cubic": "passes before the last deformed with Keys' cubic",
    "early_interpolation_sinc": "passes before the last deformed with the sinc",
    "spectral_whitening_0": "no spectral whitening (plain cross-correlation in every pass)",
    "spectral_whitening_0.5": "passes before the last whitened 1/2 (robust phase correlation)",
    "spectral_whitening_1": "passes before the last phase-only (whitening 1)",
    "final_peak_search_all_shifts": "last pass's peak searched over all shifts (FFT everywhere)",
    "final_peak_search_near_predictor": "last pass's peak at the predictor first (FFT where not)",
}


def t_e2e_variants(name):
    def make(R):
        r = R(name)
        rows = []
        for d in r.find(volumes="reconstructed"):
            if "rms" not in d or d.get("correlation") == "centre_3pass":  # bench_piv compares schedules
                continue
            key = "passes" if "passes" in d else "correlation"
            value = d[key]
            label = f"as the headline ({value})" if key == "passes" else VARIANT_LABELS.get(
                value, value.replace("_", " "))
            ex = next((e for e in r.find(volumes="exact") if e.get(key) == value), {})
            rows.append([label, f"{uvw(d)} ({d['rms']})", uvw(d, "off_axis_band_rms_"),
                         f"{uvw(ex)}" if ex else "—", d["correlate_s"]])
        out = table(["correlation of the same volumes (no depth context)", "RMS u / v / w (RMS)",
                     "off the axis band", "exact-particle volumes", "correlate s"], rows)
        return out + [""]  # the w-by-depth table that follows gives the run's provenance
    return make


MART_FLOOR_LABELS = {"paper_5_it_mu_0.5": "the paper's: 5 plain iterations at mu 0.5, no floor",
                     "8_acc_floor_3": "**8 accelerated, floor 3 (run-paper.yaml)**",
                     "20_acc": "20 accelerated, no floor",
                     "20_acc_floor_3": "**20 accelerated, floor 3 (process.yaml's MART; it takes two passes more)**",
                     "8_acc_floor_3_cut_0": "8 accelerated, floor 3, no prune cut (exact zeros only)",
                     "8_acc_floor_3_local_0": "8 accelerated, floor 3, no cut against the neighbourhood's peak",
                     "8_acc_floor_3_cut_0.03": "8 accelerated, floor 3, prune cut 3e-2 of the slice's peak",
                     "8_acc_floor_3_cut_0.1": "8 accelerated, floor 3, prune cut 1e-1 of the slice's peak"}


ISA_LABELS = {"avx2": "AVX2", "baseline": "baseline x86-64", "avx512": "AVX-512"}


def t_full_sweep(R):
    r = R("e2e-full-sweep")
    rows = []
    builds = {d["value"]: d for d in r.find(variant="isa")}
    for d in r.find(variant="mart_floor"):
        label = MART_FLOOR_LABELS.get(d["value"], d["value"].replace("_acc_floor_", " accelerated, floor "))
        if d["value"] in builds:
            b = builds[d["value"]]
            same = "the same vectors" if b["same_field_as_reference"] == "1" else "other vectors"
            label = (f"8 accelerated, floor 3 on the kernels' {ISA_LABELS[b['isa']]} build "
                     f"({float(b['over_reference']):.2f}x {ISA_LABELS[b['reference_isa']]}'s time, {same})")
        rows.append([label, d["total_s"], uvw(d), d["rms"], uvw(d, "off_axis_band_rms_"),
                     "**yes**" if d["pareto"] == "yes" else "no"])
    out = table(["MART (mu 1 unless stated), ghost floor", "s per pair", "RMS u / v / w", "RMS",
                 "off the axis band", "Pareto"], rows)
    return out + ["", r.provenance()]


SPARSE_LABELS = {"off": "off (every active voxel, every iteration)", "zeros": "exact zeros (default)"}


def t_sparse(R):
    rows = []
    for name, case in (("e2e-full-sparse", "paper"),
                       ("e2e-full-sparse-spread", "paper, particles' light spread 0.7 (log-normal)")):
        r = R(name)
        for d in r.find(variant="sparse"):
            prune = d["prune"]
            threshold, _, reach = prune.partition("-reach")
            threshold, _, local = threshold.partition("-local-")
            label = SPARSE_LABELS.get(prune, f"threshold {threshold[6:]} of its depth slice's peak"
                                      if prune.startswith("slice-") else f"threshold {prune} of the peak")
            if reach:
                label += f", kept within {reach} slices of one above it"
            if local:
                label += f", and {local} of its neighbourhood's peak"
            cpu = f"; CPU {d['pair_cpu_s']} ({float(d['cpu_over_off']):.2f})" if "pair_cpu_s" in d else ""
            rows.append([case, label, f"{d['pair_s']} ({float(d['pair_over_off']):.2f}){cpu}",
                         f"{d['recon_a_s']} + {d['recon_b_s']} + {d['correlate_s']}",
                         f"{pct(d['updates_skipped_a'])} / {pct(d['work_pruned_a'])}", d["volume_l2_vs_off"],
                         uvw(d), uvw(d, "off_axis_band_rms_"), "yes" if d["same_field_as_off"] == "1" else "no"])
    out = table(["case", "prune", "s per pair (over off): wall; CPU", "s: recon A + B + correlate",
                 "A: updates skipped / work pruned", "volume L2 vs off", "RMS u / v / w",
                 "off the axis band", "same vectors as off"], rows)
    return out + ["", R("e2e-full-sparse").provenance() + "  ", R("e2e-full-sparse-spread").provenance()]


def sensor_label(sensor):
    if sensor == "one_count_per_ray":
        return "one count per ray (the simulator's)"
    e, r, o = sensor.split(",")
    return f"{e} e per ray with shot noise, {r} e read noise, {o}-count pedestal"


def t_sensors(R):
    r = R("e2e-full-sensors")
    rows, head = [], None
    for d in r.lines:
        if d.get("bench") == "e2e" and "sensor" in d:
            head = d
        elif head and d.get("variant") == "reconstructed":
            taken = (f"taken off: {float(head['black_level_a']):g} / {float(head['black_level_b']):g}"
                     if head["black_level"] == "between_images" else "left on")
            lo, _, hi = head.get("black_level_a_range", "0..0").partition("..")
            if float(lo) != float(hi):
                taken += f" (A's {head['black_level_tiles']} tiles {float(lo):g} to {float(hi):g})"
            sensor = sensor_label(head["sensor"])
            if float(head.get("tap_offset", 0)) != 0:
                sensor += f"; right half {float(head['tap_offset']):g} counts higher (a second tap)"
            knobs = []
            if float(head["noise_threshold"]) > 0:
                knobs.append(f"noise_threshold {float(head['noise_threshold']):g}")
            if float(d["dark_cutoff"]) != 0.9:
                knobs.append(f"dark_weight_cutoff {float(d['dark_cutoff']):g}")
            rows.append([sensor, taken, ", ".join(knobs) or "run-paper.yaml's",
                         f"{uvw(d, 'off_axis_band_rms_')} ({uvw(d)})", d["off_axis_band_gain_w"],
                         pct(d["updates_skipped_a"]), f"{d['recon_a_s']} + {d['recon_b_s']} + {d['correlate_s']}"])
            head = None
    out = table(["sensor", "black level, counts (A / B)", "MART", "RMS u / v / w off the axis band (all)", "gain w",
                 "A: updates skipped", "s: recon A + B + correlate"], rows)
    return out + ["", r.provenance()]


KNOBS = [  # (variant, knob label, how a row's setting is named)
    ("paper", "paper's MART, default passes", lambda d: "5 it, mu 0.5"),
    ("iterations", "iterations at mu 0.5", lambda d: d["iterations"]),
    ("mu", "mu", lambda d: f"{float(d['mu']):g}, {d['iterations']} it"),
    ("acceleration", "accelerated at mu 1", lambda d: f"{d['iterations']} it"),
    ("no_depth_guard", "depth guard", lambda d: "none"),
    ("angular_sampling", "angular sampling", lambda d: d["value"].split(",")[0]),
    ("dark_cutoff", "dark cutoff", lambda d: d["value"]),
    ("noise_threshold", "noise floor, counts", lambda d: d["value"]),
    ("binning", "2x binning (windows 16/12/8)", lambda d: "0.25 mm voxels"),
    ("final_window", "final window", lambda d: f"{d['final_window']}³"),
    ("passes", "passes", lambda d: d["passes"]),
    ("intensity_threshold", "ghost floor, x the mean", lambda d: d["value"]),
    ("depth_prefilter", "depth prefilter passes", lambda d: d["value"]),
]


def t_reduced_sweep(R):
    r = R("e2e-reduced")
    rows = []
    for variant, label, name in KNOBS:
        cells = []
        for d in r.find(variant=variant):
            if "pareto" not in d:
                continue
            cell = f"{name(d)}: {d['rms']} ({d['total_s']} s)"
            if variant == "paper":
                cell += f"; u / v / w {uvw(d)}"
            cells.append(f"**{cell}**" if d["pareto"] == "yes" else cell)
        if cells:
            rows.append([label, " · ".join(cells)])
    out = table(["knob", "setting: RMS of u, v, w together (s per pair); bold: on the Pareto front"], rows)
    return out + ["", r.provenance()]


def t_e2e_depth(R):
    r = R("e2e-full")
    rows = []
    for volumes in ("reconstructed", "exact"):
        d = next((x for x in r.lines if x.get("volumes") == volumes and "rms_w_by_depth_mm" in x), None)
        if not d:
            continue
        bands = re.findall(r"(-?\w+)\.\.(-?\w+):([\d.]+)\((\d+),gain=([-\w.]+)", d["rms_w_by_depth_mm"])
        if not rows:
            rows.append(["z band, mm"] + [f"{lo}..{hi}".replace("inf", "∞") for lo, hi, *_ in bands])
            rows.append(["vectors"] + [b[3] for b in bands])
        rows.append([f"w RMS (gain), {volumes}"] + [f"{b[2]} ({b[4]})" for b in bands])
    if not rows:
        return [r.provenance()]
    out = table(rows[0], rows[1:])
    return out + ["", r.provenance()]


def t_recon_phases(R):
    cases = [("small camera, 60x60x200", R("recon-small")), ("paper camera, 300x200x200", R("recon-paper"))]

    def phase(r, name, key="seconds"):
        d = r.one(phase=name)
        return d.get(key, "—") if d else "—"

    def val(r, key):
        d = next((x for x in r.lines if key in x), None)
        return d[key] if d else "—"

    rows = [
        ["once per run: white image + weight tables and eq 13 normalisers, s",
         *[f"{phase(r, 'white_image')} + {phase(r, 'tables_and_normalisers')}" for _, r in cases]],
        ["setup: selection, active set, MLOS start, s", *[phase(r, "active_set_and_mlos") for _, r in cases]],
        ["per SMART iteration, s", *[phase(r, "iterations", "per_iteration") for _, r in cases]],
        ["**reconstruction, s wall (CPU s)**",
         *[f"**{phase(r, 'reconstruct_total')}** ({phase(r, 'reconstruct_total', 'cpu_s')})" for _, r in cases]],
        ["voxels skipped", *[pct(val(r, "skipped_fraction")) if r.exists else "—" for _, r in cases]],
        ["Q* / final residual", *[f"{val(r, 'quality_q_star')} / {phase(r, 'reconstruct_total', 'final_residual')}"
                                  for _, r in cases]],
        ["volume hash", *[f"`{phase(r, 'reconstruct_total', 'volume_hash')}`" for _, r in cases]],
        ["peak memory, GB", *[val(r, "peak_rss_gb") for _, r in cases]],
    ]
    reuse = {v: R("recon-paper").one(bench="recon_reuse", variant=v) for v in ("first", "reused", "fresh_again")}
    if reuse["first"]:
        rows.append(["paper: first frame / kept workspace (its third frame) / fresh again, s",
                     "", " / ".join(reuse[v]["seconds"] for v in reuse if reuse[v])])
    out = table(["5 SMART iterations at mu 0.5, MLOS start, cutoff 0.9, 0.5 ppm"] + [c for c, _ in cases], rows)
    return out + [""] + [r.provenance() + "  " for _, r in cases]


FIG22_PAPER = ["paper (its own fit)", "0.38", "0.066 / 0.80; 1.04 / 2.98", "", "", "", "30 min on 12 cores"]
FIG22_TARGET = ["target (#5), either fit", ">= 0.38", "X sd <= 0.4; Z sd <= 1.5", "", "", "", "<= 10 s"]


def t_fig22(R):
    rows = []
    for name, label in (("recon-fig22", "5 it, mu 0.5 (the paper's)"),
                        ("recon-fig22-accurate", "20 accelerated at mu 1, sensor blur 0.0052 mm")):
        r = R(name)
        if not r.exists:
            rows.append([label] + ["—"] * 6)
            continue
        q = next((x["quality_q_star"] for x in r.lines if "quality_q_star" in x), "?")
        fits = {d["fit"]: d for d in r.find(bench="recon_paper") if "fit" in d}
        total = r.one(phase="reconstruct_total")

        def xz(d, axis):
            return f"{d[f'abs_{axis}_err_vox_mean']} / {d[f'abs_{axis}_err_vox_sd']}"
        rows.append([label, q,
                     f"{xz(fits['peak_rows'], 'x')}; {xz(fits['peak_rows'], 'z')}",
                     xz(fits["moments"], "x"), xz(fits["moments"], "z"),
                     fits["moments"]["depth_error_slope_percent"] + " %", f"{total['seconds']}"])
    rows.append(FIG22_PAPER)
    rows.append(FIG22_TARGET)
    out = table(["500 particles, 300x200x200", "Q*", "peak rows: abs X; abs Z (mean / sd)",
                 "moments: abs X", "moments: abs Z", "depth slope", "reconstruction s"], rows)
    a, b = R("recon-fig22"), R("recon-fig22-accurate")
    if a.exists and b.exists and not a.meta.get("carried over") and all(
            a.meta.get(k) == b.meta.get(k) for k in ("commit", "machine")):
        m = a.meta
        return out + ["", f"*`{m['command']}` and `{b.meta['command']}` · {m.get('date', '?')} · commit "
                      f"{m['commit']} · {m['machine']} · load {m.get('load', '?').split(' (')[0]}*"]
    return out + ["", a.provenance() + "  ", b.provenance()]


def t_figures(R):
    r = R("recon-figures")
    fig21 = r.find(bench="recon_fig21")
    out = []
    if fig21:
        lateral = [f"{float(d.get('lateral_err_vox', 'nan')):.2f}" for d in fig21]
        rows = [["depth error, voxels"] + [f"{float(d.get('depth_err_vox', 'nan')):.2f}" for d in fig21]]
        if any(x != "0.00" for x in lateral):
            rows.append(["lateral error, voxels"] + lateral)
        out += table(["fig 21: z, mm"] + [f"{float(d['z_mm']):g}" for d in fig21], rows)
        out.append("")
        if len(rows) == 1:
            out[-1:] = ["", "Fig 21's lateral error is 0.00 voxel at every depth."]
    b = r.find(bench="recon_fig23b")
    c5 = [d for d in r.find(bench="recon_fig23c") if d["iterations"] == "5"]
    c20 = [d for d in r.find(bench="recon_fig23c") if d["iterations"] == "20"]
    note = ["Fig 23b, Q* after " + " / ".join(d["iterations"] for d in b) + " iterations (0.5 ppm): "
            + " / ".join(d["q_star"] for d in b) + "."]
    if out and out[-1].startswith("Fig 21's"):
        note = [out.pop() + " " + note[0]]
    out += note + [""]
    out += table(["fig 23c: ppm"] + [f"{float(d['ppm']):g}" for d in c5],
                 [["Q*, 5 it"] + [d["q_star"] for d in c5],
                  ["voxels skipped, 5 it"] + [pct(d["skipped"]) for d in c5],
                  ["Q*, 20 accelerated at mu 1, sensor blur"] + [d["q_star"] for d in c20]])
    return out + ["", r.provenance()]


def t_recon_mid(R):
    r = R("recon-mid")
    head = next((d for d in r.lines if "nonzeros" in d), None)
    parts = []
    for op in ("project", "back_project"):
        ex, mf = r.one(op=op, variant="explicit"), r.one(op=op, variant="matrix_free")
        if ex and mf:
            parts.append(f"{op.replace('_', '-')}ion {ex['median_s']} s explicit, {mf['median_s']} s matrix-free "
                         f"({mf['ratio']}x)")
    if not head:
        return [r.provenance()]
    return [f"32³ voxels on the small camera; the explicit CSR matrix holds {int(head['nonzeros']):,} non-zeros "
            f"({int(head['explicit_bytes']) / 1e9:.2f} GB, built in {head['build_s']} s on 1 thread): "
            + "; ".join(parts) + ".", "", r.provenance()]


def t_piv_uniform(name):
    def make(R):
        r = R(name)
        rows = []
        for d in r.find(bench="piv_uniform", prefilter="1", vectors="all"):
            if d["shift_voxel"] not in ("0.1", "0.3", "0.5", "1.0"):
                continue
            nopre = r.one(bench="piv_uniform", prefilter="0", vectors="all", shift_voxel=d["shift_voxel"]) or {}
            inner = r.one(bench="piv_uniform", prefilter="1", vectors="interior", shift_voxel=d["shift_voxel"]) or {}
            rows.append([d["shift_voxel"], uvw(d, "bias_", "xyz"), uvw(d, "rms_", "xyz"),
                         uvw(inner, "rms_", "xyz"), f"{nopre.get('bias_x', '?')} / {nopre.get('rms_x', '?')}"])
        vol = rows and r.find(bench="piv_uniform")[0]["volume"]
        out = table([f"shift (t, t, t), voxels ({vol})", "bias x / y / z", "RMS x / y / z",
                     "RMS, interior vectors", "no prefilter: bias x / RMS x"], rows)
        return out + [""]  # the ring table of the same run follows with the provenance
    return make


PIV_LABELS = {"default_4pass_2threads": "default, 2 threads", "default_4pass_1thread": "default, 1 thread",
              "previous_default_3pass_window_mean": "32/50, 16/50, 16/75, window-mean predictor, unsmoothed",
              "centre_3pass": "32/50, 16/50, 16/75", "centre_4pass_16_75": "32/50, 16/50, 16/75, 16/75",
              "centre_5pass": "32/50, 16/50, 16/75 x 3", "default_no_prefilter": "default without the prefilter",
              "default_fftw_measure": "default, FFTW_MEASURE plans", "single_pass_16": "one 16³@75 % pass",
              "window_mean_4pass": "default passes, window-mean predictor",
              "default_4pass_early_cubic": "default, passes before the last deformed with Keys' cubic"}


def t_piv_ring(name):
    def make(R):
        r = R(name)
        rows = []
        for d in r.find(bench="piv_ring"):
            rows.append([PIV_LABELS.get(d["variant"], d["variant"].replace("_", " ")), d["threads"], f"{d['seconds']} ({d['cpu_s']})",
                         d["cpu_ratio"], " / ".join(f"{float(d['rms_' + k]):.3f}" for k in "xyz"),
                         uvw(d, "off_axis_band_rms_"), d["outliers"], f"`{d['field_hash']}`"])
        vol = rows and r.find(bench="piv_ring")[0]["volume"]
        out = table([f"variant ({vol})", "threads", "s wall (CPU)", "CPU ratio", "RMS u / v / w",
                     "off the axis band", "outliers", "field hash"], rows)
        return out + ["", r.provenance()]
    return make


UNCERTAINTY_ROWS = [("exact", "uniform_noise", "exact, 96³: uniform shift, noise"),
                    ("exact", "paper_ring_off_axis_band", "exact, paper's ring, off the band"),
                    ("reconstructed", "uniform", "MART, small camera, 8 particle sets: uniform (2.32, 1.36, 2 voxels)"),
                    ("reconstructed", "uniform_depth_response", "the same through the depth response"),
                    ("reconstructed", "ring_off_axis_band", "MART, small camera, 8 sets: ring, off the band"),
                    ("reconstructed", "paper_ring_off_axis_band",
                     "MART, paper's ring (run-paper.yaml, depth response off), off the band"),
                    ("reconstructed", "paper_ring_off_axis_band_depth_response",
                     "the same through the depth response (run-paper.yaml as shipped)")]


def t_uncertainty(R):
    r = R("uncertainty")
    rows = []
    for kind, case, label in UNCERTAINTY_ROWS:
        per = {(d["band"], d["component"]): d for d in r.find(bench="uncertainty", kind=kind, case=case)
               if "band" in d}
        if not per:
            continue
        a = [per[("all", c)] for c in "uvw"]
        worst = [max((float(per[(b, c)]["ratio"]) for b in ("near", "middle", "far")),
                     key=lambda x: abs(x - 1)) for c in "uvw"]
        rows.append([label, " / ".join(d["rms_error"] for d in a), " / ".join(d["rms_sigma"] for d in a),
                     " / ".join(d["ratio"] for d in a), " / ".join(f"{x:.2f}" for x in worst),
                     " / ".join(d["within_1sigma"] for d in a), " / ".join(d["within_2sigma"] for d in a)])
    out = table(["volumes: case", "RMS error u / v / w", "RMS sigma", "sigma / error", "worst depth third",
                 "within 1 sigma (68 %)", "within 2 sigma (95 %)"], rows)
    return out + ["", r.provenance()]


def t_daemon(R):
    r = R("daemon")
    rows = [[d["variant"], d["voxels"], d["setup_s"], d["sustained_pairs_per_s"], d["ratio"],
             f"{d['paced_median_latency_s']} / {d['paced_max_latency_s']}",
             f"{d['paced_skipped']} of {int(d['paced_processed']) + int(d['paced_skipped'])}"]
            for d in r.find(bench="daemon_live")]
    out = table(["variant", "voxels", "setup s", "sustained pairs/s", "ratio",
                 "latency at 1 Hz, median / max s", "skipped at 1 Hz"], rows)
    return out + ["", r.provenance()]


def t_lanes(R):
    rows = []
    for r in (R("lanes"), R("lanes-paper")):
        rows += lane_rows(r)
    out = table(["variant", "processing nice", "pairs recorded", "raw frames lost", "live fields", "live dropped",
                 "live s/pair", "quality fields", "quality dropped", "quality s/pair", "RSS min / max GB"], rows)
    return out + ["", R("lanes").provenance() + "  ", R("lanes-paper").provenance()]


def lane_rows(r):
    return [[d["variant"], d.get("processing_nice", "0"), f"{d['recorded']} of {d['pairs']}", d["frames_lost"],
             f"{d['live_fields']} ({d['live_fields_per_s']}/s)", d["live_dropped"], d["live_mean_s"],
             f"{d['quality_fields']} ({d['quality_fields_per_s']}/s)", d["quality_dropped"], d["quality_mean_s"],
             f"{d['rss_min_gb']} / {d['rss_max_gb']}"]
            for d in r.find(bench="lanes")]


def t_live_tiers(R):
    r = R("e2e-full-live")
    full = r.one(variant="reconstructed")
    exact = r.one(variant="exact_volumes") or {}
    gains = lambda d: " / ".join(d.get(f"off_axis_band_gain_{c}", "?") for c in "uvw")
    # Each tier's volumes correlated again with the final peak over all shifts and at the predictor first.
    searches = {(e.get("tier"), e.get("final_peak_search")): e for e in r.find(variant="live_peak_search")}

    def search(d):
        every, near = (searches.get((d.get("tier"), k)) for k in ("all_shifts", "near_predictor"))
        return f"{uvw(every, 'off_axis_band_rms_')} -> {uvw(near, 'off_axis_band_rms_')}" if every and near else "—"

    rows = []
    if full:
        one_shot = sum(float(full[k]) for k in ("recon_a_s", "recon_b_s", "correlate_s"))
        rows.append(["the full settings (run-paper.yaml)", "0.125 x 0.125 x 0.25 mm, 1 x 1", full["iterations"],
                     RUN_PAPER_PASSES, f"{one_shot:.2f} (one-shot)", uvw(full),
                     uvw(full, "off_axis_band_rms_"), gains(full), uvw(exact, "off_axis_band_rms_") if exact else "—",
                     "—"])
    for d in r.find(variant="live"):
        b, k, n, p = d["binning"], d["pixel_binning"], d["iterations"], d["passes"]
        db = d.get("depth_binning", b)
        label = "**live (run-paper.yaml)**" if d.get("tier", f"{b},{k},{n},{p}") == RUN_PAPER_LIVE else "live"
        voxel = f"{0.125 * int(b):g}" + (f" x {0.125 * int(db):g}" if db != b else "") + " mm"
        prefilter = f", prefilter {d['depth_prefilter']}" if "depth_prefilter" in d else ""
        rows.append([label, f"{voxel}, {k} x {k}{prefilter}", n, p, f"{d['pair_s']} (first {d['first_pair_s']})",
                     uvw(d), uvw(d, "off_axis_band_rms_"), gains(d), uvw(d, "exact_off_axis_band_rms_"), search(d)])
    out = table(["tier", "voxel, pixel binning", "MART it", "passes", "s per pair in a run",
                 "RMS u / v / w, 0.125 mm voxels", "off the axis band", "gain u / v / w (off the band)",
                 "exact particles on its grid (off the band)",
                 "its volumes again: final peak over all shifts -> at the predictor first (off the band)"], rows)
    return out + ["", r.provenance()]


def sigma_ratios(r, d):
    """The rotated shear's per-vector sigma over its RMS error, for the row of tier and variant in d."""
    s = [e for e in r.find(bench="rotated_shear_sigma") if e.get("tier") == d["tier"] and
         e.get("variant") == d.get("variant")]
    return " / ".join(s[0]["ratio_" + c] for c in "uvw") if s else "—"


def t_rotated_shear(R):
    voxel = lambda d: (f"{float(d['voxel_mm']):g}" + (f" x {float(d['voxel_z_mm']):g}" if d.get("voxel_z_mm", d["voxel_mm"])
                                                        != d["voxel_mm"] else "") + " mm")
    rows, provenance = [], []
    for r in (R("rotated-shear"), R("rotated-shear-paper-accuracy")):
        if not r.exists:
            continue
        rows += [[f"{d.get('config', 'run-paper.yaml')}'s {d['tier']}"
                  + (", w through the depth response" if d.get("variant") == "depth_response"
                     else ", depth response off" if d["tier"] == "full" else ""),
                  f"{voxel(d)}, {d['pixel_binning']} x {d['pixel_binning']}, {d['iterations']} it",
                  f"{d['pair_s']} (first {d['first_s']})", uvw(d), uvw(d, "bias_"), f"{d['gain_u']} / {d['gain_w']}",
                  sigma_ratios(r, d)] for d in r.find(bench="rotated_shear") if "tier" in d]
        provenance.append(r.provenance() + "  ")
    out = table(["tier", "voxel, pixel binning, MART", "s per pair in a run", "RMS u / v / w, 0.125 mm voxels",
                 "bias u / v / w", "gain u / w", "sigma / error u / v / w"], rows)
    return out + [""] + provenance


def t_recording(R):
    r = R("recording")
    rows = [[d["variant"], f"{d['rate_hz']} Hz", f"{d.get('data_dir', '/dev/shm')} ({d.get('write', 'buffered')})",
             d["mb_per_pair"], d["wall_s_per_pair"], d["cpu_s_per_pair"],
             d["cores"], d["faults_per_pair"], d["buffers_reused"]] for d in r.find(bench="recording")]
    out = table(["frames", "rate", "folder (writes)", "MB per pair", "wall s per pair", "CPU s per pair", "cores",
                 "page faults per pair", "buffers reused"], rows)
    ratio = r.one(bench="recording_ratio")
    if ratio:
        out += ["", f"Pooled over fresh: CPU x{ratio['pooled_over_fresh_cpu']}."]
    return out + ["", r.provenance()]


def t_soak(R):
    r = R("soak")
    rows = [[f"{d['pairs']} at {d['rate_hz']} Hz", d["run_s"], d["recorded"], d["frames_lost"], d["live_fields"],
             f"{d['pace_first_hz']} / {d['pace_last_hz']}",
             f"{float(d['rss_first_gb']) * 1024:.0f} / {float(d['rss_last_gb']) * 1024:.0f} / "
             f"{float(d['rss_max_gb']) * 1024:.0f}",
             f"{d['fds_first']} / {d['fds_last']} / {d['fds_max']}",
             f"{d['threads_first']} / {d['threads_last']} / {d['threads_max']}"]
            for d in r.find(bench="soak")]
    out = table(["pairs", "s", "recorded", "raw frames lost", "live fields", "recorded per s, early / late",
                 "RSS MB, early / late / max", "open fds", "threads"], rows)
    return out + ["", r.provenance()]


def t_sim(R):
    r = R("sim")
    rows = []
    over = {d["threads"]: d for d in r.find(bench="sim_frame_overhead")}
    if over:
        rows.append(["frame without particles (clear, convert 16 Mpx)",
                     " / ".join(f"{over[t]['median_s']} ({over[t]['cpu_s']})" for t in sorted(over)), "", "", ""])
    for variant in ("no_diffraction", "diffraction_5.2um"):
        runs = {d["threads"]: d for d in r.find(bench="sim_rays", variant=variant)}
        if "2" not in runs:
            continue
        d = runs["2"]
        rows.append([f"{int(d['rays']):.1e} rays, {variant.replace('_', ' ')}",
                     " / ".join(f"{runs[t]['median_s']} ({runs[t]['cpu_s']})" for t in sorted(runs)),
                     d["mrays_per_s"], d["tracing_mrays_per_s"], d["speedup_vs_1_thread"]])
    for d in r.find(bench="sim_paper_image"):
        rows.append([f"paper image: 0.5 ppm, {int(d['rays']):.2e} rays, diffraction",
                     f"2 threads: {d['seconds']} ({d['cpu_s']})", d["mrays_per_s"], "", ""])
    out = table(["run (paper camera)", "s wall (CPU), 1 / 2 threads", "Mrays/s, 2 threads",
                 "tracing alone", "speed-up"], rows)
    return out + ["", r.provenance()]

def t_calib(R):
    r = R("calib")
    rows = []
    for stage in ("calibrate", "white_correction", "total"):
        cells = []
        for threads in ("1", "2"):
            d = r.one(bench="calib", stage=stage, threads=threads)
            cells.append(f"{d['median_s']} ({d['cpu_s']})" if d else "—")
        rows.append([stage.replace("_", " ")] + cells)
    fit = r.one(bench="calib", stage="calibrate") or {}
    out = table([f"stage ({fit.get('lenses_measured', '?')} lenses measured, residual "
                 f"{fit.get('rms_residual_px', '?')} px)", "1 thread: s wall (CPU)", "2 threads: s wall (CPU)"], rows)
    return out + ["", r.provenance()]


def t_resampling(R):
    r = R("resampling")
    cams = ("camera-small", "camera-fahringer2015")
    rows = []
    for deg in sorted({d["rotation_deg"] for d in r.find(bench="resampling")}, key=float):
        row = [deg]
        for cam in cams:
            d = r.one(bench="resampling", camera=cam, rotation_deg=deg)
            row.append(f"{d['max_departure_px']} px; {d['setup_s']} s; {d['frame_median_s']} s" if d else "—")
        rows.append(row)
    out = table(["rotation, deg", "camera-small (850x850): departure; setup; per frame",
                 "paper camera (4904x3280): departure; setup; per frame"], rows)
    return out + ["", r.provenance()]


TABLES = {
    "headline": t_headline,
    "e2e-cases": t_e2e_cases,
    "e2e-full-variants": t_e2e_variants("e2e-full"),
    "e2e-full-sweep": t_full_sweep,
    "e2e-sparse": t_sparse,
    "e2e-sensors": t_sensors,
    "e2e-full-depth": t_e2e_depth,
    "e2e-reduced-sweep": t_reduced_sweep,
    "recon-phases": t_recon_phases,
    "recon-fig22": t_fig22,
    "recon-figures": t_figures,
    "recon-mid": t_recon_mid,
    "piv-uniform": t_piv_uniform("piv"),
    "piv-ring": t_piv_ring("piv"),
    "uncertainty": t_uncertainty,
    "daemon": t_daemon,
    "lanes": t_lanes,
    "live-tiers": t_live_tiers,
    "rotated-shear": t_rotated_shear,
    "soak": t_soak,
    "recording": t_recording,
    "sim": t_sim,
    "calib": t_calib,
    "resampling": t_resampling,
}


def regenerate():
    cache = {}

    def R(name):
        if name not in cache:
            cache[name] = Result(name)
        return cache[name]

    pattern = re.compile(r"(<!-- generated: ([\w-]+) -->\n)(.*?)(<!-- end: \2 -->)", re.S)
    seen = set()
    texts = {}
    for doc in DOCS:

        def replace(m, doc=doc):
            name = m.group(2)
            if name not in TABLES:
                sys.exit(f"bench_tables: {doc.relative_to(ROOT)} asks for table '{name}', which this script lacks")
            seen.add(name)
            return m.group(1) + "\n".join(TABLES[name](R)) + "\n" + m.group(4)

        texts[doc] = pattern.sub(replace, doc.read_text())
    missing = set(TABLES) - seen
    if missing:
        sys.exit(f"bench_tables: no markers in {', '.join(str(d.relative_to(ROOT)) for d in DOCS)} for "
                 f"{', '.join(sorted(missing))}")
    for doc, text in texts.items():
        doc.write_text(text)
    for name, (_, _, plot) in BENCHES.items():
        path = RESULTS / f"{name}.txt"
        text = path.read_text() if path.exists() else ""
        script, marker = PLOTTERS.get(plot, ("bench/plot_e2e.py", "pareto="))
        if plot and marker in text and "# carried over:" not in text:
            subprocess.run(["/usr/bin/python3", script, f"docs/{plot}"], cwd=ROOT, check=True, input=text, text=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--run", nargs="+", metavar="NAME", help="quick, paper, all, or result names")
    parser.add_argument("--list", action="store_true", help="list the results and their commands")
    args = parser.parse_args()
    if args.list:
        for name, (scale, command, _) in BENCHES.items():
            print(f"{name:22} {scale:6} {' '.join(command)}")
        return
    if args.run:
        names = []
        for item in args.run:
            if item in ("quick", "paper", "all"):
                names += [n for n, b in BENCHES.items() if item in ("all", b[0])]
            elif item in BENCHES:
                names.append(item)
            else:
                sys.exit(f"bench_tables: no result named '{item}' (see --list)")
        build(names)
        for name in names:
            run(name)
    regenerate()


if __name__ == "__main__":
    main()
