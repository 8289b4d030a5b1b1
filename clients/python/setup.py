"""Builds plenopiv/plenopiv_pb2.py from proto/plenopiv.proto with protoc while the package is built (the
rest of the package is declared in pyproject.toml)."""
import os
import shutil
import subprocess

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = os.path.dirname(os.path.abspath(__file__))
# The .proto: PLENOPIV_PROTO_DIR, else the repository's proto/ (this folder is clients/python).
PROTO_DIR = os.path.abspath(os.environ.get("PLENOPIV_PROTO_DIR", os.path.join(HERE, os.pardir, os.pardir, "proto")))


class BuildWithMessages(build_py):
    """build_py, then protoc --python_out into the built package."""

    def run(self):
        super().run()
        proto = os.path.join(PROTO_DIR, "plenopiv.proto")
        if not os.path.isfile(proto):
            raise SystemExit("plenopiv: %s not found: build from the plenopiv source tree, or set "
                             "PLENOPIV_PROTO_DIR to the folder holding plenopiv.proto" % proto)
        protoc = shutil.which("protoc")
        if protoc is None:
            raise SystemExit("plenopiv: protoc not found: apt-get install protobuf-compiler")
        out = os.path.join(self.build_lib, "plenopiv")
        os.makedirs(out, exist_ok=True)
        subprocess.run([protoc, "--python_out=" + out, "-I", PROTO_DIR, proto], check=True)


setup(cmdclass={"build_py": BuildWithMessages})
