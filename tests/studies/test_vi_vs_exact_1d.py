"""ogm_ppl.studies.vi_vs_exact_1d: every guide and objective fitted on the thesis's toy and scored against the
exact posterior; the page names the command; experiments/vi_vs_exact_1d.py is its command line."""

import pytest

from ogm_ppl.studies.errors import StudyOptionError
from ogm_ppl.studies.vi_vs_exact_1d import RUNS, vi_vs_exact_1d, vi_vs_exact_1d_markdown
from tests._experiments import run_script


def test_every_fit_is_scored_and_the_closed_form_objective_fits_best(tmp_path):
    rows = vi_vs_exact_1d(quick=True, out_dir=tmp_path, progress=False)
    assert rows[0][:4] == ("exact (pose-constrained 1D)", "-", 0, 0.0) and len(rows) == len(RUNS) + 1
    assert [r[:3] for r in rows[1:]] == [(label, loss, max(steps // 5, 20)) for label, _, loss, steps, _, _ in RUNS]
    kl = {(g, o): k for g, o, _, k, _ in rows[1:]}
    assert all(k >= 0 for k in kl.values())
    assert kl[("first hit", "exact")] <= kl[("first hit", "tracegraph")]
    text = (tmp_path / "vi_vs_exact_1d.md").read_text()
    assert (
        text == vi_vs_exact_1d_markdown(rows, True, 0)
        and "`ogm_ppl.studies.vi_vs_exact_1d.vi_vs_exact_1d(quick=True, seed=0)`" in text
    )
    with pytest.raises(StudyOptionError, match="seed"):
        vi_vs_exact_1d(seed=-1, progress=False)


def test_the_script_has_its_options():
    r = run_script("vi_vs_exact_1d.py", "--help")
    assert r.returncode == 0 and "--quick" in r.stdout and "--seed" in r.stdout, r.stderr
