"""experiments/select_headline_prior.py is a front of ogm_ppl.learn.select_headline_prior: ``--quick`` gives
the library its small settings, ``--out FILE`` the folder and name, and no ``--out`` ships."""

import sys

from ogm_ppl.learn import FitResult
from tests._scripts import load_experiment


def test_quick_passes_its_settings_to_the_library(tmp_path, monkeypatch):
    mod = load_experiment("select_headline_prior_script", "select_headline_prior.py")
    try:
        calls = []
        out = tmp_path / "sel.json"
        out.write_text("{}")

        def fake(*a, **kw):
            calls.append((a, kw))
            return FitResult("headline", (out,), {}, {}, 0)

        monkeypatch.setattr(mod, "select_headline_prior", fake)
        assert mod.main(["--quick", "--out", str(out)]) == {}
        mod.main(["--corpus", "ipa"])
        (args, kw), (args2, kw2) = calls
        s = kw["settings"]
        assert args == (tmp_path,) and kw["name"] == "sel" and not kw.get("ship")
        assert (s.plans, s.window, s.sweeps, s.burn, s.fit_limit) == (2, 64, 6, 2, 10)
        assert s.candidates == mod.CANDIDATES[:2]
        assert args2 == () and kw2["ship"] and kw2["settings"].corpus == "ipa" and kw2["settings"].fit_limit is None
    finally:
        sys.modules.pop("select_headline_prior_script", None)
