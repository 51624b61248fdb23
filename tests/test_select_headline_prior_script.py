"""experiments/select_headline_prior.py is ``ogm-ppl fit-prior headline`` with its options and the package's
file replaced without ``--out``; ``--quick``'s settings are tested in tests/learn/test_select_headline.py."""

from tests._experiments import run_script


def test_the_script_offers_the_commands_options():
    r = run_script("select_headline_prior.py", "--help")
    assert r.returncode == 0, r.stderr
    text = " ".join(r.stdout.split())
    for option in ("--corpus", "--candidates", "--plans", "--fit-limit", "--name", "--quick", "--ship", "--out"):
        assert option in text, option
    assert "(the default without --out)" in text
    bad = run_script("select_headline_prior.py", "--candidates", "border", "--out", "/nonexistent/never")
    assert bad.returncode == 2 and "error: candidates" in bad.stderr
