"""ogm_ppl.studies.map_all_logs: the logs of a shared data folder and their options, and a summary row per log,
one that says a log failed; experiments/map_all_logs.py has its options."""

from ogm_ppl.studies.map_all_logs import COMMON, log_jobs, map_all_logs
from tests._experiments import run_script


def test_the_logs_and_their_options(tmp_path):
    (tmp_path / "carmen").mkdir()
    for name in ("b-corrected.log.gz", "a.log.gz", "notes.txt"):
        (tmp_path / "carmen" / name).write_bytes(b"")
    jobs = log_jobs(tmp_path)
    assert list(jobs) == ["intel", "a", "b"]
    intel = str(tmp_path / "intel-lab" / "intel-corrected.log.gz")
    assert jobs["intel"] == [intel, *COMMON, "--max-usable-range", "20"]
    assert jobs["b"] == [str(tmp_path / "carmen" / "b-corrected.log.gz"), *COMMON]


def test_a_log_that_fails_gets_its_row(tmp_path):
    (tmp_path / "data" / "carmen").mkdir(parents=True)
    (tmp_path / "data" / "carmen" / "bad.log.gz").write_bytes(b"not a log")
    text, failed = map_all_logs(tmp_path / "out", tmp_path / "data", only=["bad"])
    assert failed == ["bad"] and "| bad | failed (exit " in text and "on 1 logs; failed: bad." in text
    assert (tmp_path / "out" / "summary.md").read_text() == text


def test_the_script_has_its_options():
    r = run_script("map_all_logs.py", "--help")
    assert r.returncode == 0 and "--only" in r.stdout and "--data" in r.stdout, r.stderr
