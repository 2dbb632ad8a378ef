"""eppf.describe_files and the descriptors' streaming hooks (partial_fit, _stream_part)."""

import io
import re
import threading

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from sklearn.base import clone

import eppf.streaming as streaming
from eppf import CVFHTransformer, EPPFTransformer, describe_files
from eppf.datasets import make_shapes
from eppf.descriptors import DescriptorUnion, GASDTransformer
from eppf.io import read_point_cloud, write_mesh, write_point_cloud
from eppf.registry import DESCRIPTORS, make_descriptor


def _folder(tmp_path, n=5):
    """A folder of point files of different sizes and scales, and one mesh (sampled on reading)."""
    folder = tmp_path / "objects"
    (folder / "sub").mkdir(parents=True)
    clouds, _ = make_shapes(n, n_points=120, random_state=2, return_X_y=True)
    for k, cloud in enumerate(clouds[: 3 * n]):
        where = folder / "sub" if k % 4 == 0 else folder
        write_point_cloud(where / f"c{k:02d}.ply", cloud[: 60 + 7 * k] * (0.5 + k % 3))
    box = np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0], [0, 0, 3]], dtype=float)
    write_mesh(folder / "tetra.off", box, np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]))
    return folder


def _read_like_describe_files(folder, random_state=0, n_points=None):
    """The clouds describe_files reads: each file with its load_folder seed (the reference, read in memory)."""
    from eppf.datasets._folder import object_files
    from eppf.datasets._loaders import file_seeds

    files = object_files(folder)
    seeds = file_seeds(random_state, folder, files)
    return files, [read_point_cloud(f, n_points=n_points, random_state=s) for f, s in zip(files, seeds)]


@pytest.mark.parametrize("name", list(DESCRIPTORS))
def test_rows_are_those_of_fit_transform_for_any_chunking_and_threads(tmp_path, monkeypatch, name):
    folder = _folder(tmp_path)
    files, clouds = _read_like_describe_files(folder)
    monkeypatch.setattr(streaming, "FIRST_CHUNK_FILES", 2)
    for random_state in (7, np.random.RandomState(7)):
        est = make_descriptor(name, n_samples=400, random_state=random_state, n_jobs=1)
        expected = clone(est).fit_transform(clouds)
        for chunk_size, n_jobs in ((1, 1), (3, 2), (4, 3), (100, 2)):
            result = describe_files([folder], est, chunk_size=chunk_size, n_jobs=n_jobs)
            assert_array_equal(result.descriptors, expected)
            assert result.files == files and result.skipped == []
            assert result.n_points.tolist() == [len(c) for c in clouds]
            assert result.n_features == expected.shape[1]
    assert est.get_params().get("random_state", random_state) is random_state  # a clone was fitted
    assert not hasattr(est, "n_features_out_")


@pytest.mark.parametrize("make", [lambda: CVFHTransformer(scaling="fit"),
                                  lambda: DescriptorUnion([("eppf", EPPFTransformer(n_pairs=300, random_state=1)),
                                                           ("gasd", GASDTransformer())])])
def test_data_set_scale_of_other_descriptors_and_unions_is_learnt_from_every_file(tmp_path, make):
    folder = _folder(tmp_path)
    _, clouds = _read_like_describe_files(folder)
    est = make()
    assert est._learns_from_data()
    expected = clone(est).fit_transform(clouds)
    result = describe_files(folder, est, chunk_size=2, n_jobs=2)
    assert_array_equal(result.descriptors, expected)
    fitted = clone(est).fit(clouds)
    blocks = [e for _, e in getattr(fitted, "transformers_", [("", fitted)])]
    got = [e for _, e in getattr(result.descriptor, "transformers_", [("", result.descriptor)])]
    assert [getattr(b, "scale_", None) for b in got] == [getattr(b, "scale_", None) for b in blocks]
    assert got[0].scale_ is not None


