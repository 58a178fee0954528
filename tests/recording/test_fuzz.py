"""Fuzz: whatever bytes, arrays or header a file holds, ``load_recording`` raises only
``InputFileError`` naming a problem and the expected form -- and never through its safety net.

``load_recording`` turns any exception its own checks did not anticipate into an
``InputFileError("malformed content (TypeError: ...)")``, so a crash cannot escape to a user. That
net is a last resort, not a message: a fuzz input that reaches it is a finding (the check that
should have named the field is missing), so these tests fail on it too.

CI runs ``WEARPOSE_FUZZ_EXAMPLES`` (default 60) inputs per strategy (9 strategies);
``benchmarks/recording_fuzz.py`` runs the issue's >= 10 000 (see docs/formats.md).
"""

from __future__ import annotations

import collections
import io
import json
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from recording_testutils import two_sensor_recording
from wearpose.errors import InputFileError
from wearpose.recording import load_recording, recording_arrays

BASE = recording_arrays(two_sensor_recording(n=40, with_gt=True))
KEYS = sorted(BASE)
DATA_KEYS = [k for k in KEYS if k.startswith(("sensors/", "ground_truth/"))]
EXAMPLES = int(os.environ.get("WEARPOSE_FUZZ_EXAMPLES", "60"))
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
#: The safety net's words (fileformat.load_recording): reaching it means an unanticipated crash.
SAFETY_NET = "malformed content ("
#: Files loaded per test (``benchmarks/recording_fuzz.py`` reports them): test name -> count.
LOADS: collections.Counter[str] = collections.Counter()


def _try(data: bytes, check_conventions: bool = True) -> None:
    """Load ``data`` as a file; only a specific ``InputFileError`` may come out."""
    LOADS[os.environ.get("PYTEST_CURRENT_TEST", "?").split("::")[-1].split(" ")[0]] += 1
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "f.npz"
        p.write_bytes(data)
        try:
            load_recording(p, check_conventions=check_conventions)
        except InputFileError as exc:
            assert exc.problem and exc.expected, exc
            assert exc.path == p, exc
            assert SAFETY_NET not in exc.problem, f"an unanticipated crash reached the safety net: {exc}"


def _npz_bytes(arrays: dict, compressed: bool = False) -> bytes:
    buf = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buf, **arrays)
    return buf.getvalue()


GOOD = _npz_bytes(BASE)

dtypes = st.sampled_from([np.float32, np.float64, np.float16, ">f8", ">f4", np.int64, np.uint8, np.int8, np.bool_,
                          np.complex64, "U5", "S3", "M8[s]", "V4", [("a", "<f4"), ("b", "<i2")]])
shapes = st.lists(st.integers(0, 41), min_size=0, max_size=4).map(tuple)


@st.composite
def random_array(draw, shape=None):
    dt = draw(dtypes)
    shape = draw(shapes) if shape is None else shape
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    size = int(np.prod(shape)) if shape else 1
    vals = rng.normal(scale=draw(st.sampled_from([1e-3, 1.0, 1e3, 1e30])), size=size)
    if draw(st.booleans()):
        vals[rng.random(size) < 0.2] = draw(st.sampled_from([np.nan, np.inf, -np.inf, 0.0]))
    with np.errstate(all="ignore"):
        if dt in ("U5", "S3"):
            return np.array([str(v)[:5] for v in vals], dtype=dt).reshape(shape)
        if isinstance(dt, list) or dt == "V4":
            return np.zeros(shape, dtype=dt)
        if dt == "M8[s]":
            return np.zeros(shape, dtype=dt)
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
       st.lists(st.sampled_from(KEYS), max_size=3), st.booleans())
def test_replaced_and_dropped_arrays(replace, drop, compressed):
    arrays = dict(BASE)
    arrays.update(replace)
    for k in drop:
        arrays.pop(k, None)
    _try(_npz_bytes(arrays, compressed))


@st.composite
def same_shape_hostile(draw):
    """A sensor or ground-truth array of its own shape with hostile values: another dtype or
    byte order, NaN/inf/huge/zero entries, non-rotations, shuffled or repeated timestamps."""
    key = draw(st.sampled_from(DATA_KEYS))
    a = np.array(BASE[key])
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    how = draw(st.sampled_from(["value", "scale", "dtype", "permute", "repeat", "zero", "sign"]))
    with np.errstate(all="ignore"):
        if a.dtype.kind == "b":
            a = rng.integers(0, draw(st.sampled_from([2, 3, 256])), size=a.shape).astype(draw(st.sampled_from([np.uint8, np.int64, np.bool_])))
        elif how == "value" and a.size:
            flat = a.reshape(-1).astype(np.float64)
            flat[rng.integers(0, flat.size, size=draw(st.integers(1, 5)))] = draw(st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e-300, 0.0]))
            a = flat.reshape(a.shape)
        elif how == "scale":
            a = a * draw(st.sampled_from([0.0, -1.0, 1e-9, 57.3, 1e9, 1e40]))
        elif how == "dtype":
            a = a.astype(draw(st.sampled_from([">f8", ">f4", np.float16, np.int32, np.uint64, np.int8])))
        elif how == "permute" and a.ndim >= 1 and a.shape[0] > 1:
            a = a[rng.permutation(a.shape[0])]
        elif how == "repeat" and a.ndim >= 1 and a.shape[0] > 1:
            a = a.copy()
            a[1:] = a[:-1]
        elif how == "zero":
            a = np.zeros_like(a)
        else:
            a = -a
    return key, a


