"""plenopiv.open on real files written by the C++ tools (a simulated pair processed with `plenopiv process`, a
volume from `plenopiv reconstruct`), checked against the files as h5py reads them; plenopiv-plot on the field;
bad input named."""
import json
import os
import re
import unittest

import h5py
import numpy as np

import plenopiv
from plenopiv.files import write_vector_file
from support import (CAMERA_FILE, SMALL_SETTINGS, InstalledPackageTest, PACKAGE_DIR, binary, is_png, run,  # noqa: F401
                     scratch)

WORK = scratch("open")


def make_files():
    """A simulated pair (uniform 0.25 mm along x) processed to v.h5 (+ .vti, .png); frame A reconstructed
    to volume.h5."""
    pair = os.path.join(WORK, "pair")
    run([binary("plenopiv"), "simulate", "pair", "--camera", CAMERA_FILE, "--seed", "7", "--ppm", "0.2", "--box",
         "-1,1,-1,1,-0.5,0.5", "--uniform", "0.25,0,0", "--rays", "500", "-o", pair])
    settings = os.path.join(WORK, "process.yaml")
    with open(settings, "w") as f:
        f.write(SMALL_SETTINGS)
    frames = [os.path.join(pair, "frame_A.tif"), os.path.join(pair, "frame_B.tif")]
    run([binary("plenopiv"), "process", "--camera", CAMERA_FILE] + frames +
        ["-c", settings, "--nominal", "-o", os.path.join(WORK, "v.h5")])
    run([binary("plenopiv"), "reconstruct", "--camera", CAMERA_FILE, frames[0], "--extent", "-1", "1", "-1", "1",
         "-0.5", "0.5", "--voxel", "0.125", "--iterations", "2", "-o", os.path.join(WORK, "volume.h5")])


def h5_arrays(group):
    """Every dataset of an HDF5 group that is not a dimension scale: name -> (array, units)."""
    return {name: (item[()], item.attrs["units"].decode()) for name, item in group.items()
            if isinstance(item, h5py.Dataset) and not h5py.h5ds.is_scale(item.id)}