def test_output_goes_to_a_npy_file_or_an_open_file_as_the_rows_come(tmp_path):
    folder = _folder(tmp_path)
    est = EPPFTransformer(n_pairs=300, random_state=0)
    expected = describe_files(folder, est).descriptors
    result = describe_files([folder], est, output=tmp_path / "rows.npy", chunk_size=2)
    assert result.descriptors is None and result.n_features == expected.shape[1]
    assert_array_equal(np.load(tmp_path / "rows.npy"), expected)
    buf = io.BytesIO()
    describe_files([folder], est, output=buf, chunk_size=3)
    buf.seek(0)
    assert_array_equal(np.load(buf), expected)
    with pytest.raises(ValueError, match=r"output must be a \.npy path"):
        describe_files([folder], est, output=tmp_path / "rows.csv")


def test_unreadable_files_raise_naming_them_or_are_skipped_with_a_warning(tmp_path):
    folder = _folder(tmp_path)
    files, clouds = _read_like_describe_files(folder)
    (folder / "broken.xyz").write_text("1 2\n")
    est = EPPFTransformer(n_pairs=300, random_state=0)
    with pytest.raises(ValueError, match=r"describe_files: .*broken\.xyz"):
        describe_files([folder], est)
    with pytest.warns(UserWarning, match=rf"skipped 1 of {len(files) + 1} files that could not be read: .*broken\.xyz"):
        result = describe_files([folder], est, on_error="skip", chunk_size=2, n_jobs=2)
    assert [f for f, _ in result.skipped] == [str(folder / "broken.xyz")]
    assert result.files == files  # the others, in order, with the rows they have without the bad file
    assert_array_equal(result.descriptors, clone(est).fit_transform(clouds))
    with pytest.raises(ValueError, match=r"no file could be read \(1 of 1\)"):
        describe_files([folder / "broken.xyz"], est, on_error="skip")


def test_a_cloud_the_descriptor_refuses_is_named_by_its_file(tmp_path):
    folder = tmp_path / "c"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(5):
        write_point_cloud(folder / f"ok{i}.xyz", rng.normal(size=(80, 3)))
    write_point_cloud(folder / "ok5_flat.xyz", np.ones((80, 3)))  # every point the same: no pair to draw
    for n_jobs in (1, 2):
        with pytest.raises(ValueError, match=r"point cloud \S*ok5_flat\.xyz"):
            describe_files([folder], EPPFTransformer(scaling="object"), chunk_size=2, n_jobs=n_jobs)


def test_bad_arguments_are_refused(tmp_path):
    folder = _folder(tmp_path)
    with pytest.raises(TypeError, match="describe_files: descriptor must be an eppf descriptor"):
        describe_files([folder], object())
    from eppf.descriptors import DescriptorPool

    with pytest.raises(TypeError, match=r"got DescriptorPool \(a pool gives several draws a cloud, .* stream its "):
        describe_files([folder], DescriptorPool(GASDTransformer(), 2, random_state=0))
    with pytest.raises(ValueError, match="chunk_size must be a positive int"):
        describe_files([folder], EPPFTransformer(), chunk_size=0)
    with pytest.raises(ValueError, match="on_error must be"):
        describe_files([folder], EPPFTransformer(), on_error="ignore")
    with pytest.raises(FileNotFoundError, match="no such file or folder"):
        describe_files([tmp_path / "nothing"], EPPFTransformer())


@pytest.mark.parametrize("options, msg", [
    (dict(n_points=0), "describe_files: n_points must be None or an int >= 2, got 0"),
    (dict(resolution=-1.0), "describe_files: resolution must be None or a positive finite float, got -1.0"),
    (dict(normals="yes"), "describe_files: normals must be 'auto', True or False, got 'yes'"),
    (dict(n_points=64, resolution=0.1), "describe_files: give n_points or resolution, not both"),
])
def test_bad_reading_options_fail_once_before_any_file_is_read(tmp_path, monkeypatch, options, msg):
    # (each file's read refused them, so with on_error="skip" every file was skipped first, one message each)
    import eppf.io

    folder = _folder(tmp_path)
    monkeypatch.setattr(eppf.io, "read_point_cloud", lambda *a, **k: pytest.fail("a file was read"))
    with pytest.raises(ValueError, match=re.escape(msg)):
        describe_files([folder], GASDTransformer(), on_error="skip", **options)


