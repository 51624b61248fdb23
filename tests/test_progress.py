"""ogm_ppl.progress: plain lines off a terminal (first, throttled, last), nothing when disabled."""

import io

from ogm_ppl.progress import Progress, interactive


def test_plain_lines_first_every_and_last(monkeypatch):
    now = [0.0]
    monkeypatch.setattr("ogm_ppl.progress.time.perf_counter", lambda: now[0])
    s = io.StringIO()
    assert not interactive(s)
    p = Progress(4, "tasks", stream=s, every=10.0)  # first line at t = 0
    for t, note in ((5.0, "a"), (12.0, "b"), (30.0, "c"), (31.0, "d")):
        now[0] = t
        p.update(note=note)  # a line when 10 s passed since the last one, never for the last step
    now[0] = 40.0
    p.close()
    lines = s.getvalue().splitlines()
    assert lines[0] == "tasks: 0/4 (0 %), 0 s"
    # the pace after the first step: 7 s a step at b, (30 - 5) / 2 at c
    assert lines[1] == "tasks: 2/4 (50 %), 12 s, ~14 s left; last: b"
    assert lines[2] == "tasks: 3/4 (75 %), 30 s, ~12 s left; last: c"
    assert lines[3] == "tasks: 4/4 (100 %), 40 s, done" and len(lines) == 4


def test_disabled_prints_nothing_and_close_is_idempotent():
    s = io.StringIO()
    with Progress(3, "x", stream=s, enabled=False) as p:
        p.update()
    assert s.getvalue() == ""
    s = io.StringIO()
    p = Progress(1, "x", stream=s, every=0.0)
    p.update()
    p.close()
    p.close()
    assert s.getvalue().count("done") == 1


def test_a_run_closed_before_its_last_step_says_stopped_not_done():
    s = io.StringIO()
    with Progress(4, "tasks", stream=s, every=1e9) as p:
        p.update()
    assert s.getvalue().splitlines()[-1].endswith("1/4 (25 %), 0 s, stopped")


def test_after_keeps_a_short_run_quiet_and_a_resumed_run_estimates_from_its_own_steps(monkeypatch):
    """``after``: no line before that many seconds, none at all for a run that ends sooner; ``initial``: a
    resumed run starts at its steps done and times what is left by this run's pace."""
    now = [0.0]
    monkeypatch.setattr("ogm_ppl.progress.time.perf_counter", lambda: now[0])
    s = io.StringIO()
    with Progress(100, "gibbs sweeps", stream=s, after=10.0) as p:
        now[0] = 9.0
        p.update(50)
    assert s.getvalue() == ""
    now[0] = 0.0
    p = Progress(100, "gibbs sweeps", stream=s, after=10.0, every=10.0, initial=40)
    now[0] = 9.0
    p.update(10)
    assert s.getvalue() == ""
    now[0] = 10.0
    p.update(10)  # 10 steps in the 1 s after the first update, 40 to go
    now[0] = 15.0
    p.update(10)  # within ``every`` of the last line: quiet
    now[0] = 30.0
    p.update(30)
    p.close()
    assert s.getvalue().splitlines() == [
        "gibbs sweeps: 60/100 (60 %), 10 s, ~4 s left",
        "gibbs sweeps: 100/100 (100 %), 30 s, done",
    ]


def test_a_slow_first_step_does_not_set_the_pace(monkeypatch):
    """A first step that compiled kernels (45 s) before steps of 0.1 s: the time left is that of 0.1 s steps."""
    now = [0.0]
    monkeypatch.setattr("ogm_ppl.progress.time.perf_counter", lambda: now[0])
    s = io.StringIO()
    p = Progress(1001, "gibbs sweeps", stream=s, every=10.0, after=10.0)
    now[0] = 45.0
    p.update()
    for _ in range(100):
        now[0] += 0.1
        p.update()
    # no time left after the first step alone; then the 0.1 s steps' pace
    assert s.getvalue().splitlines() == [
        "gibbs sweeps: 1/1001 (0 %), 45 s",
        "gibbs sweeps: 101/1001 (10 %), 55 s, ~90 s left",
    ]


def test_progress_over_leaves_a_callers_progress_open_and_closes_its_own():
    """A run given its caller's Progress updates it and leaves it open (one chain in several calls: one
    "done" line at the end); given True it makes its own and closes it."""
    from ogm_ppl.progress import progress_over

    s = io.StringIO()
    mine = Progress(4, "sweeps", stream=s, every=0.0, bar=False)
    for _ in range(2):
        with progress_over(mine, 4, "ignored", unit="sweep") as bar:
            assert bar is mine
            bar.update(2)
    assert "done" not in s.getvalue()
    mine.close()
    assert s.getvalue().count("done") == 1
    with progress_over(False, 3, "x", unit="sweep") as own:
        assert isinstance(own, Progress) and not own.enabled
