#!/usr/bin/python3
"""Subscribe to plenopivd's published vector fields: print, plot live, or save to HDF5.

Run with Debian's /usr/bin/python3 (python3-zmq, python3-protobuf, python3-numpy, python3-h5py,
python3-matplotlib). plenopiv_pb2.py is generated at build time into build/python/ (protoc
--python_out); set PLENOPIV_PB2_DIR to use another folder.
"""
import argparse
import os
import sys
import time

import numpy as np
import zmq

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.environ.get("PLENOPIV_PB2_DIR",
                                  os.path.join(HERE, "..", "..", "build", "python")))
try:
    import plenopiv_pb2  # noqa: E402
except ImportError as e:
    sys.exit("plenopiv_subscribe: plenopiv_pb2 not found (%s); build the project first "
             "(it is generated into build/python/) or set PLENOPIV_PB2_DIR" % e)


class VectorField:
    """One published field: header plus u, v, w (m/s) and valid as [nz][ny][nx] numpy arrays."""

    def __init__(self, header, arrays):
        self.header = header
        self.arrays = arrays

    @property
    def shape_zyx(self):
        nx, ny, nz = self.header.shape
        return (nz, ny, nx)

    def axis_mm(self, axis):
        n = self.header.shape[axis]
        return self.header.origin_mm[axis] + self.header.spacing_mm[axis] * np.arange(n)


def decode_vectors(frames):
    """frames: [topic, header, payload...] as bytes. Returns a VectorField."""
    if len(frames) < 2 or frames[0] != b"vectors":
        raise ValueError("not a vectors message")
    header = plenopiv_pb2.VectorFieldHeader()
    header.ParseFromString(frames[1])
    nx, ny, nz = header.shape
    if len(frames) - 2 != len(header.payloads):
        raise ValueError("header names %d payloads, message has %d"
                         % (len(header.payloads), len(frames) - 2))
    arrays = {}
    for name, data in zip(header.payloads, frames[2:]):
        a = np.frombuffer(data, dtype="<f4")
        if a.size != nx * ny * nz:
            raise ValueError("payload %s has %d values, shape %s wants %d"
                             % (name, a.size, (nx, ny, nz), nx * ny * nz))
        arrays[name] = a.reshape(nz, ny, nx)
    return VectorField(header, arrays)


def summary(f):
    h = f.header
    return ("pair %6d  mean %.4f m/s  max %.4f m/s  valid %.1f %%  latency %.3f s  tier %s  run %s"
            % (h.pair_index, h.mean_speed_m_s, h.max_speed_m_s, 100.0 * h.valid_fraction,
               h.latency_s, h.tier or "?", h.run_id))


# Units of the published arrays, as plenopiv's HDF5 files give them (`units` attribute).
UNITS = {"u": "m/s", "v": "m/s", "w": "m/s", "dx": "mm", "dy": "mm", "dz": "mm",
         "vorticity_x": "1/s", "vorticity_y": "1/s", "vorticity_z": "1/s"}


def save(h5, f):
    """Appends one field as group /pair-<n> (the full settings' field) or /pair-<n>-live (the live
    tier's: a run with two lanes publishes both for a pair) in the layout of plenopiv's vector
    files: the arrays [nz][ny][nx] with `units`, the axes x, y, z (mm) attached as dimension scales,
    attribute dt_s, and a provenance subgroup (run, pair, tier, host timestamp, latency)."""
    h = f.header
    g = h5.create_group("pair-%06d%s" % (h.pair_index, "-live" if h.tier == "live" else ""))
    for axis, name in enumerate("xyz"):
        scale = g.create_dataset(name, data=f.axis_mm(axis))
        scale.make_scale(name)
        scale.attrs["units"] = "mm"
    for name, a in f.arrays.items():
        ds = g.create_dataset(name, data=a.astype(np.uint8) if name == "valid" else a)
        ds.attrs["units"] = UNITS.get(name, "1")
        for dim, axis in enumerate("zyx"):
            ds.dims[dim].attach_scale(g[axis])
    g.attrs["dt_s"] = h.dt_s
    g.attrs["axis_order"] = "z, y, x: arrays are [nz][ny][nx] (C order, x fastest)"
    p = g.create_group("provenance")
    p.attrs["software"] = "plenopiv_subscribe.py (live, from plenopivd)"
    p.attrs["run"] = h.run_id
    p.attrs["pair_index"] = str(h.pair_index)
    p.attrs["tier"] = h.tier
    p.attrs["host_timestamp_ns"] = str(h.host_timestamp_ns)
    p.attrs["latency_s"] = str(h.latency_s)
    h5.flush()


