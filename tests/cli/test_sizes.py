"""``ogm-ppl map`` refuses work that would not fit (memory, time, int64) at once, naming the parameter or option,
the estimate and the limit."""

import importlib
import re

import pytest

from ogm_ppl.cli import main
from tests.test_cli import write_log


@pytest.fixture
def little_memory(monkeypatch):
    """64 MiB free, and a ray cast fails the test if it starts."""
    import ogm_ppl._memory

    def never(*a, **k):
        raise AssertionError("the ray cast started")

    monkeypatch.setattr(ogm_ppl._memory, "available_memory", lambda: 64 << 20)
    monkeypatch.setattr(importlib.import_module("ogm_ppl.raycast"), "traverse_all", never)


def test_an_update_term_whose_table_grows_with_its_cube_is_refused_before_it_is_built(tmp_path, capsys):
    """Elfes's term sums over every first hit for each table entry: at 1 cm its table would take far more than
    the memory (the test pretends 1 GiB is free); refused with the term named, not a raw allocator error."""
    import ogm_ppl._memory

    log = write_log(tmp_path / "tiny.log")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ogm_ppl._memory, "available_memory", lambda: 1 << 30)
        assert main(["map", str(log), "--resolution", "0.01", "--method", "elfes", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    table = r"building the update term's table \(Elfes\) of 747 x 748 float64 entries"
    assert re.search(table + r".* needs about [\d.]+ GiB, more than the 1\.0 GiB", err), err


@pytest.mark.parametrize(
    "method, message",
    [
        (
            "gibbs",
            r"the ray cast on a 2501 x 3001 grid and a model and sampler over its rays \(12 bytes for each of the "
            r"[\d,]+ cells it makes room for, all 724 rays up to the sensor's maximum range, and 73 a ray, then 52 "
            r"more bytes for each of the up to [\d,]+ cells the rays cross inside the grid and the likelihood "
            r"table's working blocks\) needs about [\d.]+ MiB, more than the 64\.0 MiB this machine has free",
        ),
        (
            "ogm",
            r"traditional OGM on a 2501 x 3001 grid \(building the update term's table \(Moravec\) of [\d,]+ x "
            r"[\d,]+ float64 entries, a ray's most cells up to the sensor's maximum range of [\d.]+ m, and a copy "
            r"of it; \d+ bytes a cell with \d+ thread\(s\)\) "
            r"needs about [\d.]+ MiB, more than the 64\.0 MiB",
        ),
    ],
)
def test_a_map_too_fine_for_the_memory_is_refused_before_the_ray_cast(tmp_path, little_memory, capsys, method, message):
    """A log at a resolution far finer than the memory allows: one error line with the estimate, its basis and
    the free memory, before the ray cast (which alone needs about half the model's estimate) allocates
    anything."""
    log = write_log(tmp_path / "tiny.log")
    argv = ["map", str(log), "--resolution", "0.002", "--method", method, "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("ogm-ppl: error: ")
    assert re.search(message, err), err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--method", "gibbs", "--param", "sweeps=" + "9" * 23], "--param sweeps: must be <= 1000000000 (ogm_ppl"),
        (["--method", "gibbs", "--sweeps", "9" * 23], "argument --sweeps: must be <= 1000000000 (ogm_ppl.methods"),
        (["--method", "vi", "--param", "loss=rws", "--param", "num_particles=1000000000"], "num_particles: "),
        (["--method", "tempering", "--param", "rungs=10000000"], "rungs: 10,000,000 rungs of parallel tempering"),
        (["--seed", "9" * 20], "argument --seed: must be <= 4611686018427387904, got 99999999999999999999"),
    ],
)
def test_parameters_past_their_limits_are_one_error_line(tmp_path, simulated_dataset, capsys, argv, message):
    """Huge sweep counts are refused as the parameters are parsed; huge particle and rung counts before the
    model is built; each one line naming the option or parameter."""
    import ogm_ppl._memory

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ogm_ppl._memory, "available_memory", lambda: 8 << 30)
        rc = main(["map", str(simulated_dataset), "--out", str(tmp_path / "o"), *argv])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.count("\n") == 0 and err.startswith(f"ogm-ppl: error: {message}"), err
