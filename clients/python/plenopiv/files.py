"""plenopiv's files as xarray Datasets: vector files, volume files and run folders (the one reader), and the
vector file layout written from a Dataset (the live subscriber's --save)."""
import builtins
import json
import os
import re
import socket
import time

import h5py
import numpy as np
import xarray as xr

# HDF5 bookkeeping attributes of dimension scales (h5py/HDF5 high-level library), not metadata.
_HDF5_INTERNAL_ATTRIBUTES = {"CLASS", "NAME", "DIMENSION_LIST", "REFERENCE_LIST", "_Netcdf4Dimid"}

# What plenopiv's writer (core/io/hdf5_files.cpp) puts on the group holding 3-D arrays.
AXIS_ORDER = "z, y, x: arrays are [nz][ny][nx] (C order, x fastest; MATLAB shows them x, y, z)"
AXES = "x right, y down on the sensor, z away from the camera along the optical axis; mm; z = 0 the nominal focal plane"

# The run folder's manifest and, while it records, the journal of what was added since
# (proto/run_folder.hpp), and a pair's file stem.
MANIFEST = "manifest.json"
JOURNAL = "journal.jsonl"
_PAIR_FILE = re.compile(r"^pair-(\d+)\.h5$")


class FileError(ValueError):
    """A file or folder that is not what plenopiv writes; the message names it and what is wrong."""


def _text(value):
    """An HDF5 attribute or scalar string dataset as Python: bytes decoded, numpy scalars unwrapped."""
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    if isinstance(value, np.ndarray) and value.dtype.kind == "S":
        return [v.decode("utf-8", errors="replace") for v in value.ravel()]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray) and value.size == 1 and value.dtype.kind in "fiub":
        return value.item()  # dt_s: one value stored as a 1-element array
    return value


def _attributes(obj):
    return {k: _text(v) for k, v in obj.attrs.items() if k not in _HDF5_INTERNAL_ATTRIBUTES}


def _dimension_names(path, dataset):
    """The names of the dimension scales attached to each dimension of `dataset`."""
    names = []
    for axis, dim in enumerate(dataset.dims):
        if len(dim) == 0:
            raise FileError("%s: %s has no dimension scale on axis %d (not a plenopiv file)"
                            % (path, dataset.name, axis))
        names.append(os.path.basename(dim[0].name))
    return tuple(names)


def _flag_legend(legend):
    """CF flag attributes from a plenopiv flag legend, "bits: 1 meaning; 2 meaning; ...; 0 meaning": the
    bit values (flag_masks), their meanings as CF words (flag_meanings), and the meaning of 0."""
    text = legend[len("bits:"):] if legend.startswith("bits:") else legend
    masks, meanings, zero = [], [], None
    for entry in text.split(";"):
        match = re.match(r"^\s*(\d+)\s+(.+?)\s*$", entry)
        if not match:
            raise FileError("flag legend entry %r is not '<bit> <meaning>'" % entry)
        bit, meaning = int(match.group(1)), match.group(2)
        if bit == 0:
            zero = meaning
        else:
            masks.append(bit)
            meanings.append(re.sub(r"[^A-Za-z0-9]+", "_", meaning).strip("_"))
    return masks, meanings, zero


def _read_group(path, group):
    """Every dataset of `group` as a Dataset: the dimension scales as coordinates, the rest as data
    variables on the scales attached to them, each with its attributes (units, long_name, legend)."""
    scales, variables = {}, {}
    for name, item in group.items():
        if not isinstance(item, h5py.Dataset):
            continue
        if h5py.h5ds.is_scale(item.id):
            scales[name] = xr.Variable((name,), item[()], _attributes(item))
        else:
            variables[name] = item
    if not variables:
        raise FileError("%s: %s holds no data arrays" % (path, group.name))
    data_vars = {}
    for name, item in variables.items():
        if item.dtype.kind in "SO" and item.shape == ():
            continue  # a text dataset (a long provenance entry): metadata, not data
        attrs = _attributes(item)
        if "legend" in attrs:
            masks, meanings, zero = _flag_legend(attrs["legend"])
            attrs["flag_masks"] = np.array(masks, dtype=item.dtype)
            attrs["flag_meanings"] = " ".join(meanings)
            if zero is not None:
                attrs["flag_zero_meaning"] = zero
        data_vars[name] = xr.Variable(_dimension_names(path, item), item[()], attrs)
    return xr.Dataset(data_vars, coords=scales, attrs=_attributes(group))


