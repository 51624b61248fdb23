"""The experiment runner on dask: serial == a 2-worker local cluster bit for bit, an unreachable scheduler,
a failed task's traceback, Ctrl-C."""

import pytest

from ogm_ppl.experiment import ExperimentError, parse_spec, run_experiment
from tests.experiment._smoke import SMOKE, numbers, same, tiny


def test_serial_equals_two_worker_local_cluster(serial_run, tmp_path):
    r = run_experiment(parse_spec(tiny(), "tiny.toml"), tmp_path, workers=2, progress=False)
    assert not r.failed and not r.skipped
    same(numbers(serial_run.out_dir), numbers(tmp_path))


def test_unreachable_scheduler_fails_within_seconds(tmp_path):
    """A scheduler address nobody listens on: a ConnectionError naming it, within a few seconds."""
    import socket
    import time

    from ogm_ppl.experiment.runner import SCHEDULER_TIMEOUT_S

    with socket.socket() as s:  # a free port, closed again: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    with pytest.raises(ConnectionError, match=rf"127\.0\.0\.1:{port}"):
        run_experiment(parse_spec(tiny(), "tiny.toml"), tmp_path, scheduler=f"tcp://127.0.0.1:{port}", progress=False)
    assert time.monotonic() - t0 < SCHEDULER_TIMEOUT_S + 10


@pytest.mark.parametrize("scheduler", ["serial", None])
def test_a_failed_task_leaves_its_traceback_in_failures_txt(tmp_path, scheduler, capfd):
    """A task that raises: the error names ``failures.txt``, which holds its traceback (on dask too, where the
    workers' own "Compute Failed" reports are kept out of the log); a rerun with nothing failing removes it.
    The sensor is registered in this process only: dask's worker processes do not know it (as when its module
    is missing from $OGM_PPL_METHODS), and say so."""
    from ogm_ppl.sensors import GaussianRange, register_sensor, unregister_sensor

    state = {"fail": True}

    def flaky(sigma_cells, p_rand):
        if state["fail"]:
            raise ValueError("flaky sensor refuses today")
        return GaussianRange(sigma_cells, p_rand)

    register_sensor("test_flaky", flaky)
    try:
        d = tiny()
        d["algorithms"] = [d["algorithms"][0], {"name": "g", "kind": "gibbs", "sweeps": 2, "sensor": "test_flaky"}]
        d["output"] = {"maps": False, "figures": False}
        spec = parse_spec(d, "tiny.toml")
        with pytest.raises(ExperimentError) as e:
            run_experiment(spec, tmp_path, scheduler=scheduler, workers=1, progress=False)
        failures = tmp_path / "failures.txt"
        assert f"tracebacks in {failures}" in str(e.value)
        # the one run task (one dataset, one chain) and the score task that needed it
        assert "1 of " in str(e.value) and "tasks failed, and 1 that depend on them (first: run/" in str(e.value)
        text = failures.read_text()
        assert "Compute Failed" not in capfd.readouterr().err
        if scheduler is None:
            assert "unknown sensor kind 'test_flaky'" in text and "Traceback (most recent call last)" in text
            return
        assert "ValueError: flaky sensor refuses today" in text and 'in flaky\n    raise ValueError("flaky' in text
        state["fail"] = False
        run_experiment(spec, tmp_path, scheduler=scheduler, progress=False)
        assert not failures.exists()
    finally:
        unregister_sensor("test_flaky")


def test_ctrl_c_stops_a_dask_run_with_one_line_and_no_worker_tracebacks(tmp_path):
    """Ctrl-C reaches every process of the run (a terminal signals the whole process group): the driver stops
    and closes its cluster, the workers ignore it (no "KeyboardInterrupt" traceback from each), and a worker's
    heartbeat to the closed scheduler is kept out of the log; exit status 130."""
    import os
    import signal
    import subprocess
    import sys
    import time

    spec = SMOKE.read_text().replace("pose_fraction = [1.0, 0.5]", "pose_fraction = 1.0")
    spec = spec.replace('name = "smoke"', 'name = "long"', 1)
    spec += '\n[[algorithms]]\nname = "long"\nkind = "gibbs"\nsweeps = 200000\nchains = 2\n'
    path = tmp_path / "long.toml"
    path.write_text(spec)
    env = dict(os.environ, PYTHONPATH=str(SMOKE.parents[2]))
    p = subprocess.Popen(
        [sys.executable, "-m", "ogm_ppl", "experiment", str(path), "--workers", "2", "--out", str(tmp_path / "out")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not list((tmp_path / "out").glob("tasks/*/long/c*/gibbs.npz")) and time.monotonic() < deadline:
            assert p.poll() is None, p.communicate()
            time.sleep(0.5)  # the long chains have started (their first checkpoint is written)
        os.killpg(p.pid, signal.SIGINT)
        _, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 130, err
    assert err.rstrip().endswith(
        f"ogm-ppl: interrupted; finished tasks and the samplers' checkpoints are kept in {tmp_path / 'out'}: the "
        "same command resumes from them"
    ), err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
