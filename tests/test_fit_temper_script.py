"""experiments/fit_temper.py is ``ogm-ppl fit-prior temper`` with its options, every corpus by default and the
package's file replaced without ``--out``; ``--quick``'s settings are tested in tests/learn/test_fit_temper.py."""

from tests._experiments import run_script


def test_the_script_offers_the_commands_options():
    r = run_script("fit_temper.py", "--help")
    assert r.returncode == 0, r.stderr
    text = " ".join(r.stdout.split())
    for option in ("--corpus", "--kinds", "--betas", "--fit-limit", "--max-support", "--quick", "--ship", "--out"):
        assert option in text, option
    assert "(the default without --out)" in text
    bad = run_script("fit_temper.py", "--betas", "2", "--out", "/nonexistent/never")
    assert bad.returncode == 2 and "error: betas" in bad.stderr
