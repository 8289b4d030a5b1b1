"""What the Python package's tests share: the built plenopiv programs, real files made with them, and the
installed package (never the source tree)."""
import os
import shutil
import socket
import subprocess
import tempfile
import unittest

import plenopiv

BIN_DIR = os.environ["PLENOPIV_BIN_DIR"]
SOURCE_DIR = os.environ["PLENOPIV_SOURCE_DIR"]
PACKAGE_DIR = os.environ["PLENOPIV_PACKAGE_DIR"]  # the venv the package was installed into
CAMERA_FILE = os.path.join(SOURCE_DIR, "systemd", "config", "camera-small.yaml")

# A small box on camera-small.yaml, as the C++ tests' small runs (tests/support/recorded_run.cpp):
# seconds per pair.
SMALL_SETTINGS = ("dt_s: 0.001\n"
                  "volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [-0.5, 0.5], voxel_mm: 0.125}\n"
                  "reconstruction: {iterations: 2, start: ones, dark_weight_cutoff: 0.99}\n"
                  "correlation: {passes: [{window: 8, overlap_percent: 50}]}\n")
SMALL_SIM_URI = "sim://?seed=3&ppm=0.2&rays=500&dx_mm=0.25&flow_dt_us=1000"


def binary(name):
    return os.path.join(BIN_DIR, name)


def run(argv, timeout=300, **kwargs):
    """Runs a command; its combined output; an AssertionError with the output when it fails."""
    done = subprocess.run(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=timeout,
                          **kwargs)
    if done.returncode != 0:
        raise AssertionError("%s exited %d:\n%s" % (" ".join(argv), done.returncode, done.stdout))
    return done.stdout


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def scratch(name):
    """A fresh folder for one test module, removed at exit unless PLENOPIV_KEEP_TEST_FILES is set."""
    path = tempfile.mkdtemp(prefix="plenopiv-python-%s-" % name)
    if not os.environ.get("PLENOPIV_KEEP_TEST_FILES"):
        import atexit
        atexit.register(shutil.rmtree, path, True)
    return path


def is_png(path):
    with open(path, "rb") as f:
        return f.read(8) == b"\x89PNG\r\n\x1a\n"


class InstalledPackageTest(unittest.TestCase):
    def test_the_package_is_the_installed_one_with_its_generated_messages(self):
        self.assertTrue(os.path.realpath(plenopiv.__file__).startswith(os.path.realpath(PACKAGE_DIR)),
                        plenopiv.__file__)
        from plenopiv import plenopiv_pb2
        self.assertIn("VectorFieldHeader", plenopiv_pb2.DESCRIPTOR.message_types_by_name)
        for script in ("plenopiv-subscribe", "plenopiv-plot"):
            self.assertTrue(os.access(os.path.join(PACKAGE_DIR, "bin", script), os.X_OK), script)
