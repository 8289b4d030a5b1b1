"""Subscribe to plenopivd's published vector fields: print a line per field, save each as a vector file, plot.

python3 -m plenopiv.subscribe [--publish tcp://127.0.0.1:5556] [--count N] [--save DIR] [--plot FILE.png] [--show]
"""
import argparse
import os
import sys

import zmq

from . import plot as plotting
from .files import write_vector_file
from .messages import MessageError, decode_vectors

# When an interactive window was asked for and no display is there: where the plot goes instead.
DEFAULT_PNG = "plenopiv-live.png"


def summary(ds):
    return ("pair %6d  mean %.4f m/s  max %.4f m/s  valid %.1f %%  latency %.3f s  tier %s  run %s"
            % (ds.attrs["header_pair_index"], ds.attrs["header_mean_speed_m_s"], ds.attrs["header_max_speed_m_s"],
               100.0 * ds.attrs["header_valid_fraction"], ds.attrs["header_latency_s"],
               ds.attrs.get("header_tier") or "?", ds.attrs["header_run_id"]))


def save(directory, ds, endpoint):
    """DIR/pair-<n>.h5 (the full settings' field) or DIR/live/pair-<n>.h5 (the live tier's: a run with
    two lanes publishes both for a pair), as the run folder keeps them, in the layout of its vector
    files (the published arrays), with the header's fields as provenance. Returns the path."""
    pair = ds.attrs["header_pair_index"]
    if ds.attrs.get("header_tier") == "live":
        directory = os.path.join(directory, "live")
        os.makedirs(directory, exist_ok=True)
    path = os.path.join(directory, "pair-%06d.h5" % pair)
    provenance = {"source": "live: published by plenopivd on %s, topic vectors" % endpoint,
                  "run": ds.attrs["header_run_id"], "pair_index": pair, "dt_s": repr(ds.attrs["dt_s"]),
                  "dt_source": "as published (VectorFieldHeader.dt_s)"}
    provenance.update({k[len("header_"):]: v for k, v in ds.attrs.items()
                       if k.startswith("header_") and k[len("header_"):] not in provenance
                       and k != "header_run_id"})
    write_vector_file(path, ds, provenance)
    return path


class LiveView:
    """The newest field's middle z slice: written to a PNG (Agg) and/or shown in a window."""

    def __init__(self, png, show):
        import matplotlib
        self.png, self.window = png, None
        if show:
            if plotting.has_display():
                import matplotlib.pyplot as plt
                plt.ion()
                self.plt = plt
                self.window = plt.figure(figsize=(7, 6), layout="constrained")
            else:
                self.png = self.png or DEFAULT_PNG
                print("plenopiv.subscribe: --show: no display (DISPLAY and WAYLAND_DISPLAY are unset): "
                      "writing the plot to %s instead" % os.path.abspath(self.png), file=sys.stderr, flush=True)
        if self.window is None:
            matplotlib.use("Agg")
        self.written = None  # the pair last written to the PNG

    def show(self, ds):
        if self.png:
            plotting.write_png(ds, self.png)
            if self.written is None:
                print("plenopiv.subscribe: plotting each field to %s" % os.path.abspath(self.png), flush=True)
            self.written = ds.attrs["header_pair_index"]
        if self.window is not None:
            self.window.clear()
            ax = self.window.add_subplot()
            mesh, label = plotting.draw(ax, ds)
            self.window.colorbar(mesh, ax=ax, label=label)
            self.plt.pause(0.01)

    def close(self):
        if self.written is not None:
            print("plenopiv.subscribe: plot of pair %d in %s" % (self.written, os.path.abspath(self.png)), flush=True)


def main(argv=None):
    p = argparse.ArgumentParser(prog="plenopiv-subscribe", description=__doc__.splitlines()[0])
    p.add_argument("--publish", default="tcp://127.0.0.1:5556", help="plenopivd's publishing endpoint")
    p.add_argument("--count", type=int, default=0, help="exit after this many fields (0: never)")
    p.add_argument("--wait", type=float, default=10.0, help="seconds without a field before giving up (exit 3)")
    p.add_argument("--save", metavar="DIR",
                   help="write every field to DIR/pair-<n>.h5, laid out as the run folder's vector files")
    p.add_argument("--plot", metavar="FILE.png", help="write the newest field's middle z slice to this PNG")
    p.add_argument("--show", action="store_true",
                   help="show the slice in a window (without a display: says so and writes the PNG instead)")
    p.add_argument("--server-key", metavar="FILE.key",
                   help="plenopivd's public certificate, when its publishing uses CURVE (curve: publish: true)")
    p.add_argument("--client-cert", metavar="FILE.key_secret",
                   help="this subscriber's secret certificate (`plenopiv keys`), admitted by the daemon")
    args = p.parse_args(argv)
    if bool(args.server_key) != bool(args.client_cert):
        p.error("CURVE needs both --server-key and --client-cert")
    if args.save:
        os.makedirs(args.save, exist_ok=True)

    context = zmq.Context()
    sub = context.socket(zmq.SUB)
    sub.setsockopt(zmq.LINGER, 0)
    sub.setsockopt(zmq.RCVTIMEO, int(args.wait * 1000))
    sub.setsockopt(zmq.SUBSCRIBE, b"vectors")
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
    print("plenopiv.subscribe: subscribed to %s, topic vectors" % args.publish, flush=True)

    view = LiveView(args.plot, args.show) if args.plot or args.show else None
    received, status = 0, 0
    try:
        while args.count == 0 or received < args.count:
            try:
                frames = sub.recv_multipart()
            except zmq.Again:
                print("plenopiv.subscribe: no vector field on %s within %g s" % (args.publish, args.wait),
                      file=sys.stderr)
                status = 3
                break
            try:
                ds = decode_vectors(frames)
            except MessageError as e:
                print("plenopiv.subscribe: ignored a message: %s" % e, file=sys.stderr)
                continue
            received += 1
            print(summary(ds), flush=True)
            if args.save:
                save(args.save, ds, args.publish)
            if view is not None:
                view.show(ds)
    except KeyboardInterrupt:
        pass
    finally:
        if view is not None:
            view.close()
        sub.close()
        context.term()
    return status


if __name__ == "__main__":
    sys.exit(main())
