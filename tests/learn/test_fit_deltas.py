"""fit_deltas and fit_delta_setting: the Delta fits as workflows. Each term equals the lower-level fit
(fit_delta, warm_start_pn, cross_entropy_loss, fit_delta_for_setting) on the same data in this process (the
same code on the same inputs: equal bit for bit), is read back by the Delta readers (load_delta,
delta_by_name(path=), load_setting_fit, the setting fit's cache), records the command that remakes it, writes
into the folder named only; refused options are named with their limit, before any work; the commands.

Tiny settings (F = 20 cells, 8 datasets): seconds. The network fits (neural_opt, neural_dd: half a minute
each even here) are left to experiments/fit_deltas.py's run."""

import json
import shlex

import numpy as np
import pytest
import torch

from ogm_ppl.cli import main as ogm_ppl
from ogm_ppl.datasets import wall_datasets
from ogm_ppl.inference.variational import fit_delta_for_setting, load_setting_fit
from ogm_ppl.inference.variational.delta_fit import cross_entropy_loss, fit_delta, warm_start_pn
from ogm_ppl.inference.variational.setting_fit import fit_on_data
from ogm_ppl.learn import FitOptionError, fit_delta_setting, fit_deltas
from ogm_ppl.learn.deltas import FIT, REFERENCES
from ogm_ppl.models.delta import MarshallBarfoot, Moravec, delta_by_name, fitted_setting, load_delta
from tests.learn._helpers import files_under, fitted_dir_listing

SMALL = {"datasets": 8, "folds": 2, "sigma": 2.0, "F": 20, "wall": 16}
FAMILIES = ["moravec_opt", "marshall_barfoot_opt", "p3"]


def _direct(data) -> dict:
    """The fits of FAMILIES on ``data`` by the lower-level functions, as fit_deltas documents them."""
    out = {"moravec_opt": fit_delta(Moravec.haehnel(), data, **FIT)}
    mb = [fit_delta(MarshallBarfoot(1.3863, beta), data, **FIT) for beta in range(1, 6)]
    out["marshall_barfoot_opt"] = min(mb, key=lambda r: r.train_loss)  # the first of equal losses, as the fit
    prev = None
    for N in (1, 2, 3):
        out[f"p{N}"] = fit_delta(warm_start_pn(prev, N), data, **FIT)
        prev = out[f"p{N}"].family
    return out


def _same(a, b) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return type(a) is type(b) and sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    root = tmp_path_factory.mktemp("deltas")
    shipped = fitted_dir_listing()
    r = fit_deltas(root / "out", families=FAMILIES, progress=False, **SMALL)
    assert fitted_dir_listing() == shipped
    return root, r


def test_each_term_equals_the_lower_level_fit_and_loads_back(fitted):
    root, r = fitted
    names = [f"delta_{n}.json" for n in FAMILIES] + ["delta_cv.json"]
    assert [f.name for f in r.files] == names and files_under(root) == {f"out/{n}" for n in names}
    data = wall_datasets(num=8, F=20, wall=16, sigma=2.0, seed=0)
    direct = _direct(data)
    for name in FAMILIES:
        term = load_delta(root / "out" / f"delta_{name}.json")
        assert _same(term, direct[name].family), name
        assert _same(delta_by_name(name, path=root / "out"), term)  # by name in the folder, and by path
        assert _same(delta_by_name("anything", path=root / "out" / f"delta_{name}.json"), term)
        rec = json.loads((root / "out" / f"delta_{name}.json").read_text())
        assert rec["train_cross_entropy"] == direct[name].train_loss
        assert rec["provenance"]["command"] == r.provenance["command"]
        setting = fitted_setting(term)
        assert (setting["sigma"], setting["F"], setting["wall"], setting["num"]) == (2.0, 20, 16, 8)
        assert setting["function"] == "ogm_ppl.learn.fit_deltas" and setting["name"] == name
    assert (
        load_delta(root / "out" / "delta_marshall_barfoot_opt.json").beta == direct["marshall_barfoot_opt"].family.beta
    )


