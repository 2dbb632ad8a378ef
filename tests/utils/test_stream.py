"""The bounded ordered thread map and the .npy row writer under ``eppf describe``'s stream."""

import io
import threading
import time

import numpy as np
import pytest

from eppf.utils._stream import HEADER_BYTES, RowWriter, ordered_map


def test_ordered_map_keeps_the_order_of_items_finishing_out_of_order():
    def slow_first(x):
        time.sleep(0.02 if x % 3 == 0 else 0)
        return x * 10

    assert list(ordered_map(slow_first, range(12), workers=3, depth=4)) == [x * 10 for x in range(12)]


def test_ordered_map_never_runs_more_than_depth_items_ahead_of_the_consumer():
    started, lock = [], threading.Lock()

    def record(x):
        with lock:
            started.append(x)
        return x

    seen = []
    for x in ordered_map(record, range(50), workers=2, depth=3):
        time.sleep(0.002)  # a slow consumer: the threads would race ahead if nothing bounded them
        with lock:
            ahead = max(started) - x
        seen.append(x)
        assert ahead <= 3
    assert seen == list(range(50))


def test_ordered_map_raises_an_item_error_at_its_turn_and_starts_nothing_after_a_stop():
    started = []

    def fail_at_5(x):
        started.append(x)
        if x == 5:
            raise ValueError("item 5 is bad")
        return x

    got = []
    with pytest.raises(ValueError, match="item 5 is bad"):
        for x in ordered_map(fail_at_5, range(1000), workers=2, depth=3):
            got.append(x)
    assert got == [0, 1, 2, 3, 4]
    assert max(started) <= 5 + 3  # the items submitted at the stop, no more
    gen = ordered_map(lambda x: x, range(1000), workers=1, depth=2)
    assert next(gen) == 0
    gen.close()  # a consumer that stops early leaves no thread running
    assert not [t for t in threading.enumerate() if t.name.startswith("eppf-stream")]


def test_row_writer_gives_the_array_of_np_save_with_the_final_row_count():
    rng = np.random.default_rng(0)
    parts = [rng.normal(size=(k, 7)) for k in (3, 0, 5, 1)]
    buf = io.BytesIO()
    w = RowWriter(buf, 7)
    for p in parts:
        w.write(p)
    w.close()
    buf.seek(0)
    assert np.lib.format.read_magic(buf) == (1, 0)
    shape, fortran, dtype = np.lib.format.read_array_header_1_0(buf)
    assert shape == (9, 7) and not fortran and dtype == np.float64 and buf.tell() == HEADER_BYTES
    buf.seek(0)
    np.testing.assert_array_equal(np.load(buf), np.vstack(parts))
    with pytest.raises(ValueError, match=r"shape \(k, 7\)"):
        w.write(np.zeros((2, 6)))


def test_row_writer_header_holds_huge_shapes_in_its_fixed_length():
    buf = io.BytesIO()
    w = RowWriter(buf, 123456789)
    w.n_rows = 10 ** 15  # the header alone: no rows are written
    w.close()
    buf.seek(0)
    np.lib.format.read_magic(buf)
    assert np.lib.format.read_array_header_1_0(buf)[0] == (10 ** 15, 123456789)
    assert HEADER_BYTES % 64 == 0


def test_progress_bar_off_takes_the_same_calls_and_shows_nothing(capsys):
    from eppf.utils import progress_bar

    bar = progress_bar(total=5, desc="files", unit="file", enabled=False)
    bar.update(2)
    bar.close()
    assert list(progress_bar(range(3), desc="reading", enabled=False)) == [0, 1, 2]
    assert capsys.readouterr() == ("", "")
    on = progress_bar(total=2, desc="files", unit="file")
    on.update(2)
    on.close()
    assert "files" in capsys.readouterr().err
