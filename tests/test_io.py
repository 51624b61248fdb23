"""ogm_ppl.io: atomic writes leave the old file or the new one, never a mix, and no temporary file behind."""

import errno
import os

import numpy as np
import pytest

from ogm_ppl.io import StagedFolder, atomic_write, atomic_write_bytes, atomic_write_text, writable_folder


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


def test_staged_folder_all_old_until_commit_then_all_new(tmp_path):
    """Outputs staged beside the folder: before commit the folder holds only the old outputs; after it
    only the new ones, with entries the new run did not write (caches) kept; no staging folder left."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "map.npz").write_text("old map")
    (out / "report.json").write_text("old report")
    (out / "cache").mkdir()
    s = StagedFolder(out)
    atomic_write_text(s.path / "map.npz", "new map")
    atomic_write_text(s.path / "report.json", "new report")
    assert (out / "map.npz").read_text() == "old map" and (out / "report.json").read_text() == "old report"
    s.commit()
    assert (out / "map.npz").read_text() == "new map" and (out / "report.json").read_text() == "new report"
    assert (out / "cache").is_dir()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_staged_folder_keeps_the_folders_permissions(tmp_path):
    """A committed folder has the old folder's mode, or a new folder's (``0o777`` less the umask), not the
    private ``0o700`` of the staging folder, so that a map server running as another user can read it."""
    from ogm_ppl.io import _UMASK

    out = tmp_path / "out"
    out.mkdir()
    out.chmod(0o751)
    s = StagedFolder(out)
    atomic_write_text(s.path / "map.npz", "new")
    assert (s.commit().stat().st_mode & 0o7777) == 0o751
    s = StagedFolder(tmp_path / "fresh")
    atomic_write_text(s.path / "map.npz", "new")
    assert (s.commit().stat().st_mode & 0o7777) == 0o777 & ~_UMASK


def test_staged_folder_interrupted_leaves_the_old_folder(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.json").write_text("old")
    s = StagedFolder(out)
    atomic_write_text(s.path / "map.npz", "new")
    del s  # interrupted before commit: the staging folder goes, the old outputs stay
    import gc

    gc.collect()
    assert sorted(p.name for p in out.iterdir()) == ["report.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    # a swap cut between its two renames: the old folder is put back by the next run
    os.replace(out, tmp_path / ".out.old-abc")
    StagedFolder(out)
    assert (out / "report.json").read_text() == "old"


def test_a_write_that_cannot_happen_names_the_file_asked_for(tmp_path):
    """Errors name the target (not the temporary file beside it) and leave nothing behind."""
    folder = tmp_path / "maps"
    folder.mkdir()
    with pytest.raises(IsADirectoryError, match="is a folder; give a file name") as e:
        atomic_write_text(folder, "x")
    assert e.value.filename == str(folder)
    blocker = tmp_path / "plain.txt"
    blocker.write_text("keep")
    with pytest.raises(OSError, match="cannot write it") as e:
        atomic_write_text(blocker / "sub" / "a.json", "x")
    assert e.value.filename == str(blocker / "sub" / "a.json")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["maps", "plain.txt"] and blocker.read_text() == "keep"
    assert list(folder.iterdir()) == []


def test_writable_folder_creates_it_or_says_why_not(tmp_path):
    assert writable_folder(tmp_path / "a" / "b") == tmp_path / "a" / "b"
    assert (tmp_path / "a" / "b").is_dir() and list((tmp_path / "a" / "b").iterdir()) == []
    (tmp_path / "f").write_text("x")
    with pytest.raises(NotADirectoryError, match="exists and is not a folder") as e:
        writable_folder(tmp_path / "f")
    assert e.value.filename == str(tmp_path / "f")
    with pytest.raises(OSError, match="cannot write there") as e:
        writable_folder(tmp_path / "f" / "sub")
    assert e.value.filename == str(tmp_path / "f" / "sub")


def test_a_full_disk_names_the_file_and_keeps_the_old_one(tmp_path, monkeypatch):
    """A write that fails for want of space (``OSError`` ENOSPC naming no file) is raised naming the file asked
    for; the previous file is left whole and no temporary file stays behind."""
    from tests._faults import full_disk

    p = atomic_write_text(tmp_path / "report.json", "old")
    full_disk(monkeypatch)
    for write in (lambda: atomic_write_text(p, "new" * 10_000), lambda: atomic_write_bytes(p, b"x" * 100_000)):
        with pytest.raises(OSError, match=r"No space left on device") as e:
            write()
        assert e.value.errno == errno.ENOSPC and e.value.filename == str(p)
    with pytest.raises(OSError) as e, atomic_write(tmp_path / "m.npz") as f:
        np.savez(f, x=np.zeros(100_000))
    assert e.value.filename == str(tmp_path / "m.npz")
    assert p.read_text() == "old" and sorted(q.name for q in tmp_path.iterdir()) == ["report.json"]


def test_staged_folder_writes_a_linked_folder_in_place_and_leaves_the_link(tmp_path):
    """A symbolic link to a folder is written through: the outputs land in the folder it names, the user's own
    files there stay, the link stays a link, and nothing is written, moved or left beside either of them."""
    real = tmp_path / "real"
    real.mkdir()
    (real / "keep.txt").write_text("mine")
    (real / "ros").mkdir()
    (real / "ros" / "old.pgm").write_text("old ros")
    link = tmp_path / "link"
    link.symlink_to(real)
    for text in ("first", "second"):
        s = StagedFolder(link)
        assert s.in_place and s.path.parent == link
        atomic_write_text(s.path / "map.npz", text)
        atomic_write_text(s.path / "ros" / "map.yaml", text)
        assert (real / "map.npz").exists() == (text == "second")  # nothing replaced before commit
        s.commit()
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "real"]
    assert sorted(p.name for p in real.iterdir()) == ["keep.txt", "map.npz", "ros"]
    assert (real / "keep.txt").read_text() == "mine" and (real / "map.npz").read_text() == "second"
    assert [p.name for p in (real / "ros").iterdir()] == ["map.yaml"]  # an output folder replaces its namesake


def test_staged_folder_of_the_working_directory_is_written_in_place(tmp_path, monkeypatch):
    """``.`` (or a folder holding the working directory) cannot be renamed away: it is written in place, and the
    working directory stays the same folder."""
    work = tmp_path / "work"
    (work / "sub").mkdir(parents=True)
    (work / "map.npz").write_text("old")
    monkeypatch.chdir(work / "sub")
    inode = os.stat(work).st_ino
    for target in ("..", str(work)):
        with StagedFolder(target) as s:
            assert s.in_place
            atomic_write_text(s.path / "map.npz", target)
        assert (work / "map.npz").read_text() == target and os.stat(work).st_ino == inode
    assert sorted(p.name for p in work.iterdir()) == ["map.npz", "sub"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["work"]


def test_staged_folder_as_a_context_discards_on_error_and_names_the_target(tmp_path):
    """Leaving the block with an error discards the staged outputs (the old folder as it was, no staging folder
    left); an ``OSError`` naming a staged file names the file in the target instead."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "map.npz").write_text("old")
    with pytest.raises(OSError) as e, StagedFolder(out) as s:
        raise OSError(errno.ENOSPC, "No space left on device", str(s.path / "ros" / "map.pgm"))
    assert e.value.filename == str(out / "ros" / "map.pgm")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"] and (out / "map.npz").read_text() == "old"
