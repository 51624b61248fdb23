"""experiments/fit_temper.py is a front of ogm_ppl.learn.fit_temper: ``--quick`` gives the library its small
settings and the folder, and no ``--out`` ships."""

import sys

from ogm_ppl.learn import FitResult
from tests._scripts import load_experiment


def test_quick_passes_its_settings_to_the_library(tmp_path, monkeypatch):
    mod = load_experiment("fit_temper_script", "fit_temper.py")
    try:
        calls = []
        monkeypatch.setattr(
            mod, "fit_temper", lambda *a, **kw: calls.append((a, kw)) or FitResult("temper", (), {}, {}, 0)
        )
        assert mod.main(["--quick", "--out", str(tmp_path)]) == []
        mod.main(["--corpus", "ipa", "--kinds", "border_bo"])
        (args, kw), (args2, kw2) = calls
        s = kw["settings"]
        assert args == (["dungeon"], tmp_path) and not kw["ship"] and not kw["update"]
        assert (s.plans, s.window, s.sweeps, s.burn, s.fit_limit) == (2, 48, 10, 4, 10)
        assert s.kinds == mod.KINDS[:2] and s.betas == mod.BETAS[:2]
        assert args2 == (["ipa"], None) and kw2["ship"] and kw2["settings"].kinds == ("border_bo",)
    finally:
        sys.modules.pop("fit_temper_script", None)
