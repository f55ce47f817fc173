"""Unit tests of the shoal_node package's pure parts (no run needed):
`python3 -m unittest discover -s python/tests` from the repository's root."""

import ctypes
import math
import unittest

import shoal_node as sn
from shoal_node import msgs


class Contract(unittest.TestCase):
    def test_every_sample_type_has_its_rust_size_and_name(self):
        for name, (cls, service) in msgs.CHANNELS.items():
            self.assertEqual(ctypes.sizeof(cls), cls.SIZE, name)
            self.assertEqual(ctypes.alignment(cls), 8, name)
            self.assertTrue(cls.type_name().startswith(f"shoal.{cls.__name__}.v"), name)
            self.assertEqual(service.format(run_id="r", vehicle="F1"), f"shoal/r/F1/{name}")

    def test_the_doorbell_slot_holds_its_fields_on_one_cache_line(self):
        self.assertEqual(msgs.SLOT_BYTES, 64)
        ends = [off + (8 if f in ("tick", "sim_time_ns") else 4) for f, off in msgs.SLOT_FIELDS.items()]
        self.assertLessEqual(max(ends), msgs.SLOT_BYTES)
        self.assertEqual(len(set(msgs.SLOT_FIELDS.values())), len(msgs.SLOT_FIELDS))


class Finite(unittest.TestCase):
    def test_a_nan_anywhere_is_found_at_its_byte(self):
        sp = msgs.Setpoint()
        self.assertIsNone(sn.non_finite_field(sp))
        sp.keepout_m[5] = math.inf
        offset = msgs.Setpoint.keepout_m.offset + 5 * 8
        self.assertEqual(sn.non_finite_field(sp), offset)
        nav = msgs.Nav()
        nav.header.seq = 7  # integers never count
        self.assertIsNone(sn.non_finite_field(nav))
        nav.velocity_body_mps[1] = math.nan
        self.assertEqual(sn.non_finite_field(nav), msgs.Nav.velocity_body_mps.offset + 8)


class Stats(unittest.TestCase):
    def test_quantiles_are_kept_to_three_digits(self):
        h = sn.Histogram()
        for ns in range(1, 1001):
            h.record(ns * 1000)
        self.assertEqual(h.n, 1000)
        self.assertEqual(h.max, 1_000_000)
        self.assertEqual(h.quantile(0.5), 500_000)
        self.assertAlmostEqual(h.quantile(0.99), 990_000, delta=1000)
        self.assertEqual(sum(n for _, n in h.buckets()), 1000)
        self.assertEqual(sn.Histogram().quantile(0.5), 0)

    def test_the_earliest_origin_ignores_an_empty_one(self):
        a, b, none = sn.Origin(5, 1), sn.Origin(3, 2), sn.Origin()
        self.assertEqual(a.earliest(b), b)
        self.assertEqual(b.earliest(a), b)
        self.assertEqual(none.earliest(a), a)
        self.assertEqual(a.earliest(none), a)


class Text(unittest.TestCase):
    def test_a_nul_padded_field_reads_as_text(self):
        s = msgs.ProcessStats()
        s.vehicle[:2] = b"F3"
        self.assertEqual(sn.text(s.vehicle), "F3")


if __name__ == "__main__":
    unittest.main()