def test_cross_validation_equals_fitting_each_fold_directly(fitted):
    root, r = fitted
    data = wall_datasets(num=8, F=20, wall=16, sigma=2.0, seed=0)
    scores: dict[str, list[float]] = {}
    for k in range(2):  # fold k = datasets 4k .. 4k + 3
        held = data.subset(torch.arange(4 * k, 4 * k + 4))
        fits = _direct(data.subset(torch.tensor([i for i in range(8) if i // 4 != k])))
        with torch.no_grad():
            for name in FAMILIES:
                scores.setdefault(name, []).append(float(cross_entropy_loss(fits[name].family, held)))
            for name in REFERENCES:
                scores.setdefault(name, []).append(float(cross_entropy_loss(delta_by_name(name), held)))
    cv = json.loads((root / "out" / "delta_cv.json").read_text())
    assert list(cv["cv"]) == FAMILIES + list(REFERENCES)
    for name, v in scores.items():
        assert r.summary["cv"][name]["folds"] == v
        assert cv["cv"][name] == {"mean": float(np.mean(v)), "std": float(np.std(v))}
    for name in FAMILIES:
        rec = json.loads((root / "out" / f"delta_{name}.json").read_text())
        assert rec["heldout_cross_entropy"] == float(np.mean(scores[name]))
    assert cv["params"] == {"moravec_opt": 2, "marshall_barfoot_opt": 2, "p3": 3, **{n: 2 for n in REFERENCES[:3]}} | {
        "p21_thesis": 21
    }
    assert "| p3 | 3 |" in r.summary["markdown"]


def test_the_recorded_command_remakes_the_files(fitted, capsys):
    root, r = fitted
    cmd = r.provenance["command"]
    assert cmd == (
        f"ogm-ppl fit-prior deltas --out {root / 'out'} --datasets 8 --folds 2 --sigma 2 --F 20 --wall 16 "
        "--families moravec_opt marshall_barfoot_opt p3"
    )
    argv = shlex.split(cmd)[1:]
    argv[argv.index("--out") + 1] = str(root / "again")
    assert ogm_ppl([*argv, "--quiet"]) == 0
    assert "delta_p3.json" in capsys.readouterr().out
    for name in FAMILIES:
        a, b = (json.loads((root / d / f"delta_{name}.json").read_text()) for d in ("out", "again"))
        assert a["delta"] == b["delta"] and a["train_cross_entropy"] == b["train_cross_entropy"]
        assert a["heldout_cross_entropy"] == b["heldout_cross_entropy"]


def test_p21_dd_starts_from_the_uniform_chain_and_fits_the_data_driven_target(tmp_path):
    r = fit_deltas(tmp_path, datasets=4, folds=0, sigma=1.0, F=10, wall=8, families=["p21_dd"], progress=False)
    assert [f.name for f in r.files] == ["delta_p21_dd.json", "delta_cv.json"]
    data = wall_datasets(num=4, F=10, wall=8, sigma=1.0, seed=0)
    dd = wall_datasets(num=4, F=10, wall=8, sigma=1.0, seed=0, prior="data_driven")
    prev = None
    for N in range(1, 21):
        prev = fit_delta(warm_start_pn(prev, N), data, **FIT).family
    direct = fit_delta(warm_start_pn(prev, 21), dd, **FIT)
    term = delta_by_name("p21_dd", path=tmp_path)
    assert _same(term, direct.family) and fitted_setting(term)["prior"] == "data_driven"
    assert r.summary["data_driven"] == {"p21_dd": direct.train_loss}
    rec = json.loads((tmp_path / "delta_p21_dd.json").read_text())
    assert rec["heldout_cross_entropy"] is None and r.summary["cv"] == {}


def test_a_setting_fit_equals_fit_delta_for_setting_and_is_read_back_and_reused(tmp_path):
    kw = {"sigma": 2.0, "F": 20, "num": 6, "heldout": 4}
    shipped = fitted_dir_listing()
    r = fit_delta_setting(tmp_path / "out", family=["p3", "moravec_opt"], **kw)
    assert fitted_dir_listing() == shipped
    stems = {n: f"{n}_sigma2_F20_wall16_n6_r1-10_seed0_uniform" for n in ("p3", "moravec_opt")}
    assert files_under(tmp_path) == {f"out/delta_{s}.json" for s in stems.values()}
    assert r.provenance["command"] == (
        f"ogm-ppl fit-prior delta-setting --family p3 moravec_opt --sigma 2 --F 20 --num 6 --heldout 4 "
        f"--out {tmp_path / 'out'}"
    )
    data = wall_datasets(num=6, F=20, wall=16, sigma=2.0, seed=0)
    for name, stem in stems.items():
        lower, training = fit_delta_for_setting(name, 2.0, 20, num=6, heldout=4)
        path = tmp_path / "out" / f"delta_{stem}.json"
        family, tr = load_setting_fit(path)
        assert _same(family, lower) and _same(family, fit_on_data(name, data).family)
        assert _same(delta_by_name(stem, path=tmp_path / "out"), family)
        assert r.summary["terms"][name]["stem"] == stem and r.summary["terms"][name]["file"] == str(path)
        same = ("train_cross_entropy", "heldout_cross_entropy", "sigma", "F", "wall", "num", "seed", "prior")
        assert all(tr[k] == training[k] for k in same)
        assert json.loads(path.read_text())["provenance"]["command"] == r.provenance["command"]
        # the setting fit's cache finds it: read, not refitted
        cached, ctr = fit_delta_for_setting(name, 2.0, 20, num=6, heldout=4, cache_dir=tmp_path / "out")
        assert _same(cached, family) and ctr["seconds"] == tr["seconds"]
    before = {p.name: p.stat().st_mtime_ns for p in (tmp_path / "out").iterdir()}
    again = fit_delta_setting(tmp_path / "out", family=["p3", "moravec_opt"], reuse=True, **kw)
    assert {p.name: p.stat().st_mtime_ns for p in (tmp_path / "out").iterdir()} == before
    assert again.summary["terms"]["p3"]["delta"] == r.summary["terms"]["p3"]["delta"]
    nothing = fit_delta_setting(None, family="p3", **kw)
    assert nothing.files == () and nothing.summary["terms"]["p3"]["delta"] == r.summary["terms"]["p3"]["delta"]


@pytest.mark.parametrize(
    ("kwargs", "option", "limit"),
    [
        ({"datasets": 1}, "datasets", "between 2 and 1000000"),
        ({"folds": 1}, "folds", "0 (no cross-validation) or between 2 and datasets (8)"),
        ({"folds": 9}, "folds", "between 0 and 8"),
        ({"families": ["p22"]}, "families", "must be among"),
        ({"families": []}, "families", "one or more"),
        ({"F": 1}, "F", "between 2 and 10000"),
        ({"wall": 20}, "wall", "between 1 and 19"),
        ({"sigma": 0.0}, "sigma", "(0, inf)"),
        ({"seed": -1}, "seed", "at least 0"),
    ],
)
def test_bad_deltas_options_are_named_with_their_limit_and_nothing_is_written(tmp_path, kwargs, option, limit):
    with pytest.raises(FitOptionError, match=option) as e:
        fit_deltas(tmp_path / "out", **{**SMALL, **kwargs}, progress=False)
    assert e.value.option == option and limit in str(e.value)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("kwargs", "option", "limit"),
    [
        ({"family": "elfes_opt"}, "family", "'pN' (N >= 1"),
        ({"sigma": -1.0}, "sigma", "(0, inf)"),
        ({"F": 1}, "F", "between 2 and 10000"),
        ({"wall": 0}, "wall", "between 1 and 19"),
        ({"num": 0}, "num", "between 1 and"),
        ({"num_readings": (3, 2)}, "num_readings", "between 3 and"),
        ({"num_readings": (1,)}, "num_readings", "two whole numbers"),
        ({"prior": "flat"}, "prior", "'uniform' or 'data_driven'"),
        ({"heldout": -1}, "heldout", "between 0 and"),
    ],
)
def test_bad_setting_options_are_named_with_their_limit_and_nothing_is_written(tmp_path, kwargs, option, limit):
    with pytest.raises(FitOptionError, match=option) as e:
        fit_delta_setting(tmp_path / "out", **{"sigma": 2.0, "F": 20, "num": 4, **kwargs})
    assert e.value.option == option and limit in str(e.value)
    assert not (tmp_path / "out").exists()


def test_an_out_that_is_a_file_is_refused(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(FitOptionError, match=r"out: .* is a file"):
        fit_deltas(tmp_path / "f", **SMALL, progress=False)
    with pytest.raises(FitOptionError, match=r"out: .* is a file"):
        fit_delta_setting(tmp_path / "f", sigma=2.0, F=20)


def test_the_commands_fit_and_refuse_a_bad_option_in_one_line(tmp_path, capsys):
    out = tmp_path / "cmd"
    argv = [
        "fit-prior",
        "delta-setting",
        "--family",
        "p2",
        "--sigma",
        "2",
        "--F",
        "20",
        "--num",
        "4",
        "--out",
        str(out),
    ]
    assert ogm_ppl(argv) == 0
    stem = "p2_sigma2_F20_wall16_n4_r1-10_seed0_uniform"
    assert f"delta_{stem}.json" in capsys.readouterr().out
    lower, _ = fit_delta_for_setting("p2", 2.0, 20, num=4)
    assert _same(delta_by_name(stem, path=out), lower)
    for bad, option in (
        (["--wall", "20"], "wall"),
        (["--num-readings", "0", "3"], "num_readings"),
        (["--family", "elfes_opt"], "family"),
    ):
        assert ogm_ppl([*argv, *bad]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"ogm-ppl: error: --{option.replace('_', '-')}") and len(err.strip().splitlines()) == 1
    deltas = ["fit-prior", "deltas", "--out", str(tmp_path / "d"), "--datasets", "8", "--folds", "2", "--quiet"]
    for bad, option in ((["--folds", "1"], "folds"), (["--families", "p99"], "families"), (["--F", "1"], "F")):
        assert ogm_ppl([*deltas, *bad]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"ogm-ppl: error: --{option.replace('_', '-')}") and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "d").exists() and files_under(tmp_path) == {f"cmd/delta_{stem}.json"}