def _provenance(path, file):
    """/provenance as attributes provenance_<entry> (attributes and long entries kept as text datasets)."""
    if "provenance" not in file:
        return {}
    group = file["provenance"]
    entries = _attributes(group)
    for name, item in group.items():
        if isinstance(item, h5py.Dataset):
            entries[name] = _text(item[()])
    return {"provenance_" + k: v for k, v in entries.items()}


def open_file(path):
    """A plenopiv HDF5 file: a vector field (/vectors, as process, correlate, the daemon and the live
    subscriber write it, statistics.h5 too) or a volume (/volume, reconstruct)."""
    try:
        file = h5py.File(path, "r")
    except OSError as e:
        raise FileError("%s: not an HDF5 file (%s)" % (path, e)) from None
    with file:
        if "vectors" in file:
            ds = _read_group(path, file["vectors"])
            ds.attrs["kind"] = "vectors"
        elif "volume" in file:
            ds = _read_group(path, file)
            ds.attrs["kind"] = "volume"
        else:
            raise FileError("%s: neither /vectors nor /volume (not a plenopiv vector field or volume file)" % path)
        ds.attrs.update(_provenance(path, file))
    ds.attrs["source"] = os.path.abspath(path)
    return ds


def read_manifest(run_dir):
    """The run folder's manifest.json as a dict (msg::RunManifest's .proto field names: run_id, pairs, ...)."""
    path = os.path.join(run_dir, MANIFEST)
    try:
        with builtins.open(path, encoding="utf-8") as f:  # this module defines its own open
            manifest = json.load(f)
    except (OSError, ValueError) as e:
        raise FileError("%s: cannot read the run manifest (%s)" % (path, e)) from None
    if not isinstance(manifest, dict) or "run_id" not in manifest:
        raise FileError("%s: not a run manifest (no run_id)" % path)
    journal = os.path.join(run_dir, JOURNAL)
    if manifest.get("state") == "recording" and os.path.exists(journal):
        _apply_journal(manifest, journal)
    return manifest


def _apply_journal(manifest, path):
    """A recording run's journal (one msg::ManifestJournalEntry per line) applied to its manifest, as
    run_folder::read_manifest does: a pair line adds a pair or its new fields to the listed one, a
    drop or warning line is appended. A last line without its newline (cut short by a crash) lists
    nothing."""
    with builtins.open(path, encoding="utf-8") as f:
        text = f.read()
    pairs = manifest.setdefault("pairs", [])
    listed = {int(p.get("pair_index", 0)): p for p in pairs}
    for number, line in enumerate(text.split("\n")[:-1], start=1):
        try:
            entry = json.loads(line)
            if not isinstance(entry, dict):
                raise ValueError("not an object")
        except ValueError as e:
            raise FileError("%s: line %d: not a journal entry (%s)" % (path, number, e)) from None
        if "pair" in entry:
            pair = entry["pair"]
            index = int(pair.get("pair_index", 0))
            if index in listed:
                listed[index].update({k: v for k, v in pair.items() if v not in ("", 0, None)})
            else:
                listed[index] = dict(pair)
                pairs.append(listed[index])
        elif "drop" in entry:
            manifest.setdefault("dropped", []).append(entry["drop"])
        elif "warning" in entry and entry["warning"] not in manifest.setdefault("warnings", []):
            manifest["warnings"].append(entry["warning"])


def _manifest_attributes(manifest):
    """The manifest's scalar entries as attributes run_<name> (losses as run_losses_<name>, warnings
    joined one per line); the per-pair lists become coordinates instead."""
    attrs = {}
    for key, value in manifest.items():
        name = "run_" + key
        if isinstance(value, (str, int, float, bool)):
            attrs[name] = value
        elif key == "losses":
            attrs.update({name + "_" + k: v for k, v in value.items()})
        elif key == "warnings":
            attrs[name] = "\n".join(value)
    return attrs


