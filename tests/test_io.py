"""ogm_ppl.io: atomic writes leave the old file or the new one, never a mix, and no temporary file behind."""

import os

import numpy as np
import pytest

from ogm_ppl.io import atomic_write, atomic_write_bytes, atomic_write_text


def test_new_file_gets_the_mode_open_would_give(tmp_path):
    umask = os.umask(0o022)
    try:
        p = atomic_write_text(tmp_path / "a.txt", "x")
    finally:
        os.umask(umask)
    assert p.read_text() == "x"
    assert os.stat(p).st_mode & 0o777 == 0o644


def test_existing_file_keeps_its_mode(tmp_path):
    p = tmp_path / "a.bin"
    p.write_bytes(b"old")
    os.chmod(p, 0o640)
    atomic_write_bytes(p, b"new")
    assert p.read_bytes() == b"new" and os.stat(p).st_mode & 0o777 == 0o640


def test_error_inside_the_block_keeps_the_old_file_and_removes_the_temporary(tmp_path):
    p = tmp_path / "m.npz"
    with atomic_write(p) as f:
        np.savez(f, x=np.arange(3))
    with pytest.raises(RuntimeError, match="interrupted"):
        with atomic_write(p) as f:
            f.write(b"half a file")
            raise RuntimeError("interrupted")
    with np.load(p, allow_pickle=False) as z:
        assert z["x"].tolist() == [0, 1, 2]
    assert sorted(q.name for q in tmp_path.iterdir()) == ["m.npz"]


def test_parent_folder_is_created_and_mode_is_checked(tmp_path):
    assert atomic_write_text(tmp_path / "a" / "b" / "c.txt", "z").read_text() == "z"
    with pytest.raises(ValueError, match="mode"):
        with atomic_write(tmp_path / "d", "a"):
            pass
