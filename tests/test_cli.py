import json

from ogm_ppl.cli import main


def test_run_writes_figures_and_report(tmp_path, capsys):
    assert main(["run", "--out", str(tmp_path)]) == 0
    for name in ("simple2d_maps.png", "toy1d_marginals.png", "report.md", "report.json"):
        assert (tmp_path / name).stat().st_size > 0
    assert not list(tmp_path.glob("*.tmp*"))  # atomic writes leave nothing behind
    report = json.loads((tmp_path / "report.json").read_text())
    maps = report["simple2d"]["maps"]
    assert len(maps) == 7
    for r in maps.values():
        assert 0 < r["best_f1"] <= 1 and 0.5 < r["roc_auc"] <= 1
    # keeping cell correlations (patch map, Gibbs) beats every independent-cell map on this example
    independent = [r["roc_auc"] for k, r in maps.items() if "Gibbs" not in k and "patch" not in k]
    correlated = [r["roc_auc"] for k, r in maps.items() if "Gibbs" in k or "patch" in k]
    assert min(correlated) > max(independent)
    assert "| map | best F1" in capsys.readouterr().out