def _stack(fields, pair_indices, run_dir):
    """Fields of one run on one grid, stacked along a `pair` dimension."""
    first = fields[0]
    for f, pair in zip(fields[1:], pair_indices[1:]):
        for axis in "xyz":
            if f[axis].shape != first[axis].shape or not np.array_equal(f[axis].values, first[axis].values):
                raise FileError("%s: pair %d's %s axis differs from pair %d's: not one grid"
                                % (run_dir, pair, axis, pair_indices[0]))
    per_pair = [f.drop_vars(list(f.coords)) for f in fields]
    stacked = xr.concat([f.assign_attrs({}) for f in per_pair], dim="pair", data_vars="all",
                        combine_attrs="override")
    stacked.attrs = {}
    stacked = stacked.assign_coords(pair=("pair", np.asarray(pair_indices, dtype=np.uint64)),
                                    **{a: first[a] for a in "xyz"})
    stacked["dt_s"] = ("pair", np.array([f.attrs["dt_s"] for f in fields], dtype=np.float64),
                       {"units": "s", "long_name": "pulse separation the velocities were computed with"})
    # The attributes every file shares (axes, settings, software, run); per-pair ones (pair index,
    # frames, time written) are left out.
    stacked.attrs.update({k: v for k, v in first.attrs.items() if k not in ("source", "dt_s")
                          and all(k in f.attrs and np.array_equal(f.attrs[k], v) for f in fields[1:])})
    stacked.attrs["files"] = "\n".join(f.attrs["source"] for f in fields)
    return stacked


# A run folder's tiers (daemon/lanes.hpp): the manifest entry naming each pair's vector file.
TIERS = {"full": "vectors", "live": "live_vectors"}


def open_run(run_dir, tier="full"):
    """A run folder (its vector files of `tier`: "full", the run's full settings, or "live", the live
    lane's fast tier) or a reprocessed output folder (pair-<n>.h5 from `plenopiv process --run`),
    stacked along `pair`, with the run manifest's entries as attributes and each pair's frame A time
    (host clock) as coordinate `time` when a manifest is there."""
    if tier not in TIERS:
        raise ValueError("tier: %r is not one of %s" % (tier, ", ".join(sorted(TIERS))))
    manifest_dir = None
    if os.path.exists(os.path.join(run_dir, MANIFEST)):
        manifest_dir = run_dir
    elif os.path.exists(os.path.join(run_dir, os.pardir, MANIFEST)):
        manifest_dir = os.path.normpath(os.path.join(run_dir, os.pardir))
    manifest = read_manifest(manifest_dir) if manifest_dir else None
    listed = {int(p.get("pair_index", 0)): p for p in manifest.get("pairs", [])} if manifest else {}

    files = {}
    if manifest_dir == run_dir:
        for index, pair in listed.items():
            if pair.get(TIERS[tier]):
                files[index] = os.path.join(run_dir, pair[TIERS[tier]])
        others = [t for t, key in sorted(TIERS.items()) if t != tier and any(p.get(key) for p in listed.values())]
        what = "%s-tier vector fields in its manifest (%s)" % (
            tier, "it has %s-tier ones: tier=%r" % (others[0], others[0]) if others
            else "the daemon processed none: reprocess with plenopiv process --run")
    else:
        for name in os.listdir(run_dir):
            match = _PAIR_FILE.match(name)
            if match:
                files[int(match.group(1))] = os.path.join(run_dir, name)
        what = "pair-<n>.h5 files (not a run folder: no %s)" % MANIFEST
    if not files:
        raise FileError("%s: no %s" % (run_dir, what))
    pairs = sorted(files)
    ds = _stack([open_file(files[p]) for p in pairs], pairs, run_dir)
    if manifest:
        ds.attrs.update(_manifest_attributes(manifest))
        times = [int(listed[p].get("host_timestamp_a_ns", 0)) if p in listed else 0 for p in pairs]
        if all(times):
            ds = ds.assign_coords(time=("pair", np.array(times, dtype="datetime64[ns]")))
        measured = [float(listed[p].get("measured_dt_s", 0.0)) if p in listed else 0.0 for p in pairs]
        ds["measured_dt_s"] = ("pair", np.array(measured),
                               {"units": "s", "long_name": "laser pulse separation measured for the pair; 0: not measured"})
    ds.attrs["kind"] = "run"
    if manifest_dir == run_dir:
        ds.attrs["tier"] = tier
    ds.attrs["source"] = os.path.abspath(run_dir)
    return ds


