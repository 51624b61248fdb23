import itertools
import math

import pytest
import torch

from ogm_ppl import GaussianRange
from ogm_ppl.models import (
    PN,
    BorensteinKoren,
    Elfes,
    MarshallBarfoot,
    Moravec,
    Stachniss,
    delta_by_name,
)
from ogm_ppl.models.delta import THESIS_P21

D = torch.arange(-30, 31, dtype=torch.float64)


def test_moravec_is_p2_and_haehnel_values():
    m = Moravec(0.9787, -0.7021)
    torch.testing.assert_close(m.delta(D), PN([-0.7021, 0.9787]).delta(D))
    h = Moravec.haehnel()
    assert h.l_occ.item() == pytest.approx(1.3863, abs=1e-4) and h.l_free.item() == -h.l_occ.item()


def test_pn_layout_matches_table_2_2():
    p = PN(THESIS_P21)
    assert p.lo == -11
    vals = p.delta(D)
    by_d = dict(zip(D.long().tolist(), vals.tolist()))
    assert by_d[-30] == by_d[-11] == -5.4028
    assert by_d[0] == 0.0995 and by_d[9] == 0.0034 and by_d[10] == 0.0 and by_d[30] == 0.0
    assert PN([0.3]).delta(torch.tensor([-5.0, -1.0, 0.0])).tolist() == [0.3, 0.3, 0.0]  # p1: free only


def test_simple_families():
    assert BorensteinKoren(0.7).delta(torch.tensor([-2.0, 0.0, 1.0])).tolist() == [0.0, 0.7, 0.0]
    mb = MarshallBarfoot(0.5, beta=2).delta(torch.tensor([-3.0, -1.0, 0.0, 1.0, 2.0]))
    assert mb.tolist() == [-0.5, -0.5, 0.5, 0.5, 0.0]
    with pytest.raises(ValueError, match="beta"):
        MarshallBarfoot(0.5, beta=0)
    st = Stachniss(1.0, -0.6, 4.0).delta(torch.tensor([-3.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0]))
    torch.testing.assert_close(st, torch.tensor([-0.6, -0.6, 0.2, 1.0, 0.5, 0.0, 0.0]))
    torch.testing.assert_close(Stachniss(1.0, -0.6, 1e-3).delta(D), Moravec(1.0, -0.6).delta(D))


def test_max_range_column_is_the_free_value():
    for d in (Moravec.haehnel(), PN(THESIS_P21), MarshallBarfoot(0.7, 2), BorensteinKoren(0.2)):
        t = d.table(10, 12)
        assert t.shape == (10, 13)
        assert torch.all(t[:, -1] == d.delta(torch.tensor([-1e9]))[0])


def brute_force_update(F, lam, sigma, z, is_max):
    """Log-odds update of every cell from one reading, by enumerating all 2^(F+1) maps."""
    s = GaussianRange(sigma)
    num = torch.full((F + 1,), -math.inf)
    den = torch.full((F + 1,), -math.inf)
    for m in itertools.product([0, 1], repeat=F + 1):
        f = m.index(1) if 1 in m else F + 1
        lp = sum(math.log(lam) if c else math.log1p(-lam) for c in m)
        lp = torch.tensor(lp) + s.log_prob(torch.tensor(float(z)), f, F, is_max=is_max)
        occ = torch.tensor(m, dtype=torch.bool)
        num = torch.where(occ, torch.logaddexp(num, lp), num)
        den = torch.where(occ, den, torch.logaddexp(den, lp))
    return num - den - (math.log(lam) - math.log1p(-lam))


@pytest.mark.parametrize("lam", [0.5, 0.3])
def test_elfes_is_the_exact_single_reading_update(lam):
    F, sigma = 7, 1.7
    table = Elfes(sigma, l_min=-1e9, prior=lam).table(F + 1, F + 1)
    for z in (0, 3, 7):
        torch.testing.assert_close(table[:, z], brute_force_update(F, lam, sigma, z, False))
    torch.testing.assert_close(table[:, -1], brute_force_update(F, lam, sigma, 0, True))


def test_elfes_floor_and_fixed_range():
    e = Elfes(2.9627, -12.9047, max_kappa=75)
    t = e.table(80, 78)
    assert t.shape == (80, 79) and t.min().item() == pytest.approx(-12.9047)
    assert torch.all(t[76:] == 0)  # beyond the sensor's range: no information
    torch.testing.assert_close(t[:76], Elfes(2.9627, -12.9047).table(76, 78))


@pytest.mark.parametrize(
    "family",
    [
        lambda: Stachniss(0.5, -0.8, 6.3),
        lambda: Elfes(2.0, -3.0),
        lambda: PN(torch.randn(7)),
        lambda: Moravec(0.3, -0.2),
        lambda: MarshallBarfoot(0.4, 2),
        lambda: BorensteinKoren(0.3),
    ],
)
def test_tables_have_correct_gradients(family):
    fam = family()
    names = [n for n, _ in fam.named_parameters()]
    inputs = tuple(p.detach().clone().requires_grad_(True) for p in fam.parameters())

    def table(*values):
        return torch.func.functional_call(fam, dict(zip(names, values)), (12, 14))

    assert torch.autograd.gradcheck(table, inputs)


