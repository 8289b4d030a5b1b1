"""python3 -m plenopiv.subscribe against a real plenopivd on the simulated camera: the saved fields are the
run folder's, in its layout; --plot writes a PNG and says where; --show without a display says so and writes
the PNG; plenopiv.open reads the run folder and its reprocessed folder (`plenopiv process --run`)."""
import os
import signal
import subprocess
import sys
import time
import unittest

import h5py
import numpy as np

import plenopiv
from support import (CAMERA_FILE, SMALL_SETTINGS, SMALL_SIM_URI, InstalledPackageTest, PACKAGE_DIR,  # noqa: F401
                     SOURCE_DIR, binary, free_port, is_png, run, scratch)

PAIRS = 3
WORK = scratch("subscribe")
CONTROL = "ipc://" + os.path.join(WORK, "control")
PUBLISH = "tcp://127.0.0.1:%d" % free_port()
# The live path takes the newest pair and may skip some (they stay on disk): the subscriber saves
# what was published, and the test compares it with the vector files the manifest lists.
RUN_YAML = "pairs: %d\nrate_hz: 1\n" % PAIRS + SMALL_SETTINGS


def client(*args, timeout=30):
    return run([binary("plenopiv"), "--endpoint", CONTROL, "--timeout", "5"] + list(args), timeout=timeout)


def wait_until(condition, seconds, what):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.2)
    raise AssertionError("gave up waiting %g s for %s" % (seconds, what))


def start(argv, log, **kwargs):
    """Starts a subscriber with its output (stdout and stderr) going to the file `log`."""
    with open(log, "w") as f:
        return subprocess.Popen(argv, stdout=f, stderr=subprocess.STDOUT, text=True, **kwargs)


def wait_for_text(process, log, text):
    """Waits until the process has written `text` to its log (its start-up: imports take seconds)."""
    def written():
        if process.poll() is not None:
            raise AssertionError("the subscriber ended (exit %d) before printing %r: %s"
                                 % (process.returncode, text, open(log).read()))
        return text in open(log).read()
    wait_until(written, 120, text)


class Session:
    """plenopivd on the simulated camera, two subscribers, one run of PAIRS pairs, then the daemon stopped."""

    def __init__(self):
        self.data = os.path.join(WORK, "data")
        self.saved = os.path.join(WORK, "saved")
        self.png = os.path.join(WORK, "view.png")
        self.headless = os.path.join(WORK, "headless")
        os.makedirs(self.headless)
        daemon_log = open(os.path.join(WORK, "plenopivd.log"), "w")
        self.daemon = subprocess.Popen(
            [binary("plenopivd"), "--config", os.path.join(SOURCE_DIR, "systemd", "config", "plenopivd.yaml"),
             "--control", CONTROL, "--publish", PUBLISH, "--data-dir", self.data, "--camera-file", CAMERA_FILE,
             "--camera", SMALL_SIM_URI, "--simulation"],
            stdout=daemon_log, stderr=subprocess.STDOUT)
        try:
            self._run()
        finally:
            self.daemon.terminate()
            self.daemon_status = self.daemon.wait(30)
            daemon_log.close()

    def _answers(self):
        if self.daemon.poll() is not None:
            raise AssertionError("plenopivd exited %d: %s" % (self.daemon.returncode,
                                                              open(os.path.join(WORK, "plenopivd.log")).read()))
        try:
            client("status")
            return True
        except AssertionError:
            return False

    def _run(self):
        wait_until(self._answers, 60, "plenopivd to answer")
        # The console entry point, saving and plotting; and `python -m` asked for a window with no display.
        saver_log, shower_log = os.path.join(WORK, "saver.log"), os.path.join(WORK, "shower.log")
        self.saver = start(
            [os.path.join(PACKAGE_DIR, "bin", "plenopiv-subscribe"), "--publish", PUBLISH, "--wait", "300",
             "--save", self.saved, "--plot", self.png], saver_log)
        env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
        self.shower = start(
            [sys.executable, "-m", "plenopiv.subscribe", "--publish", PUBLISH, "--count", "1", "--wait", "120",
             "--show"], shower_log, cwd=self.headless, env=env)
        for subscriber, log in ((self.saver, saver_log), (self.shower, shower_log)):
            wait_for_text(subscriber, log, "plenopiv.subscribe: subscribed to " + PUBLISH)
        time.sleep(0.5)  # the subscriptions reach the publisher (PUB/SUB joins late)
        config = os.path.join(WORK, "run.yaml")
        with open(config, "w") as f:
            f.write(RUN_YAML)
        self.started = client("run", "start", "--config", config, timeout=120)
        self.shower.wait(300)
        self.shower_output = open(shower_log).read()
        wait_until(lambda: "Idle" in client("status").splitlines()[0], 300, "the run to end")
        # Every field is published before the run ends; the saver runs until interrupted (Ctrl-C).
        time.sleep(2)
        self.saver.send_signal(signal.SIGINT)
        self.saver.wait(60)
        self.saver_output = open(saver_log).read()
        runs = [d for d in os.listdir(self.data) if d.startswith("run-")]
        assert len(runs) == 1, runs
        self.run_dir = os.path.join(self.data, runs[0])
        self.manifest = plenopiv.files.read_manifest(self.run_dir)
        # The pairs the live path processed (and published).
        self.processed = [p["pair_index"] for p in self.manifest["pairs"] if p.get("vectors")]
        assert self.processed, "the live path processed no pair"


