"""Fuzz: whatever bytes or arrays a file holds, load_recording raises only InputFileError."""

from __future__ import annotations

import io
import json
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from recording_testutils import two_sensor_recording
from wearpose.errors import InputFileError, WearposeError
from wearpose.recording import load_recording, recording_arrays

BASE = recording_arrays(two_sensor_recording(n=40, with_gt=True))
KEYS = sorted(BASE)
SETTINGS = settings(max_examples=int(__import__("os").environ.get("FUZZ_N", "60")), deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _try(data: bytes) -> None:
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "f.npz"
        p.write_bytes(data)
        try:
            load_recording(p)
        except InputFileError as exc:
            assert isinstance(exc, WearposeError)
            assert exc.problem and exc.expected


def _npz_bytes(arrays: dict) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


GOOD = _npz_bytes(BASE)

dtypes = st.sampled_from([np.float32, np.float64, np.int64, np.uint8, np.bool_, np.complex64, "U5", np.int8])
shapes = st.lists(st.integers(0, 41), min_size=0, max_size=4).map(tuple)


@st.composite
def random_array(draw):
    dt, shape = draw(dtypes), draw(shapes)
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    size = int(np.prod(shape)) if shape else 1
    vals = rng.normal(scale=draw(st.sampled_from([1e-3, 1.0, 1e3, 1e30])), size=size)
    if draw(st.booleans()):
        vals[rng.random(size) < 0.2] = draw(st.sampled_from([np.nan, np.inf, -np.inf, 0.0]))
    with np.errstate(all="ignore"):
        if dt == "U5":
            return np.array([str(v)[:5] for v in vals]).reshape(shape)
        return vals.astype(dt).reshape(shape)


@SETTINGS
@given(st.binary(max_size=2000))
def test_random_bytes(data):
    _try(data)


@SETTINGS
@given(st.integers(0, len(GOOD) - 1), st.integers(1, 64), st.integers(0, 255))
def test_corrupted_and_truncated_zip(pos, length, byte):
    _try(GOOD[:pos])  # truncated file
    _try(GOOD[:pos] + bytes([byte]) * length + GOOD[pos + length:])  # overwritten bytes


@SETTINGS
@given(st.dictionaries(st.sampled_from(KEYS), random_array(), min_size=1, max_size=4),
       st.lists(st.sampled_from(KEYS), max_size=3))
def test_replaced_and_dropped_arrays(replace, drop):
    arrays = dict(BASE)
    arrays.update(replace)
    for k in drop:
        arrays.pop(k, None)
    _try(_npz_bytes(arrays))


json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats(allow_nan=True) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3),
    max_leaves=8)


@SETTINGS
@given(st.integers(0, 1), st.sampled_from(["name", "kind", "site", "rate", "acc_unit", "acc_frame", "acc_gravity",
                                            "world_up", "position_unit", "reference", "mag_unit", "extra"]),
       json_values, st.sampled_from(["subject", "meta", "ground_truth", "sensors", "bogus"]), json_values)
def test_mutated_header(sensor, key, value, top_key, top_value):
    h = json.loads(str(BASE["header"]))
    h["sensors"][sensor][key] = value
    arrays = dict(BASE)
    arrays["header"] = np.array(json.dumps(h))
    _try(_npz_bytes(arrays))
    h2 = json.loads(str(BASE["header"]))
    h2[top_key] = top_value
    arrays["header"] = np.array(json.dumps(h2))
    _try(_npz_bytes(arrays))