def test_an_output_file_that_is_text_or_cannot_seek_is_refused_before_the_work(tmp_path, monkeypatch):
    # (a pipe failed with "[Errno 29] Illegal seek", a text file with "write() argument must be str", both after
    # every file was described)
    import os

    folder = _folder(tmp_path)
    monkeypatch.setattr(streaming, "write_descriptors", lambda *a, **k: pytest.fail("described before the check"))
    with open(tmp_path / "d.txt", "w") as text:
        with pytest.raises(TypeError, match=r"describe_files: output must be a file opened in binary mode"):
            describe_files([folder], GASDTransformer(), output=text)
    read_end, write_end = os.pipe()
    with os.fdopen(read_end, "rb"), os.fdopen(write_end, "wb") as pipe:
        with pytest.raises(ValueError, match=r"describe_files: output must be seekable .* write to a .npy path"):
            describe_files([folder], GASDTransformer(), output=pipe)


# ---------------------------------------------------------------------------
# The hooks
# ---------------------------------------------------------------------------


def test_partial_fit_on_batches_learns_the_scale_of_fit_on_all():
    rng = np.random.default_rng(5)
    clouds = [rng.normal(size=(30, 3)) * s for s in (1.0, 1e-200, 3.0, 1e150, 0.5)]
    for est in (EPPFTransformer(), CVFHTransformer(scaling="fit")):
        fitted = clone(est).fit(clouds)
        batched = clone(est)
        for lo in range(0, len(clouds), 2):
            batched.partial_fit(clouds[lo:lo + 2])
        assert batched.scale_ == fitted.scale_
        batched.fit(clouds[2:3])  # fit starts over
        assert batched.scale_ == clone(est).fit(clouds[2:3]).scale_
        batched.partial_fit(clouds[1:2])
        assert batched.scale_ == clone(est).fit(clouds[1:2]).scale_
    overflow = [np.array([[1e308, 0, 0], [-1e308, 1, 1]])]
    with pytest.raises(ValueError, match="out of float64's range") as fit_error:
        EPPFTransformer().fit(clouds + overflow)
    est = EPPFTransformer().partial_fit(clouds)
    with pytest.raises(ValueError, match="out of float64's range") as partial_error:
        est.partial_fit(overflow)
    assert str(partial_error.value) == str(fit_error.value)
    assert est._partial_fit_side == max(np.ptp(c, axis=0).max() for c in clouds)  # not the refused batch's


def test_only_data_set_scaling_needs_every_cloud_first():
    assert EPPFTransformer()._learns_from_data()
    assert not EPPFTransformer(scaling="object")._learns_from_data()
    assert not make_descriptor("esf")._learns_from_data() and not make_descriptor("gasd")._learns_from_data()
    assert make_descriptor("eppf+gasd")._learns_from_data()
    assert not make_descriptor("eppf+gasd", scaling="object")._learns_from_data()


def test_stream_parts_draw_the_seeds_of_consecutive_chunks():
    clouds = list(make_shapes(3, n_points=100, random_state=0, return_X_y=True)[0])
    est = EPPFTransformer(n_pairs=300, random_state=11, n_jobs=2).fit(clouds)
    expected = est.transform(clouds)
    generator = est._stream_generator()
    parts = [est._stream_part(n, generator, n_jobs=1) for n in (4, 1, len(clouds) - 5)]
    assert all(p.n_jobs == 1 for p in parts) and est.n_jobs == 2 and est.random_state == 11
    rows = [None] * 3
    threads = [threading.Thread(target=lambda k, lo, hi: rows.__setitem__(k, parts[k].transform(clouds[lo:hi])),
                                args=a) for a in ((2, 5, len(clouds)), (0, 0, 4), (1, 4, 5))]
    for t in threads:  # the last chunk first: each part has its own seeds
        t.start()
        t.join()
    assert_array_equal(np.vstack(rows), expected)
    assert make_descriptor("gasd")._stream_generator() is None


