"""Where the command line writes: never over what it reads, through a linked folder, into ``.``, and a full disk
named with the previous result kept."""

import os

import pytest

from ogm_ppl.cli import load_map, main
from tests._faults import full_disk
from tests.test_cli import MAP_FILES, write_log


def _files(folder):
    return {p.relative_to(folder): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_convert_onto_its_own_log_is_refused_and_the_log_kept(tmp_path, capsys):
    """``convert x.log --out x.log`` (or a link to it, or a hard link) is refused before anything is read or
    written: the log stays as it was."""
    log = write_log(tmp_path / "x.log")
    before = log.read_bytes()
    (tmp_path / "soft.npz").symlink_to(log)
    os.link(log, tmp_path / "hard.npz")
    for out in (log, tmp_path / "soft.npz", tmp_path / "hard.npz", tmp_path / "." / "x.log"):
        assert main(["convert", str(log), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert err == f"ogm-ppl: error: --out {out} is the input {log}: writing it would replace what it is read from"
    assert log.read_bytes() == before and (tmp_path / "soft.npz").is_symlink()


def test_map_onto_or_over_its_own_input_is_refused(tmp_path, simulated_dataset, capsys):
    """Any command: ``--out`` equal to the input, inside an input folder, or a map folder whose map.npz would
    replace the input there, is refused naming both; an input elsewhere in the folder is fine."""
    folder = tmp_path / "run1"
    folder.mkdir()
    inside = folder / "map.npz"
    inside.write_bytes(simulated_dataset.read_bytes())
    bag = tmp_path / "bag"
    bag.mkdir()
    cases = [
        (["map", str(simulated_dataset), "--out", str(simulated_dataset)], "is the input"),
        (["map", str(inside), "--out", str(folder)], f"--out {folder}: its map.npz would replace the input {inside}"),
        (["convert", str(bag), "--out", str(bag / "x.npz")], f"--out {bag / 'x.npz'} lies inside the input {bag}"),
        (["simulate", "--map", str(simulated_dataset), "--out", str(simulated_dataset)], "is the input"),
    ]
    for argv, message in cases:
        assert main(argv) == 2, argv
        assert message in capsys.readouterr().err
    assert inside.read_bytes() == simulated_dataset.read_bytes()
    elsewhere = folder / "data.npz"
    os.replace(inside, elsewhere)
    assert main(["map", str(elsewhere), "--out", str(folder)]) == 0
    assert elsewhere.exists() and (folder / "map.npz").exists()


def test_map_into_a_linked_folder_writes_through_the_link(tmp_path, simulated_dataset):
    """``ln -s real link; map --out link``: the link stays a link, the outputs land in ``real`` beside the user's
    own files, and nothing else in the link's folder is written, moved or left behind; a second run replaces the
    outputs there."""
    real = tmp_path / "real"
    real.mkdir()
    (real / "keep.txt").write_text("mine")
    link = tmp_path / "link"
    link.symlink_to(real)
    for _ in range(2):
        assert main(["map", str(simulated_dataset), "--out", str(link)]) == 0
        assert link.is_symlink() and os.readlink(link) == str(real)
        assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "real", "sim.npz"]
        assert (real / "keep.txt").read_text() == "mine"
        assert sorted(str(p.relative_to(real)) for p in real.rglob("*") if p.is_file()) == sorted(
            [*MAP_FILES, "keep.txt"]
        )
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    assert main(["map", str(simulated_dataset), "--out", str(tmp_path / "dangling")]) == 2
    assert not (tmp_path / "nowhere").exists()


def test_map_into_the_working_directory(tmp_path, simulated_dataset, monkeypatch, capsys):
    """``--out .`` writes the map in the working directory (which stays the same folder), the user's files kept."""
    work = tmp_path / "work"
    work.mkdir()
    (work / "notes.txt").write_text("mine")
    monkeypatch.chdir(work)
    inode = os.stat(work).st_ino
    assert main(["map", str(simulated_dataset), "--out", "."]) == 0
    assert os.stat(".").st_ino == inode and os.path.samefile(os.getcwd(), work)
    assert sorted(str(p.relative_to(work)) for p in work.rglob("*") if p.is_file()) == sorted([*MAP_FILES, "notes.txt"])
    assert capsys.readouterr().out.strip().endswith("-> .")


def test_a_map_written_to_a_full_disk_names_the_file_and_keeps_the_previous_map(tmp_path, simulated_dataset, capsys):
    """Disk full while the map is written: one error line naming OUT/map.npz and the reason; the previous run's
    outputs are left whole and no staging folder is left behind."""
    out = tmp_path / "out"
    assert main(["map", str(simulated_dataset), "--out", str(out)]) == 0
    before = _files(out)
    with pytest.MonkeyPatch.context() as mp:
        full_disk(mp)
        capsys.readouterr()
        assert main(["map", str(simulated_dataset), "--out", str(out), "--method", "elfes"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err == f"ogm-ppl: error: {out / 'map.npz'}: cannot write it (No space left on device)"
    assert _files(out) == before and load_map(out / "map.npz")["method"] == "ogm"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "sim.npz"]
