"""DescriptorCache: arrays stored under a key, and a damaged cache file recomputed rather than trusted."""

import zipfile

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from eppf.utils._cache import DescriptorCache


def _compute(calls):
    def compute():
        calls.append(1)
        return {"X": np.arange(12.0).reshape(4, 3), "ids": np.arange(4)}

    return compute


def test_second_get_loads_what_the_first_stored(tmp_path):
    cache, calls = DescriptorCache(str(tmp_path)), []
    first = cache.get("T", ["a", "b"], _compute(calls), ["X", "ids"], "t")
    again = cache.get("T", ["a", "b"], _compute(calls), ["X", "ids"], "t")
    assert len(calls) == 1 and cache.n_loaded == 1
    for k in ("X", "ids"):
        assert_array_equal(again[k], first[k])


@pytest.mark.parametrize("damage", ["truncated", "flipped", "not a zip"])
def test_a_damaged_cache_file_is_recomputed(tmp_path, damage):
    logged = []
    cache, calls = DescriptorCache(str(tmp_path), log=logged.append), []
    cache.get("T", ["k"], _compute(calls), ["X", "ids"], "t")
    (path,) = tmp_path.glob("T-*.npz")
    data = path.read_bytes()
    if damage == "truncated":
        data = data[: len(data) // 2]
    elif damage == "flipped":  # inside the stored X (zip stores CRCs: the read must notice)
        with zipfile.ZipFile(path) as zf:
            info = zf.getinfo("X.npy")
        data = bytearray(data)
        data[info.header_offset + 30 + len(info.filename) + info.compress_size - 8] ^= 0xFF
        data = bytes(data)
    else:
        data = b"not an archive"
    path.write_bytes(data)
    out = cache.get("T", ["k"], _compute(calls), ["X", "ids"], "t")
    assert len(calls) == 2 and any("unreadable cache file" in line for line in logged)
    assert_array_equal(out["X"], np.arange(12.0).reshape(4, 3))
