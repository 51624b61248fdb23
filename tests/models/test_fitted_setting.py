"""The setting a Delta term was fitted for travels with it: ``DeltaFamily.fitted_setting``
and ``fitted_setting(delta_or_name)``."""

import json

import pytest

from ogm_ppl.models import PN, DeltaFileError, Moravec, delta_by_name, load_delta
from ogm_ppl.models.delta import THESIS_SETTING, fitted_names, fitted_setting, load_fitted


def test_shipped_terms_carry_their_training_block():
    for name in fitted_names():
        fam, rec = load_fitted(name)
        assert fam.fitted_setting == {**rec["training"], "name": name}
        assert fam.training is True  # nn.Module's train/eval flag is untouched
    s = fitted_setting("p21")
    assert (s["name"], s["sigma"], s["F"], s["wall"]) == ("p21", 3.0, 75, 60)
    assert delta_by_name("p21").fitted_setting == s


def test_thesis_terms_hold_section_2_5_setting_and_hand_set_ones_none():
    for name in ("p21_thesis", "moravec_thesis", "elfes_thesis", "stachniss_thesis"):
        assert fitted_setting(name) == {**THESIS_SETTING, "name": name}
    assert (THESIS_SETTING["sigma"], THESIS_SETTING["F"], THESIS_SETTING["wall"]) == (3.0, 75, 60)
    assert fitted_setting("haehnel") is None
    assert fitted_setting(Moravec(1.0, -1.0)) is None and PN.zeros(3).fitted_setting is None


def test_fitted_setting_is_a_copy():
    fam = delta_by_name("p21")
    fitted_setting(fam)["sigma"] = 1.0
    assert fam.fitted_setting["sigma"] == 3.0


def test_load_delta_keeps_the_setting_and_rejects_a_bad_block(tmp_path):
    from importlib import resources

    rec = json.loads((resources.files("ogm_ppl") / "fitted" / "delta_p21.json").read_text())
    path = tmp_path / "d.json"
    path.write_text(json.dumps(rec))
    assert load_delta(path).fitted_setting == {**rec["training"], "name": "p21"}
    path.write_text(json.dumps({k: v for k, v in rec.items() if k != "training"}))
    assert load_delta(path).fitted_setting is None
    path.write_text(json.dumps({**rec, "training": "sigma 3"}))
    with pytest.raises(DeltaFileError, match=r"d\.json: 'training' must be an object, got str"):
        load_delta(path)