class OpenVectorFile(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.path = os.path.join(WORK, "v.h5")
        cls.ds = plenopiv.open(cls.path)

    def test_every_array_of_the_file_is_a_variable_on_z_y_x_with_its_units(self):
        with h5py.File(self.path, "r") as f:
            arrays = h5_arrays(f["vectors"])
            axes = {a: f["vectors"][a][()] for a in "xyz"}
            dt_s = float(f["vectors"].attrs["dt_s"][0])
        self.assertEqual(set(self.ds.data_vars), set(arrays))
        # What process writes today, at least (more may be added, none renamed).
        self.assertTrue({"dx", "dy", "dz", "u", "v", "w", "valid", "peak_ratio", "vorticity_z", "flags"}
                        <= set(self.ds.data_vars), list(self.ds.data_vars))
        for name, (values, units) in arrays.items():
            var = self.ds[name]
            self.assertEqual(var.dims, ("z", "y", "x"), name)
            np.testing.assert_array_equal(var.values, values, err_msg=name)
            self.assertEqual(var.dtype, values.dtype, name)
            self.assertEqual(var.attrs["units"], units, name)
        self.assertEqual(self.ds["u"].attrs["units"], "m/s")
        self.assertEqual(self.ds["dx"].attrs["units"], "mm")
        self.assertEqual(self.ds["vorticity_z"].attrs["units"], "1/s")
        for a in "xyz":
            np.testing.assert_array_equal(self.ds[a].values, axes[a])
            self.assertEqual(self.ds[a].attrs["units"], "mm")
        self.assertEqual(self.ds.attrs["dt_s"], dt_s)
        self.assertEqual(dt_s, 0.001)

    def test_coordinates_follow_the_grid_and_the_velocity_is_the_displacement_over_dt(self):
        origin, spacing = self.ds.attrs["origin_mm"], self.ds.attrs["spacing_mm"]
        for i, a in enumerate("xyz"):
            expected = origin[i] + spacing[i] * np.arange(self.ds.sizes[a])
            np.testing.assert_allclose(self.ds[a].values, expected, rtol=0, atol=1e-12)
        # The box is x, y in [-1, 1] mm, z in [-0.5, 0.5] mm: node centres lie inside it.
        self.assertTrue(-1 < float(self.ds.x.min()) < float(self.ds.x.max()) < 1)
        np.testing.assert_allclose(self.ds.u, self.ds.dx * 1e-3 / self.ds.attrs["dt_s"], rtol=1e-6)
        # The simulated flow is 0.25 mm along x: the valid vectors' mean says so.
        valid = self.ds.valid > 0
        self.assertGreater(int(valid.sum()), 0)
        self.assertAlmostEqual(float(self.ds.dx.where(valid).mean()), 0.25, delta=0.08)

    def test_flags_are_decoded_with_their_legend(self):
        flags = self.ds["flags"]
        self.assertEqual(flags.dtype, np.uint8)
        legend = flags.attrs["legend"]
        bits = [int(b) for b in re.findall(r"(?:^bits:|;)\s*(\d+)\s", legend) if int(b) != 0]
        self.assertEqual(list(flags.attrs["flag_masks"]), bits)
        self.assertEqual(bits, [1, 2, 4, 8, 16, 32, 64])
        meanings = flags.attrs["flag_meanings"].split()
        self.assertEqual(len(meanings), len(bits))
        self.assertTrue(meanings[2].startswith("no_particle_signal"), meanings)
        decoded = plenopiv.flags(self.ds)
        self.assertEqual(list(decoded.data_vars), meanings)
        for mask, meaning in zip(bits, meanings):
            np.testing.assert_array_equal(decoded[meaning].values, (flags.values & mask) != 0, err_msg=meaning)
        # The invalid bits agree with `valid`: a node flagged "no particle signal" or "without a
        # replacement" has no vector.
        invalid = decoded[meanings[2]] | decoded[meanings[6]]
        self.assertFalse(bool((invalid & (self.ds.valid > 0)).any()))

    def test_provenance_and_axes_are_attributes(self):
        attrs = self.ds.attrs
        self.assertTrue(attrs["provenance_software"].startswith("plenopiv "), attrs["provenance_software"])
        for key in ("provenance_commit", "provenance_host", "provenance_written_utc", "provenance_settings"):
            self.assertIn(key, attrs)
        self.assertIn("voxel_mm: 0.125", attrs["provenance_settings"])
        self.assertTrue(attrs["axis_order"].startswith("z, y, x"))
        self.assertEqual(attrs["kind"], "vectors")
        self.assertEqual(attrs["source"], os.path.abspath(self.path))

    def test_the_writer_s_layout_is_the_reader_s(self):
        """write_vector_file (the live subscriber's --save) and open are one layout: a field written from
        what open gave reads back the same, and its HDF5 looks like the C++ writer's."""
        copy = os.path.join(WORK, "copy.h5")
        write_vector_file(copy, self.ds, {"run": "test"})
        back = plenopiv.open(copy)
        self.assertEqual(set(back.data_vars), set(self.ds.data_vars))
        for name in self.ds.data_vars:
            np.testing.assert_array_equal(back[name].values, self.ds[name].values, err_msg=name)
            self.assertEqual(back[name].dtype, self.ds[name].dtype, name)
            self.assertEqual(back[name].attrs["units"], self.ds[name].attrs["units"], name)
        for a in "xyz":
            np.testing.assert_array_equal(back[a].values, self.ds[a].values)
        np.testing.assert_array_equal(back.flags.attrs["flag_masks"], self.ds.flags.attrs["flag_masks"])
        self.assertEqual(back.attrs["provenance_run"], "test")
        with h5py.File(self.path, "r") as original, h5py.File(copy, "r") as written:
            self.assertEqual(set(original), set(written))
            self.assertEqual(set(original["vectors"].attrs), set(written["vectors"].attrs))
            for name in ("u", "valid", "flags"):
                self.assertEqual([d[0].name for d in written["vectors"][name].dims],
                                 [d[0].name for d in original["vectors"][name].dims])
                self.assertEqual(written["vectors"][name].dtype, original["vectors"][name].dtype)
        self.assertFalse(os.path.exists(copy + ".tmp"))

    def test_plenopiv_plot_writes_a_png_and_says_where(self):
        png = os.path.join(WORK, "slice.png")
        out = run([os.path.join(PACKAGE_DIR, "bin", "plenopiv-plot"), self.path, "-o", png])
        self.assertIn(os.path.abspath(png), out)
        self.assertTrue(is_png(png))


class OpenVolumeFile(unittest.TestCase):
    def test_the_volume_is_on_its_voxel_centres(self):
        path = os.path.join(WORK, "volume.h5")
        ds = plenopiv.open(path)
        self.assertEqual(ds.attrs["kind"], "volume")
        self.assertEqual(list(ds.data_vars), ["volume"])
        self.assertEqual(ds.volume.dims, ("z", "y", "x"))
        with h5py.File(path, "r") as f:
            np.testing.assert_array_equal(ds.volume.values, f["volume"][()])
            origin, spacing = f["volume"].attrs["origin_mm"], f["volume"].attrs["spacing_mm"]
        self.assertIn("units", ds.volume.attrs)
        for i, a in enumerate("xyz"):
            np.testing.assert_allclose(ds[a].values, origin[i] + spacing[i] * np.arange(ds.sizes[a]), atol=1e-12)
            self.assertEqual(ds[a].attrs["units"], "mm")
        self.assertEqual(ds.sizes["x"], 16)  # 2 mm at 0.125 mm
        self.assertGreater(float(ds.volume.max()), 0)
        self.assertTrue(ds.attrs["provenance_software"].startswith("plenopiv "))


class BadInput(unittest.TestCase):
    def assert_refused(self, path, words):
        with self.assertRaises(plenopiv.FileError) as caught:
            plenopiv.open(path)
        self.assertIn(path, str(caught.exception))
        self.assertIn(words, str(caught.exception))

    def test_a_run_folder_opens_either_tier(self):
        """A run folder whose manifest lists a full-tier file for pairs 0 and 2 and a live-tier one for
        every pair (as the daemon's lanes write them): each tier opens on its own pairs."""
        folder = os.path.join(WORK, "run-tiers")
        os.makedirs(os.path.join(folder, "vectors", "live"), exist_ok=True)
        with open(os.path.join(WORK, "v.h5"), "rb") as f:
            field = f.read()
        pairs = []
        for i in range(3):
            pair = {"pair_index": i, "live_vectors": "vectors/live/pair-%06d.h5" % i}
            if i != 1:
                pair["vectors"] = "vectors/pair-%06d.h5" % i
            for key in ("vectors", "live_vectors"):
                if key in pair:
                    with open(os.path.join(folder, pair[key]), "wb") as f:
                        f.write(field)
            pairs.append(pair)
        with open(os.path.join(folder, "manifest.json"), "w") as f:
            json.dump({"run_id": "tiers", "pairs": pairs}, f)
        full, live = plenopiv.open(folder), plenopiv.open(folder, tier="live")
        self.assertEqual(list(full.pair.values), [0, 2])
        self.assertEqual(list(live.pair.values), [0, 1, 2])
        self.assertEqual((full.attrs["tier"], live.attrs["tier"]), ("full", "live"))
        self.assertIn("vectors/live/pair-000001.h5", live.attrs["files"])
        np.testing.assert_array_equal(live.u.sel(pair=2).values, full.u.sel(pair=2).values)
        with self.assertRaisesRegex(ValueError, "tier: 'fast' is not one of full, live"):
            plenopiv.open(folder, tier="fast")
        only_live = os.path.join(WORK, "run-live-only")
        os.makedirs(only_live, exist_ok=True)
        with open(os.path.join(only_live, "manifest.json"), "w") as f:
            json.dump({"run_id": "live-only", "pairs": [{"pair_index": 0, "live_vectors": os.path.join(
                folder, "vectors/live/pair-000000.h5")}]}, f)
        self.assert_refused(only_live, "no full-tier vector fields in its manifest (it has live-tier ones: tier='live')")

    def test_a_run_still_recording_lists_what_its_journal_adds(self):
        """A run folder being recorded: manifest.json as the run's start wrote it, the pairs and fields
        since then in journal.jsonl (a last line cut short by a crash lists nothing)."""
        folder = os.path.join(WORK, "run-recording")
        os.makedirs(os.path.join(folder, "vectors"), exist_ok=True)
        with open(os.path.join(WORK, "v.h5"), "rb") as f, \
                open(os.path.join(folder, "vectors", "pair-000001.h5"), "wb") as out:
            out.write(f.read())
        with open(os.path.join(folder, "manifest.json"), "w") as f:
            json.dump({"run_id": "recording", "state": "recording", "pairs": []}, f)
        with open(os.path.join(folder, "journal.jsonl"), "w") as f:
            f.write('{"pair":{"pair_index":0,"frame_a":"frames/pair-000000-A.tif"}}\n'
                    '{"pair":{"pair_index":1,"frame_a":"frames/pair-000001-A.tif","host_timestamp_a_ns":7}}\n'
                    '{"drop":{"trigger_index":2,"reason":"camera queue overflow"}}\n'
                    '{"pair":{"pair_index":1,"vectors":"vectors/pair-000001.h5"}}\n'
                    '{"pair":{"pair_index":3,"vec')
        manifest = plenopiv.files.read_manifest(folder)
        self.assertEqual([p["pair_index"] for p in manifest["pairs"]], [0, 1])
        self.assertEqual(manifest["pairs"][1]["frame_a"], "frames/pair-000001-A.tif")
        self.assertEqual(manifest["dropped"][0]["reason"], "camera queue overflow")
        ds = plenopiv.open(folder)
        self.assertEqual(list(ds.pair.values), [1])
        with open(os.path.join(folder, "journal.jsonl"), "w") as f:
            f.write('{"pair": \n')
        with self.assertRaises(plenopiv.FileError) as caught:
            plenopiv.files.read_manifest(folder)
        self.assertIn("journal.jsonl: line 1: not a journal entry", str(caught.exception))

    def test_what_is_not_a_plenopiv_file_is_refused_by_name(self):
        self.assert_refused(os.path.join(WORK, "nothing-here.h5"), "no such file")
        text = os.path.join(WORK, "notes.txt")
        with open(text, "w") as f:
            f.write("not HDF5\n")
        self.assert_refused(text, "not an HDF5 file")
        other = os.path.join(WORK, "other.h5")
        with h5py.File(other, "w") as f:
            f["data"] = np.zeros(3)
        self.assert_refused(other, "neither /vectors nor /volume")
        empty = os.path.join(WORK, "empty-folder")
        os.makedirs(empty, exist_ok=True)
        self.assert_refused(empty, "no pair-<n>.h5 files")
        broken_run = os.path.join(WORK, "run-broken")
        os.makedirs(broken_run, exist_ok=True)
        with open(os.path.join(broken_run, "manifest.json"), "w") as f:
            f.write("{\"run_id\": ")
        self.assert_refused(broken_run, "cannot read the run manifest")


if __name__ == "__main__":
    make_files()
    unittest.main(verbosity=2)