class LiveSubscriber(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.s = Session()

    def test_the_subscriber_printed_every_field_and_said_where_the_plot_is(self):
        self.assertEqual(self.s.saver.returncode, 0, self.s.saver_output)
        for i in self.s.processed:
            self.assertIn("pair %6d  mean " % i, self.s.saver_output)
        self.assertIn("plotting each field to %s" % os.path.abspath(self.s.png), self.s.saver_output)
        self.assertIn("plot of pair %d in %s" % (self.s.processed[-1], os.path.abspath(self.s.png)),
                      self.s.saver_output)
        self.assertTrue(is_png(self.s.png))
        self.assertFalse(os.path.exists(self.s.png + ".tmp.png"))

    def test_a_window_without_a_display_is_refused_aloud_and_the_png_written_instead(self):
        self.assertEqual(self.s.shower.returncode, 0, self.s.shower_output)
        png = os.path.join(self.s.headless, "plenopiv-live.png")
        self.assertIn("no display", self.s.shower_output)
        self.assertIn("writing the plot to %s instead" % png, self.s.shower_output)
        self.assertTrue(is_png(png))

    def test_the_run_folder_opens_as_pairs_with_the_manifest(self):
        ds = plenopiv.open(self.s.run_dir)
        self.assertEqual(ds.attrs["kind"], "run")
        self.assertEqual(len(self.s.manifest["pairs"]), PAIRS)
        self.assertEqual(list(ds.pair.values), self.s.processed)
        self.assertEqual(ds.u.dims, ("pair", "z", "y", "x"))
        self.assertEqual(ds.u.attrs["units"], "m/s")
        self.assertTrue({"dx", "u", "valid", "peak_ratio", "vorticity_z", "flags"} <= set(ds.data_vars))
        self.assertEqual(ds.attrs["run_state"], "complete")
        self.assertEqual("run-" + ds.attrs["run_run_id"], os.path.basename(self.s.run_dir))
        self.assertEqual(ds.attrs["run_camera_uri"], SMALL_SIM_URI)
        self.assertEqual(ds.attrs["provenance_run"], ds.attrs["run_run_id"])
        self.assertIn("voxel_mm: 0.125", ds.attrs["provenance_settings"])
        self.assertEqual(ds.time.dtype, np.dtype("datetime64[ns]"))
        self.assertTrue(bool((ds.time.diff("pair") > np.timedelta64(0, "ns")).all()))
        # Each file's dt is the pair's measured one (the sim trigger measures its pulses) or the run's.
        expected_dt = [m if m > 0 else ds.attrs["run_nominal_dt_s"] for m in ds.measured_dt_s.values]
        np.testing.assert_array_equal(ds.dt_s.values, expected_dt)
        # Each pair's velocity is its displacement over its own dt.
        np.testing.assert_allclose(ds.u, ds.dx * 1e-3 / ds.dt_s, rtol=1e-6)
        for i in self.s.processed:
            with h5py.File(os.path.join(self.s.run_dir, "vectors", "pair-%06d.h5" % i), "r") as f:
                np.testing.assert_array_equal(ds.u.sel(pair=i).values, f["vectors/u"][()])

    def test_saved_fields_are_the_recorded_ones_in_the_run_folder_s_layout(self):
        live = plenopiv.open(self.s.run_dir)
        saved = plenopiv.open(self.s.saved)
        self.assertEqual(sorted(os.listdir(self.s.saved)), ["pair-%06d.h5" % i for i in self.s.processed])
        self.assertEqual(list(saved.pair.values), list(live.pair.values))
        # The published arrays: the velocity, its standard uncertainty (the correlation's default) and valid.
        published = {"u", "v", "w", "sigma_u", "sigma_v", "sigma_w", "valid"}
        self.assertEqual(set(saved.data_vars) - {"dt_s"}, published)
        for name in sorted(published):
            self.assertEqual(saved[name].dtype, live[name].dtype, name)
            np.testing.assert_allclose(saved[name].values, live[name].values, rtol=1e-6, atol=0, err_msg=name)
            self.assertEqual(saved[name].attrs["units"], live[name].attrs["units"], name)
            self.assertEqual(saved[name].attrs["long_name"], live[name].attrs["long_name"], name)
        for a in "xyz":
            np.testing.assert_allclose(saved[a].values, live[a].values, rtol=0, atol=1e-9)
        for key in ("axis_order", "axes", "sigma_method"):
            self.assertEqual(saved.attrs[key], live.attrs[key])
        self.assertIn("correlation statistics of the final pass", live.attrs["sigma_method"])
        np.testing.assert_array_equal(saved.dt_s.values, live.dt_s.values)
        self.assertEqual(saved.attrs["provenance_run"], live.attrs["run_run_id"])
        # The same HDF5 layout as the daemon's file of the same pair.
        name = "pair-%06d.h5" % self.s.processed[0]
        with h5py.File(os.path.join(self.s.saved, name), "r") as mine, \
                h5py.File(os.path.join(self.s.run_dir, "vectors", name), "r") as theirs:
            self.assertEqual(set(mine), set(theirs))
            self.assertEqual(set(mine["vectors"].attrs), set(theirs["vectors"].attrs))
            self.assertLessEqual(set(mine["vectors"]), set(theirs["vectors"]))
            for key in ("origin_mm", "spacing_mm", "dt_s"):
                np.testing.assert_allclose(mine["vectors"].attrs[key], theirs["vectors"].attrs[key])
            self.assertEqual(mine["provenance"].attrs["pair_index"], theirs["provenance"].attrs["pair_index"])

    def test_the_reprocessed_run_opens_beside_the_live_one(self):
        out = run([binary("plenopiv"), "process", "--run", self.s.run_dir], timeout=600)
        self.assertIn("series.pvd", out)
        reprocessed = plenopiv.open(os.path.join(self.s.run_dir, "reprocessed"))
        live = plenopiv.open(self.s.run_dir)
        # Every recorded pair, the ones the live path skipped too.
        self.assertEqual(list(reprocessed.pair.values), list(range(PAIRS)))
        self.assertEqual(reprocessed.attrs["run_run_id"], live.attrs["run_run_id"])  # the parent's manifest
        reprocessed = reprocessed.sel(pair=live.pair.values)
        np.testing.assert_array_equal(reprocessed.time.values, live.time.values)
        # The same settings, frames and dt: the same fields (docs/daemon.md, "Run folder").
        for name in ("dx", "dy", "dz", "valid", "flags"):
            np.testing.assert_array_equal(reprocessed[name].values, live[name].values, err_msg=name)

    def test_the_daemon_stopped_cleanly(self):
        self.assertIn("started", self.s.started)
        self.assertEqual(self.s.daemon_status, 0)


if __name__ == "__main__":
    unittest.main(verbosity=2)