class LivePlot:
    """Quiver of (u, v) on the middle z slice over the out-of-plane vorticity dv/dx - du/dy."""

    def __init__(self, png):
        import matplotlib
        if png or not os.environ.get("DISPLAY"):
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        self.plt = plt
        self.png = png
        self.fig, self.ax = plt.subplots(figsize=(7, 6))
        self.colorbar = None
        if not png:
            plt.ion()

    def show(self, f):
        k = f.shape_zyx[0] // 2
        u, v = f.arrays["u"][k], f.arrays["v"][k]
        valid = f.arrays.get("valid", np.ones_like(u))[k] > 0
        x, y = f.axis_mm(0), f.axis_mm(1)
        dx = f.header.spacing_mm[0] * 1e-3
        dy = f.header.spacing_mm[1] * 1e-3
        dvdx = np.gradient(v, dx, axis=1) if u.shape[1] > 1 else np.zeros_like(v)
        dudy = np.gradient(u, dy, axis=0) if u.shape[0] > 1 else np.zeros_like(u)
        vort = dvdx - dudy
        self.ax.clear()
        mesh = self.ax.pcolormesh(x, y, vort, shading="nearest", cmap="RdBu_r")
        X, Y = np.meshgrid(x, y)
        self.ax.quiver(X[valid], Y[valid], u[valid], v[valid])
        self.ax.set_xlabel("x (mm)")
        self.ax.set_ylabel("y (mm)")
        self.ax.invert_yaxis()  # y down, as the upright image shows it
        self.ax.set_aspect("equal")
        z = f.axis_mm(2)[k]
        self.ax.set_title("run %s pair %d, z = %.2f mm" % (f.header.run_id, f.header.pair_index, z))
        if self.colorbar is None:
            self.colorbar = self.fig.colorbar(mesh, ax=self.ax, label="vorticity (1/s)")
        else:
            self.colorbar.update_normal(mesh)
        if self.png:
            self.fig.savefig(self.png, dpi=100)
        else:
            self.plt.pause(0.01)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--publish", default="tcp://127.0.0.1:5556", help="plenopivd publishing endpoint")
    p.add_argument("--count", type=int, default=0, help="exit after this many fields (0: never)")
    p.add_argument("--wait", type=float, default=10.0,
                   help="seconds without a field before giving up (exit 3)")
    p.add_argument("--save", metavar="FILE.h5", help="append every field to this HDF5 file")
    p.add_argument("--plot", action="store_true", help="live matplotlib view of the middle z slice")
    p.add_argument("--png", metavar="FILE.png", help="with --plot: write the view here (headless)")
    p.add_argument("--server-key", metavar="FILE.key",
                   help="plenopivd's public certificate, when its publishing uses CURVE (curve: publish: true)")
    p.add_argument("--client-cert", metavar="FILE.key_secret",
                   help="this subscriber's secret certificate (`plenopiv keys`), admitted by the daemon")
    args = p.parse_args(argv)

    context = zmq.Context()
    sub = context.socket(zmq.SUB)
    sub.setsockopt(zmq.LINGER, 0)
    sub.setsockopt(zmq.RCVTIMEO, int(args.wait * 1000))
    sub.setsockopt(zmq.SUBSCRIBE, b"vectors")
    if bool(args.server_key) != bool(args.client_cert):
        p.error("CURVE needs both --server-key and --client-cert")
    if args.server_key:
        from zmq import auth  # the certificate files `plenopiv keys` writes are zmq.auth's format
        server_public, _ = auth.load_certificate(args.server_key)
        client_public, client_secret = auth.load_certificate(args.client_cert)
        if client_secret is None:
            p.error(args.client_cert + ": holds no secret key: give the .key_secret file")
        sub.curve_serverkey = server_public
        sub.curve_publickey = client_public
        sub.curve_secretkey = client_secret
    sub.connect(args.publish)

    h5 = None
    if args.save:
        import h5py
        # Written under a temporary name and renamed when complete (or interrupted).
        tmp = args.save + ".tmp"
        h5 = h5py.File(tmp, "w")
    plot = LivePlot(args.png) if args.plot or args.png else None
    received = 0
    status = 0
    try:
        while args.count == 0 or received < args.count:
            try:
                frames = sub.recv_multipart()
            except zmq.Again:
                print("plenopiv_subscribe: no vector field on %s within %g s" % (args.publish, args.wait),
                      file=sys.stderr)
                status = 3
                break
            try:
                f = decode_vectors(frames)
            except ValueError as e:
                print("plenopiv_subscribe: ignored a message: %s" % e, file=sys.stderr)
                continue
            received += 1
            print(summary(f), flush=True)
            if h5 is not None:
                save(h5, f)
            if plot is not None:
                plot.show(f)
    except KeyboardInterrupt:
        pass
    finally:
        if h5 is not None:
            h5.close()
            os.replace(args.save + ".tmp", args.save)
        sub.close()
        context.term()
    return status


if __name__ == "__main__":
    sys.exit(main())
