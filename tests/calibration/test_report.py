"""ogm_ppl.calibration.report: bar labels, and which rows a test corpus's own table shows."""

from ogm_ppl.calibration.report import bar_labels, fmt, shown


def test_bar_labels_drop_the_test_corpus_unless_two_would_read_alike():
    names = ["independent", "independent:ipa", "patch3:ipa", "guide:houseexpo"]
    assert bar_labels(names, "ipa") == ["independent", "independent:ipa", "patch3", "guide:houseexpo"]


def test_a_corpus_table_shows_its_own_methods_and_a_plan_set_every_one():
    rows = [{"train": t} for t in ("ipa", "houseexpo", "none", "own", "ipa@sym")]
    assert [shown(r, "ipa") for r in rows] == [True, False, True, True, True]
    assert all(shown(r, "mine") for r in rows)
    assert (fmt(None), fmt(float("nan")), fmt(0.12345)) == ("", "", "0.123")