def test_side_by_side_rows_run_on_other_threads_with_one_thread_each(monkeypatch):
    seen = []
    real = EPPFTransformer.transform

    def recording(self, X):
        seen.append((threading.get_ident(), self.n_jobs))
        return real(self, X)

    monkeypatch.setattr(EPPFTransformer, "transform", recording)
    clouds = list(make_shapes(2, n_points=80, random_state=0, return_X_y=True)[0])
    for n_threads, own in ((1, 3), (2, 3)):
        seen.clear()
        est = EPPFTransformer(n_pairs=200, random_state=1, n_jobs=own).fit(clouds)
        rows, out = streaming._Rows(est, n_threads), []
        try:
            for lo in range(0, len(clouds), 3):
                rows.submit(clouds[lo:lo + 3], [f"f{lo + i}" for i in range(3)], out.append)
            rows.finish(out.append)
        finally:
            rows.close()
        assert len(seen) == len(range(0, len(clouds), 3))
        here = threading.get_ident()
        if n_threads == 1:
            assert all(t == here and j == own for t, j in seen)
        else:
            assert all(t != here and j == 1 for t, j in seen)


def test_random_state_takes_what_load_folder_takes(tmp_path):
    # the docstring said int, a RandomState was used without a word, and a float failed inside
    # scikit-learn's check_random_state with a message naming neither describe_files nor the parameter
    from eppf.datasets._folder import object_files
    from eppf.datasets._loaders import file_seeds

    folder = _folder(tmp_path, n=1)
    est = EPPFTransformer(n_pairs=200, random_state=0)
    by_int = describe_files(folder, est, random_state=5)
    by_rs = describe_files(folder, est, random_state=np.random.RandomState(5))
    # a RandomState draws the folder's base seed as load_folder draws it: the same clouds as reading them so
    files = object_files(str(folder))
    seeds = file_seeds(np.random.RandomState(5), str(folder), files)
    same = est.fit_transform([read_point_cloud(f, random_state=s) for f, s in zip(files, seeds)])
    assert_array_equal(by_rs.descriptors, same)
    assert by_int.files == by_rs.files
    assert describe_files(folder, est, random_state=None).descriptors.shape == by_int.descriptors.shape
    for bad, exc in ((1.5, TypeError), ("0", TypeError), (-1, ValueError), (2**40, ValueError)):
        with pytest.raises(exc, match=r"describe_files: random_state must be "):
            describe_files(folder, est, random_state=bad)


def test_paths_of_every_kind_and_of_no_kind(tmp_path):
    import os

    folder = _folder(tmp_path, n=1)
    est = EPPFTransformer(n_pairs=200, random_state=0)
    expected = describe_files(folder, est)
    # a bytes folder gave bytes names, which the reading and the file seeds then failed on
    for files in (os.fsencode(folder), [os.fsencode(folder)], [str(folder)], (f for f in [folder])):
        result = describe_files(files, est)
        assert result.files == expected.files
        assert_array_equal(result.descriptors, expected.descriptors)
    out = os.fsencode(tmp_path / "rows.npy")
    assert describe_files(folder, est, output=out).descriptors is None
    assert_array_equal(np.load(tmp_path / "rows.npy"), expected.descriptors)
    with pytest.raises(TypeError, match=r"describe_files: files\[1\] must be a str, bytes or os\.PathLike path, got int"):
        describe_files([folder, 3], est)
    with pytest.raises(TypeError, match=r"describe_files: files must be a path or a sequence of paths, got int"):
        describe_files(3, est)
    with pytest.raises(TypeError, match=r"describe_files: output must be a \.npy path or a binary file open for "
                                        r"writing, got int"):
        describe_files(folder, est, output=4)
    with pytest.raises(ValueError, match=r"describe_files: n_points must be at most 1,000,000,000 points per object"):
        describe_files(folder, est, n_points=10**12)
