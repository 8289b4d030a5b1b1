"""A vector field's z slice as a PNG (matplotlib, Agg): in-plane vectors over a diverging colour map of
vorticity_z (or w, when the field has no vorticity); python3 -m plenopiv.plot FILE -o slice.png."""
import argparse
import os
import sys

import numpy as np

# Flag bits of a replaced vector (core/piv/peak_fit.hpp: second peak, third peak, neighbour mean).
REPLACED_BITS = 8 | 16 | 32


def has_display():
    """Whether an interactive window can open: an X11 or Wayland display is named."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _nice(value):
    """A round number (1, 2 or 5 times a power of ten) near `value` > 0: the reference vector's length."""
    exponent = np.floor(np.log10(value))
    mantissa = value / 10 ** exponent
    return float((1 if mantissa < 2 else 2 if mantissa < 5 else 5) * 10 ** exponent)


def draw(ax, ds, z_index=None):
    """Draws the slice z_index (default the middle one) of the vector field `ds` (plenopiv.open's or the
    subscriber's Dataset) on `ax`; returns the colour mesh (for a colour bar) and its label."""
    nz = ds.sizes["z"]
    k = nz // 2 if z_index is None else z_index
    if not 0 <= k < nz:
        raise ValueError("z index %d outside 0..%d" % (k, nz - 1))
    s = ds.isel(z=k)
    x, y = s["x"].values, s["y"].values
    background = "vorticity_z" if "vorticity_z" in s else "w"
    c = s[background].values
    limit = float(np.nanmax(np.abs(c))) if np.isfinite(c).any() else 0.0
    limit = limit if limit > 0 else 1.0
    mesh = ax.pcolormesh(x, y, c, shading="nearest", cmap="RdBu_r", vmin=-limit, vmax=limit)
    label = "%s (%s)" % (background.replace("vorticity_z", "vorticity z").replace("w", "w, out of plane"),
                         s[background].attrs.get("units", "?"))
    valid = s["valid"].values > 0 if "valid" in s else np.ones(c.shape, dtype=bool)
    X, Y = np.meshgrid(x, y)
    u, v = s["u"].values, s["v"].values
    speed = np.hypot(u, v)[valid]
    reference = _nice(float(np.nanmax(speed))) if speed.size and np.nanmax(speed) > 0 else 1.0
    arrows = ax.quiver(X[valid], Y[valid], u[valid], v[valid], angles="xy", pivot="middle", color="k",
                       scale=reference * max(len(x), len(y)) * 1.2, scale_units="width")
    ax.quiverkey(arrows, 0.9, -0.09, reference, "%g m/s" % reference, labelpos="W", coordinates="axes")
    if (~valid).any():
        ax.plot(X[~valid], Y[~valid], "x", color="0.4", markersize=5, label="no vector")
    if "flags" in s:
        replaced = (s["flags"].values & REPLACED_BITS) != 0
        if replaced.any():
            ax.plot(X[replaced], Y[replaced], "o", markerfacecolor="none", markeredgecolor="darkorange",
                    markersize=8, label="replaced vector")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="lower left", fontsize="small", framealpha=0.8)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_xlim(x[0] - 0.5 * (x[1] - x[0] if len(x) > 1 else 1), x[-1] + 0.5 * (x[1] - x[0] if len(x) > 1 else 1))
    ax.set_ylim(y[0] - 0.5 * (y[1] - y[0] if len(y) > 1 else 1), y[-1] + 0.5 * (y[1] - y[0] if len(y) > 1 else 1))
    ax.invert_yaxis()  # y down, as the upright image shows it
    ax.set_aspect("equal")
    run = ds.attrs.get("header_run_id") or ds.attrs.get("provenance_run") or ""
    pair = ds.attrs.get("header_pair_index", ds.attrs.get("provenance_pair_index", ""))
    title = "z = %.2f mm" % float(s["z"])
    if run != "" or pair != "":
        title = "run %s, pair %s, %s" % (run, pair, title)
    ax.set_title(title, loc="left", fontsize="medium")
    return mesh, label


def write_png(ds, path, z_index=None):
    """The slice as a PNG at `path` (Agg; written under a temporary name and renamed)."""
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    fig = Figure(figsize=(7, 6), layout="constrained")
    ax = fig.add_subplot()
    mesh, label = draw(ax, ds, z_index)
    fig.colorbar(mesh, ax=ax, label=label)
    tmp = path + ".tmp.png"
    fig.savefig(tmp, dpi=100)
    os.replace(tmp, path)


def main(argv=None):
    from .files import FileError, open as open_file
    p = argparse.ArgumentParser(prog="plenopiv-plot", description=__doc__.splitlines()[0])
    p.add_argument("file", help="a vector file (pair-<n>.h5, process -o) or a run folder")
    p.add_argument("-o", "--output", required=True, metavar="FILE.png", help="the PNG to write")
    p.add_argument("--pair", type=int, help="with a run folder: the pair index (default: the first)")
    p.add_argument("--z-index", type=int, help="the z slice (default: the middle one)")
    args = p.parse_args(argv)
    try:
        ds = open_file(args.file)
    except FileError as e:
        print("plenopiv-plot: %s" % e, file=sys.stderr)
        return 2
    if ds.attrs.get("kind") == "volume":
        print("plenopiv-plot: %s is a volume, not a vector field" % args.file, file=sys.stderr)
        return 2
    if "pair" in ds.dims:
        pair = int(ds["pair"][0]) if args.pair is None else args.pair
        if pair not in ds["pair"].values:
            print("plenopiv-plot: %s has no pair %d (it has %s)" % (args.file, pair, list(ds["pair"].values)),
                  file=sys.stderr)
            return 2
        ds = ds.sel(pair=pair).assign_attrs(provenance_pair_index=pair, provenance_run=ds.attrs.get("run_run_id", ""))
    try:
        write_png(ds, args.output, args.z_index)
    except ValueError as e:
        print("plenopiv-plot: %s" % e, file=sys.stderr)
        return 2
    print("plenopiv-plot: wrote %s" % os.path.abspath(args.output))
    return 0


if __name__ == "__main__":
    sys.exit(main())