def open(path, tier="full"):  # noqa: A001 (the package's entry point: plenopiv.open)
    """Opens what plenopiv writes as an xarray.Dataset:
    - a vector file (pair-<n>.h5, process -o, correlate, statistics.h5): every array of /vectors on
      coordinates z, y, x (mm) from the file's dimension scales, attributes units and long_name,
      flags with CF flag_masks / flag_meanings from their legend; dt_s, axis_order, axes and the
      file's provenance (provenance_<entry>) as attributes;
    - a volume file (reconstruct): `volume` on z, y, x (mm) likewise;
    - a run folder (run-<id>/) or a reprocessed folder (<run>/reprocessed): its vector files stacked
      along `pair` (coordinate: pair index; dt_s and, with a manifest, time and measured_dt_s per
      pair), the manifest's entries as attributes run_<name>; of a run folder, the fields of `tier`
      ("full": the run's settings, vectors/; "live": the live lane's fast tier, vectors/live/).
    FileError naming the file when it is none of these."""
    path = os.fspath(path)
    if os.path.isdir(path):
        return open_run(path, tier)
    if not os.path.exists(path):
        raise FileError("%s: no such file or folder" % path)
    return open_file(path)


def flags(ds, name="flags"):
    """The bits of a flags variable as one boolean variable per meaning (from its flag_masks and
    flag_meanings), on the same dimensions."""
    if name not in ds:
        raise FileError("%s: no %s variable (files written without flags, or the live subscriber's)"
                        % (ds.attrs.get("source", "dataset"), name))
    var = ds[name]
    masks, meanings = var.attrs["flag_masks"], var.attrs["flag_meanings"].split()
    return xr.Dataset({meaning: (var & mask) != 0 for mask, meaning in zip(masks, meanings)})


def _write_text(obj, name, value):
    """A text attribute as plenopiv's writer stores it (fixed-length ASCII string)."""
    obj.attrs.create(name, np.bytes_(value.encode("utf-8")))


def write_vector_file(path, ds, provenance):
    """Writes the vector field `ds` (data variables on z, y, x; attributes dt_s, origin_mm, spacing_mm) in the layout of plenopiv's
    vector files (core/io/hdf5_files.cpp): /vectors with the dimension scales x, y, z (mm), each array
    with units and long_name, `valid` as uint8, attributes dt_s, origin_mm, spacing_mm, axis_order,
    axes, sigma_method (with sigma); /provenance with software, host, written_utc and `provenance`
    (name -> text). Written under a temporary name and renamed."""
    tmp = path + ".tmp"
    with h5py.File(tmp, "w") as f:
        group = f.create_group("vectors")
        for axis in "xyz":
            scale = group.create_dataset(axis, data=np.asarray(ds[axis].values, dtype=np.float64))
            scale.make_scale(axis)
            _write_text(scale, "units", "mm")
        _write_text(group, "axis_order", AXIS_ORDER)
        _write_text(group, "axes", AXES)
        for name, var in ds.data_vars.items():
            if var.dims != ("z", "y", "x"):
                raise FileError("%s: %s is on %s, not (z, y, x)" % (path, name, var.dims))
            data = var.values.astype(np.uint8) if name == "valid" else var.values
            dataset = group.create_dataset(name, data=data)
            for key in ("units", "long_name", "legend"):
                if key in var.attrs:
                    _write_text(dataset, key, str(var.attrs[key]))
            for dim, axis in enumerate("zyx"):
                dataset.dims[dim].attach_scale(group[axis])
        for name in ("dt_s", "origin_mm", "spacing_mm"):
            group.attrs.create(name, np.atleast_1d(np.asarray(ds.attrs[name], dtype=np.float64)))
        # What sigma holds: a file's own attribute, or a published message's header field.
        sigma_method = ds.attrs.get("sigma_method") or ds.attrs.get("header_sigma_method")
        if sigma_method and "sigma_u" in ds.data_vars:
            _write_text(group, "sigma_method", str(sigma_method))
        p = f.create_group("provenance")
        from . import __version__
        _write_text(p, "software", "plenopiv-python %s" % __version__)
        _write_text(p, "host", socket.gethostname())
        _write_text(p, "written_utc", time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))
        for key, value in provenance.items():
            _write_text(p, key, str(value))
    os.replace(tmp, path)
