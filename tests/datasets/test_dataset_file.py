"""Dataset files: a round trip, and every malformed file gives one DatasetFileError naming the path."""

import gzip
import io
import zipfile

import numpy as np
import pytest

from ogm_ppl import Grid, Scans
from ogm_ppl.datasets import Dataset, DatasetFileError, load_dataset, save_dataset
from ogm_ppl.datasets.dataset_file import FORMAT


def scans():
    valid = np.array([[True, False, True], [True, True, True]])
    angles = np.array([[-0.5, 0.0, 0.5], [-0.4, 0.0, 0.4]])
    ranges = np.array([[1.0, np.nan, 4.0], [2.0, 3.0, 0.05]])
    return Scans([[0, 0, 0], [1, 2, 0.3]], angles, ranges, 4.0, valid=valid, min_range=0.1)


def saved(tmp_path, **kw):
    grid = Grid((3, 4), 0.5, (-1.0, -1.0))
    truth = np.arange(12).reshape(3, 4) % 2 == 0
    return save_dataset(tmp_path / "d.npz", scans(), grid=grid, truth=truth, **kw), grid, truth


def test_round_trip(tmp_path):
    path, grid, truth = saved(tmp_path, settings={"a": 1, "b": [1.5]}, provenance={"src": "x"})
    d = load_dataset(path)
    assert isinstance(d, Dataset) and d.grid == grid and d.truth.dtype == bool
    assert np.array_equal(d.truth, truth)
    s = scans()
    for name in ("poses", "angles", "ranges", "valid", "is_max"):
        assert np.array_equal(getattr(d.scans, name), getattr(s, name)), name
    assert (d.scans.max_range, d.scans.min_range) == (4.0, 0.1)
    assert d.settings == {"a": 1, "b": [1.5]} and d.provenance == {"src": "x"}
    bare = load_dataset(save_dataset(tmp_path / "noext", s))  # written exactly at the path given
    assert bare.grid is None and bare.truth is None and bare.settings == {}
    one_d = load_dataset(save_dataset(tmp_path / "1d.npz", s, grid=Grid.line(5), truth=np.zeros(5)))
    assert one_d.grid == Grid.line(5)
    assert [p.name for p in tmp_path.iterdir() if "tmp" in p.name] == []  # no temporary left


def test_save_rejects_bad_input(tmp_path):
    with pytest.raises(TypeError, match="JSON"):
        save_dataset(tmp_path / "x.npz", scans(), settings={"f": object()})
    with pytest.raises(ValueError, match="shape"):
        save_dataset(tmp_path / "x.npz", scans(), grid=Grid((2, 2)), truth=np.zeros(3))
    with pytest.raises(TypeError):
        save_dataset(tmp_path / "x.npz", "not scans")
    assert not (tmp_path / "x.npz").exists()


def rewrite(path, drop=(), **replace):
    """Write back the npz at ``path`` with entries dropped or replaced."""
    with np.load(path) as f:
        arrays = {k: f[k] for k in f.files if k not in drop}
    arrays.update(replace)
    np.savez(path, **arrays)


def _npz_bytes(**arrays):
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def _zip_with(path, name, data):
    with zipfile.ZipFile(path, "w") as z:
        z.writestr(name, data)


BAD = {
    "empty": (lambda p: p.write_bytes(b""), "empty"),
    "text": (lambda p: p.write_text("hello"), "not an npz"),
    "gzip": (lambda p: p.write_bytes(gzip.compress(b"FLASER")), "gzip"),
    "truncated": (lambda p: p.write_bytes(p.read_bytes()[:200]), "truncated or corrupt"),
    "foreign": (lambda p: p.write_bytes(_npz_bytes(x=np.zeros(3))), "not an ogm_ppl dataset"),
    "pickle": (
        lambda p: p.write_bytes(_npz_bytes(format=np.array([{"a": 1}], dtype=object))),
        "pickled",
    ),
    "format": (lambda p: rewrite(p, format=np.array("other")), "has format 'other'"),
    "version": (lambda p: rewrite(p, format_version=np.array(2)), "format version 2"),
    "version-type": (lambda p: rewrite(p, format_version=np.array("1")), "format_version"),
    "missing": (lambda p: rewrite(p, drop=("ranges",)), "lacks the entries ['ranges']"),
    "shape": (lambda p: rewrite(p, poses=np.zeros((2, 2))), "invalid scans"),
    "dtype": (lambda p: rewrite(p, valid=np.ones((2, 3))), "'valid'"),
    "nan-pose": (lambda p: rewrite(p, poses=np.array([[0, 0, 0], [np.nan, 0, 0]])), "non-finite"),
    "max-range": (lambda p: rewrite(p, max_range=np.array([4.0, 5.0])), "'max_range'"),
    "json": (lambda p: rewrite(p, settings=np.array("{not json")), "not valid JSON"),
    "json-list": (lambda p: rewrite(p, provenance=np.array("[1]")), "JSON object"),
    "grid": (lambda p: rewrite(p, grid=np.array([3.0, 4.0, -0.5, 0.0, 0.0])), "'grid'"),
    "truth": (lambda p: rewrite(p, truth=np.zeros((4, 3))), "'truth'"),
    "truth-nan": (lambda p: rewrite(p, truth=np.full((3, 4), np.nan)), "non-finite"),
    "grid-fraction": (lambda p: rewrite(p, grid=np.array([3.5, 4.0, 0.5, 0.0, 0.0])), "whole number"),
    "no-scans": (
        lambda p: rewrite(
            p, poses=np.zeros((0, 3)), angles=np.zeros((0, 3)), ranges=np.zeros((0, 3)), valid=np.zeros((0, 3), bool)
        ),
        "no scans",
    ),
    "sigma-text": (lambda p: rewrite(p, settings=np.array('{"sigma_cells": "abc"}')), "'sigma_cells'"),
    "sigma-negative": (lambda p: rewrite(p, settings=np.array('{"sigma_cells": -1}')), "'sigma_cells'"),
    "zip-member": (lambda p: _zip_with(p, "poses.npy", b"\x93NUMPY garbage"), "corrupt"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_malformed_file_gives_dataset_file_error(tmp_path, case):
    path, _, _ = saved(tmp_path)
    damage, words = BAD[case]
    damage(path)
    with pytest.raises(DatasetFileError) as e:
        load_dataset(path)
    assert str(path) in str(e.value) and words in str(e.value) and "(" in str(e.value)  # a hint
    assert isinstance(e.value, ValueError)


def test_missing_file_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_dataset(tmp_path / "nope.npz")


def test_format_constant():
    assert FORMAT == "ogm_ppl.dataset"
