"""plenopiv.messages on hand-made `vectors` messages: a well-formed one decodes to the Dataset the subscriber
saves (every header field kept by name), malformed ones are refused saying what is wrong."""
import unittest

import numpy as np

from plenopiv import plenopiv_pb2
from plenopiv.messages import MessageError, decode_vectors, header_entries
from support import InstalledPackageTest  # noqa: F401


def message(payloads=("u", "v", "w", "valid"), shape=(4, 3, 2), values=None, topic=b"vectors", sigma_method=""):
    header = plenopiv_pb2.VectorFieldHeader(run_id="r1", pair_index=7, shape=list(shape),
                                            origin_mm=[-1.0, -0.5, 0.0], spacing_mm=[0.5, 0.5, 1.0], dt_s=1e-4,
                                            payloads=list(payloads), latency_s=0.25, sigma_method=sigma_method)
    n = int(np.prod(shape))
    arrays = [np.arange(n, dtype="<f4") * (i + 1) if values is None else values for i in range(len(payloads))]
    return [topic, header.SerializeToString()] + [a.tobytes() for a in arrays]


class DecodeVectors(unittest.TestCase):
    def test_a_field_decodes_on_its_grid_with_units_and_every_header_field(self):
        ds = decode_vectors(message())
        self.assertEqual(dict(ds.sizes), {"z": 2, "y": 3, "x": 4})
        np.testing.assert_array_equal(ds.x.values, [-1.0, -0.5, 0.0, 0.5])
        np.testing.assert_array_equal(ds.z.values, [0.0, 1.0])
        # [nz][ny][nx], x fastest: the value at (z, y, x) is its flat index.
        self.assertEqual(float(ds.u[1, 2, 3]), 1 * 12 + 2 * 4 + 3)
        self.assertEqual(float(ds.v[1, 2, 3]), 2 * 23)
        self.assertEqual(ds.u.attrs["units"], "m/s")
        self.assertEqual(ds.valid.attrs["units"], "1")
        self.assertEqual(ds.attrs["dt_s"], 1e-4)
        self.assertEqual(ds.attrs["header_run_id"], "r1")
        self.assertEqual(ds.attrs["header_pair_index"], 7)
        self.assertEqual(ds.attrs["header_latency_s"], 0.25)
        # Every scalar field of the .proto, whatever it holds today.
        scalar = [f.name for f in plenopiv_pb2.VectorFieldHeader.DESCRIPTOR.fields if f.label != f.LABEL_REPEATED]
        self.assertEqual(sorted(header_entries(plenopiv_pb2.VectorFieldHeader())), sorted(scalar))
        self.assertTrue(all("header_" + name in ds.attrs for name in scalar))

    def test_a_sigma_says_what_it_holds_as_its_vector_file_does(self):
        sigma = ("u", "valid", "sigma_u")
        ds = decode_vectors(message(payloads=sigma, sigma_method="correlation statistics; a floor"))
        self.assertEqual(ds.sigma_u.attrs["long_name"], "standard uncertainty of u (correlation statistics; a floor); "
                                                        "NaN: no estimate (invalid or interpolated)")
        self.assertEqual(ds.attrs["header_sigma_method"], "correlation statistics; a floor")
        # A daemon that does not say: the statistic's name alone.
        plain = decode_vectors(message(payloads=sigma))
        self.assertIn("(correlation statistics, Wieneke 2015)", plain.sigma_u.attrs["long_name"])

    def test_an_array_the_subscriber_does_not_know_says_its_units_are_unknown(self):
        ds = decode_vectors(message(payloads=("u", "mystery")))
        self.assertIn("unknown", ds.mystery.attrs["units"])

    def test_malformed_messages_are_refused_saying_what_is_wrong(self):
        cases = [
            (message(topic=b"status"), "not a vectors message"),
            (message()[:2] + message()[2:4], "names 4 payloads, the message has 2"),
            (message(values=np.zeros(5, dtype="<f4")), "payload u has 5 values"),
            (message(shape=(4, 3)), "need 3 values each"),
            ([b"vectors", b"\xff\xff\xff"], "not a VectorFieldHeader"),
        ]
        for frames, words in cases:
            with self.assertRaises(MessageError) as caught:
                decode_vectors(frames)
            self.assertIn(words, str(caught.exception))


if __name__ == "__main__":
    unittest.main(verbosity=2)