def test_delta_by_name():
    for name in (
        "haehnel",
        "moravec_thesis",
        "p21_thesis",
        "elfes_thesis",
        "stachniss_thesis",
        "marshall_barfoot_thesis",
        "borenstein_koren_thesis",
    ):
        assert delta_by_name(name).table(5, 5).isfinite().all()
    with pytest.raises(ValueError, match="unknown Delta name"):
        delta_by_name("nope")


@pytest.mark.parametrize("kw", [dict(sigma=0.0), dict(prior=1.0), dict(prior=0.0)])
def test_elfes_bad_parameters(kw):
    with pytest.raises(ValueError):
        Elfes(**kw)


def test_load_delta_round_trip_and_malformed_files(tmp_path):
    import json
    from importlib import resources

    from ogm_ppl.models import DeltaFileError, delta_by_name, load_delta

    shipped = resources.files("ogm_ppl") / "fitted" / "delta_p21.json"
    good = json.loads(shipped.read_text())
    path = tmp_path / "p21.json"
    path.write_text(json.dumps(good))
    torch.testing.assert_close(load_delta(path).table(30, 30), delta_by_name("p21").table(30, 30))

    def variant(f):
        rec = json.loads(json.dumps(good))
        f(rec)
        return json.dumps(rec)

    cases = {
        "empty": ("", "empty file"),
        "truncated": (json.dumps(good)[:50], "not valid JSON"),
        "list": ("[1, 2]", "expected a JSON object"),
        "no_delta": (variant(lambda r: r.pop("delta")), "no 'delta' entry"),
        "format": (variant(lambda r: r.update(format=7)), "unknown artefact format 7"),
        "family": (variant(lambda r: r["delta"].update(family="os.system")), "unknown Delta family"),
        "nan": (variant(lambda r: r["delta"]["params"]["values"].__setitem__(3, float("nan"))), "non-finite"),
        "text": (variant(lambda r: r["delta"]["params"].update(values="abc")), "not numeric"),
        "shape": (
            variant(lambda r: r["delta"].update(family="Moravec", params={"l_occ": [1.0, 2.0]})),
            "expects parameters",
        ),
        "missing": (
            variant(lambda r: r["delta"].update(family="Moravec", params={"l_occ": 1.0})),
            "expects parameters",
        ),
    }
    for name, (text, message) in cases.items():
        p = tmp_path / f"{name}.json"
        p.write_text(text)
        with pytest.raises(DeltaFileError, match=rf"{name}\.json: .*{message}"):
            load_delta(p)
    with pytest.raises(DeltaFileError, match="no such file"):
        load_delta(tmp_path / "absent.json")


def _shipped(name):
    import json
    from importlib import resources

    return json.loads((resources.files("ogm_ppl") / "fitted" / f"delta_{name}.json").read_text())


def _edit(rec, path, value):
    d = rec
    for k in path[:-1]:
        d = d[k]
    d[path[-1]] = value
    return rec


@pytest.mark.parametrize(
    "artefact, path, value, message",
    [
        ("neural_opt", ("delta", "fixed", "F"), -75, r"NeuralDelta\.F .*>= 1, got -75"),
        ("neural_opt", ("delta", "fixed", "hidden"), 10**9, r"NeuralDelta\.hidden must lie in 1\.\.4096"),
        ("elfes_opt", ("delta", "fixed", "max_kappa"), -3, r"Elfes\.max_kappa must be None or an integer >= 0"),
        ("p21", ("training", "sigma"), float("nan"), r"field 'training\.sigma' is not a finite number"),
        ("p21", ("training", "num_readings"), [1, float("inf")], r"'training\.num_readings\[1\]'"),
        ("p21", ("training", "F"), -75, r"'training\.F' must be a number > 0"),
        ("p21", ("training", "sigma"), "3", r"'training\.sigma' must be a number > 0"),
    ],
)
def test_artefact_settings_refused_with_file_and_field(tmp_path, artefact, path, value, message):
    """Settings that would change the map (a negative ``F``), crash deep in torch (a negative ``max_kappa``),
    exhaust memory (a huge hidden layer) or switch the fitted-setting check off (NaN in ``training``) are
    refused on loading, naming the file and the field."""
    import json

    from ogm_ppl.models import DeltaFileError, load_delta

    rec = _edit(_shipped(artefact), path, value)
    p = tmp_path / f"{artefact}.json"
    p.write_text(json.dumps(rec))
    with pytest.raises(DeltaFileError, match=rf"{artefact}\.json: .*{message}"):
        load_delta(p)


def test_every_shipped_artefact_still_loads():
    from ogm_ppl.models.delta import fitted_names, load_fitted

    for name in fitted_names():
        assert load_fitted(name)[0].table(5, 5).isfinite().all(), name
