"""ogm_ppl.calibration.names: the matrix of prior names, and bias files refused naming the file."""

import json

import pytest

from ogm_ppl.calibration import BIAS_FORMAT, BiasFileError, load_bias_file, name_digest, prior_names
from ogm_ppl.calibration.names import kind_label


def test_prior_names_cover_the_matrix_once():
    got = prior_names(["independent", "mrf", "border:ipa", "mrf"], ["houseexpo", "ipa"])
    assert got == [
        ("independent", None),
        ("independent:houseexpo", "houseexpo"),
        ("independent:ipa", "ipa"),
        ("mrf:houseexpo", "houseexpo"),
        ("mrf:ipa", "ipa"),
        ("border:ipa", "ipa"),
    ]
    assert prior_names(["mrf@cal"], ["ipa"]) == [("mrf:ipa@cal", "ipa")]
    assert kind_label("border_bo:ipa@cal") == "border_bo@cal" and kind_label("border1_bo:ipa+bias") == "border1_bo+bias"


def test_a_bias_changes_the_digest_of_its_name_only():
    plain = name_digest("mrf:ipa", {}, {})
    assert name_digest("mrf:ipa+bias", {"mrf:ipa": 0.5}, {}) != plain
    assert name_digest("mrf:ipa", {"mrf:ipa": 0.5}, {}) == plain
    assert name_digest("traditional OGM (p21)", {}, {}) == "ogm"


def test_bias_files_are_read_and_bad_ones_named(tmp_path):
    assert load_bias_file(None) == {}
    p = tmp_path / "bias.json"
    p.write_text(json.dumps({"format": BIAS_FORMAT, "bias": {"patch3:houseexpo": 1}}))
    assert load_bias_file(p) == {"patch3:houseexpo": 1.0}
    for text in ('{"format": "ogm_ppl.prior_bias", "bias": {"a": "high"}}', '{"bias": {"a": 1.0}}', "{", "[]"):
        p.write_text(text)
        with pytest.raises(BiasFileError, match=f"{p}: not a bias file"):
            load_bias_file(p)
    with pytest.raises(BiasFileError, match="not a bias file"):
        load_bias_file(tmp_path / "missing.json")