@SETTINGS
@given(st.lists(same_shape_hostile(), min_size=1, max_size=3), st.booleans())
def test_hostile_values_of_the_right_shape(changes, check_conventions):
    arrays = dict(BASE)
    for k, a in changes:
        arrays[k] = a
    _try(_npz_bytes(arrays), check_conventions)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-10**30, 10**30) | st.floats(allow_nan=True) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3),
    max_leaves=8)
SENSOR_FIELDS = ["name", "kind", "site", "rate", "acc_unit", "acc_frame", "acc_gravity", "world_up", "position_unit",
                 "gyro_unit", "mag_unit", "reference", "source", "source_site", "extra"]


def _with_header(h: object) -> bytes:
    arrays = dict(BASE)
    arrays["header"] = np.array(h if isinstance(h, str) else json.dumps(h))
    return _npz_bytes(arrays)


@SETTINGS
@given(st.integers(0, 1), st.sampled_from(SENSOR_FIELDS), json_values,
       st.sampled_from(["subject", "meta", "ground_truth", "sensors", "bogus"]), json_values)
def test_mutated_header(sensor, key, value, top_key, top_value):
    h = json.loads(str(BASE["header"]))
    h["sensors"][sensor][key] = value
    _try(_with_header(h))
    h2 = json.loads(str(BASE["header"]))
    h2[top_key] = top_value
    _try(_with_header(h2))


@SETTINGS
@given(st.sampled_from(["start", "fps", "meta", "extra"]), json_values, st.sampled_from(["del", "set"]))
def test_mutated_ground_truth_header(key, value, how):
    h = json.loads(str(BASE["header"]))
    if how == "del":
        h["ground_truth"].pop(key, None)
    else:
        h["ground_truth"][key] = value
    _try(_with_header(h))


@SETTINGS
@given(st.one_of(
    st.text(max_size=200),  # any text, mostly not JSON
    st.integers(1, 100_000).map(lambda n: "[" * n + "]" * n),  # nested past the recursion limit
    st.integers(1, 100_000).map(lambda n: '{"sensors": ' + "[" * n + "]" * n + "}"),
    st.sampled_from(['{"sensors": NaN}', '{"sensors": [Infinity]}', '{"sensors": [{"name": "a", "kind": "imu", "rate": 1e999}]}',
                     '{"sensors": [{"name": "a", "kind": "imu", "rate": ' + "9" * 5000 + "}]}", "\ud800", "{}" * 3]),
))
def test_header_text(text):
    _try(_with_header(text))


@st.composite
def raw_npy_header(draw):
    """A member whose ``.npy`` header declares any shape / dtype / order over a few bytes of data
    (a huge declared shape must not allocate it)."""
    shape = tuple(draw(st.lists(st.sampled_from([0, 1, 3, 40, 2**31, 2**40, 2**62, -1]), max_size=3)))
    descr = draw(st.sampled_from(["<f8", ">f4", "|b1", "<i8", "|O", "<U9", "|V0", "<f16", "bogus"]))
    fortran = draw(st.booleans())
    head = "{'descr': %r, 'fortran_order': %s, 'shape': %r, }" % (descr, fortran, shape)
    head = head.ljust(118) + "\n"
    body = draw(st.binary(max_size=64))
    return draw(st.sampled_from(KEYS)), b"\x93NUMPY\x01\x00" + len(head).to_bytes(2, "little") + head.encode("latin1") + body


@SETTINGS
@given(st.lists(raw_npy_header(), min_size=1, max_size=2))
def test_forged_npy_members(members):
    forged = dict(members)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for k in KEYS:
            if k in forged:
                z.writestr(k + ".npy", forged[k])
            else:
                b = io.BytesIO()
                np.save(b, BASE[k])
                z.writestr(k + ".npy", b.getvalue())
    _try(buf.getvalue())


def test_fuzzing_finds_what_the_net_hides(monkeypatch: pytest.MonkeyPatch) -> None:
    """The net check can fail: a check that crashes (as an unguarded one would) is reported."""
    import wearpose.recording.fileformat as ff

    def crash(*a, **k):  # a check that raises what no check anticipated
        raise TypeError("boom")

    monkeypatch.setattr(ff, "check_recording", crash)
    with pytest.raises(AssertionError, match="safety net"):
        _try(GOOD)


def test_a_member_header_numpy_cannot_tokenize_is_named() -> None:
    """Found by test_corrupted_and_truncated_zip (one byte overwritten inside a member's header):
    numpy's header filter lets ``tokenize.TokenError`` through (an unclosed bracket); the loader
    names it as a damaged header, not through the safety net."""
    head = ("{'descr': '<f8', 'fortran_order': False, 'shape': (40, 3, ".ljust(118) + "\n").encode("latin1")
    member = b"\x93NUMPY\x01\x00" + len(head).to_bytes(2, "little") + head + bytes(960)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for k in KEYS:
            b = io.BytesIO()
            np.save(b, BASE[k])
            z.writestr(k + ".npy", member if k == DATA_KEYS[0] else b.getvalue())
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "f.npz"
        p.write_bytes(buf.getvalue())
        with pytest.raises(InputFileError, match="a damaged array header inside the npz") as err:
            load_recording(p)
    assert err.value.path == p
