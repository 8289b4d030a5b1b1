"""plenopiv's Python side: open vector fields, volumes and run folders as xarray Datasets, subscribe to a
live plenopivd (python3 -m plenopiv.subscribe) and plot a field (python3 -m plenopiv.plot)."""

__version__ = "0.1.0"

from .files import FileError, flags, open  # noqa: E402 (after the version, which files.py reads)

__all__ = ["FileError", "flags", "open", "__version__"]
