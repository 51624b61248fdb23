"""Counting prior tables: exact counts against brute-force loops, symmetries, border tables, I/O."""

import itertools
import json
import zipfile

import numpy as np
import pytest

from ogm_ppl.priors.learn import count_tables, dihedral_permutations, permute_codes, window_codes
from ogm_ppl.priors.tables import (
    BORDER8_INDEX,
    BORDER16_INDEX,
    INNER9_INDEX,
    PAIR_OFFSETS,
    PriorTables,
    available_tables,
    decode_code,
    encode_window,
    load_tables,
    save_tables,
    split_border_inner,
    tables_by_name,
)

ARRAYS = [
    "cell_counts",
    "counts3x3",
    "codes5x5",
    "counts5x5",
    "pair_counts",
    "line_counts",
    "run_counts",
]


def _random_map(shape, seed, p_unknown=0.1):
    rng = np.random.default_rng(seed)
    return rng.random(shape) < 0.4, rng.random(shape) >= p_unknown


def _brute(occ, known, L=4, R=5):
    """Every statistic by plain Python loops over cells and windows."""
    H, W = occ.shape
    cells = np.zeros(2, np.int64)
    c3 = np.zeros(512, np.int64)
    c5 = {}
    pairs = np.zeros((4, 2, 2), np.int64)
    lines = np.zeros(2**L, np.int64)
    runs = np.zeros((2, R + 1), np.int64)
    for r in range(H):
        for c in range(W):
            if known[r, c]:
                cells[int(occ[r, c])] += 1
            for size in (3, 5):
                if r + size <= H and c + size <= W and known[r : r + size, c : c + size].all():
                    code = sum(int(occ[r + i // size, c + i % size]) << i for i in range(size * size))
                    if size == 3:
                        c3[code] += 1
                    else:
                        c5[code] = c5.get(code, 0) + 1
            for k, (dr, dc) in enumerate(PAIR_OFFSETS):
                r2, c2 = r + dr, c + dc
                if 0 <= r2 < H and 0 <= c2 < W and known[r, c] and known[r2, c2]:
                    pairs[k, int(occ[r, c]), int(occ[r2, c2])] += 1
            if c + L <= W and known[r, c : c + L].all():
                lines[sum(int(occ[r, c + i]) << i for i in range(L))] += 1
            if r + L <= H and known[r : r + L, c].all():
                lines[sum(int(occ[r + i, c]) << i for i in range(L))] += 1
    state = np.where(known, occ.astype(int), 2)
    for seq in list(state) + list(state.T):
        groups = [(v, len(list(g))) for v, g in itertools.groupby(seq)]
        for i in range(1, len(groups) - 1):
            v, n = groups[i]
            if v < 2 and groups[i - 1][0] == 1 - v and groups[i + 1][0] == 1 - v:
                runs[v, min(n, R)] += 1
    codes = np.array(sorted(c5), dtype=np.int64)
    return {
        "cell_counts": cells,
        "counts3x3": c3,
        "codes5x5": codes,
        "counts5x5": np.array([c5[k] for k in codes], dtype=np.int64),
        "pair_counts": pairs,
        "line_counts": lines,
        "run_counts": runs,
    }


def _eq(t: PriorTables, ref: dict):
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(t, name), ref[name], err_msg=name)


def test_bit_order():
    # bit i = cell i of the row-major window
    w = np.zeros((3, 3), dtype=int)
    w[0, 2] = 1  # cell 2
    w[2, 0] = 1  # cell 6
    assert encode_window(w) == (1 << 2) | (1 << 6)
    np.testing.assert_array_equal(decode_code(68, (3, 3)), w.astype(bool))
    assert window_codes(w.astype(bool)).tolist() == [68]
    w5 = np.zeros((5, 5), dtype=int)
    w5[4, 4] = 1
    assert encode_window(w5) == 1 << 24
    assert BORDER16_INDEX.tolist() == [0, 1, 2, 3, 4, 5, 9, 10, 14, 15, 19, 20, 21, 22, 23, 24]
    assert INNER9_INDEX.tolist() == [6, 7, 8, 11, 12, 13, 16, 17, 18]
    assert BORDER8_INDEX.tolist() == [0, 1, 2, 3, 5, 6, 7, 8]


@pytest.mark.parametrize("seed", [0, 1])
def test_counts_equal_brute_force(seed):
    occ, known = _random_map((7, 6), seed)
    t = count_tables([(occ, known)], symmetries=False, line_length=4, max_run=5, progress=False)
    _eq(t, _brute(occ, known))


def test_counts_equal_brute_force_all_known_and_sum_over_maps():
    a = _random_map((6, 6), 3, p_unknown=0)[0]
    b, kb = _random_map((8, 5), 4)
    t = count_tables([a, (b, kb)], symmetries=False, line_length=4, max_run=5, progress=False)
    ra, rb = _brute(a, np.ones_like(a)), _brute(b, kb)
    for name in ("cell_counts", "counts3x3", "pair_counts", "line_counts", "run_counts"):
        np.testing.assert_array_equal(getattr(t, name), ra[name] + rb[name], err_msg=name)
    assert t.counts5x5.sum() == ra["counts5x5"].sum() + rb["counts5x5"].sum()


def test_hand_made_map():
    m = np.zeros((6, 6), dtype=bool)
    m[:, 0] = True  # a wall down the left column
    t = count_tables([m], symmetries=False, progress=False)
    assert t.cell_counts.tolist() == [30, 6]
    left = encode_window([[1, 0, 0]] * 3)
    assert t.counts3x3[left] == 4 and t.counts3x3[0] == 12 and t.counts3x3.sum() == 16
    assert t.pair_stats(4) == (2 * 30 - 6, 6)  # 60 pairs, 6 wall/free edges
    assert t.psi(4) == pytest.approx(6 / 54)


def test_symmetries_equal_counting_transformed_maps():
    occ, known = _random_map((9, 7), 5)
    sym = count_tables([(occ, known)], symmetries=True, line_length=4, max_run=5, progress=False)
    variants = []
    for flip in (False, True):
        o, k = (np.fliplr(occ), np.fliplr(known)) if flip else (occ, known)
        variants += [(np.rot90(o, r).copy(), np.rot90(k, r).copy()) for r in range(4)]
    ref = count_tables(variants, symmetries=False, line_length=4, max_run=5, progress=False)
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(sym, name), getattr(ref, name), err_msg=name)
    # the 3x3 table is invariant under every permutation of the group
    for p in dihedral_permutations(3):
        import torch

        perm = permute_codes(torch.arange(512), p).numpy()
        np.testing.assert_array_equal(sym.counts3x3[perm], sym.counts3x3)


def test_border_tables_are_marginals_of_5x5():
    occ, known = _random_map((12, 11), 6, p_unknown=0.05)
    t = count_tables([(occ, known)], progress=False)
    bt = t.border_table()
    b, i, n = bt.triples()
    # re-assembling the 5x5 code from border and inner gives back the 5x5 table
    code = np.zeros_like(b)
    for j, pos in enumerate(BORDER16_INDEX):
        code |= ((b >> j) & 1) << pos
    for j, pos in enumerate(INNER9_INDEX):
        code |= ((i >> j) & 1) << pos
    order = np.argsort(code)
    np.testing.assert_array_equal(code[order], t.codes5x5)
    np.testing.assert_array_equal(n[order], t.counts5x5)
    # summing over the inner reproduces the border marginal, over the border the inner marginal
    border, inner = split_border_inner(t.codes5x5)
    for x in np.unique(border)[:20]:
        inn, cnt = bt.lookup(int(x))
        assert cnt.sum() == t.counts5x5[border == x].sum()
        assert (np.diff(inn) > 0).all()
    inner_marg = np.bincount(inner, weights=t.counts5x5, minlength=512)
    np.testing.assert_array_equal(np.bincount(bt.inner, weights=bt.counts, minlength=512), inner_marg)
    assert bt.lookup(12345678)[0].size == 0 or 12345678 in bt.borders
    # 1-given-8 re-indexes the 3x3 table
    c18 = t.counts1given8()
    assert c18.shape == (256, 2) and c18.sum() == t.counts3x3.sum()
    assert c18[0, 0] == t.counts3x3[0] and c18[255, 1] == t.counts3x3[511]
    assert c18[0, 1] == t.counts3x3[1 << 4]
    b1, i1, n1 = t.border1_triples()
    assert n1.sum() == c18.sum() and (c18[b1, i1] == n1).all()


def test_line_border_triples():
    m = np.zeros((1, 6), dtype=bool)
    m[0, 3:] = True  # 0 0 0 1 1 1
    t = count_tables([m], symmetries=False, line_length=4, progress=False)
    b, i, n = t.line_border_triples(2)  # windows 0001, 0011, 0111 (cells 0..3 of each 4-window)
    got = sorted(zip(b.tolist(), i.tolist(), n.tolist()))
    # window 0,0,0,1 -> border (0, 1) = 2, inner 0; 0,0,1,1 -> border 2, inner 0b10 = 2; 0,1,1,1 -> border 2, inner 3
    assert got == [(2, 0, 1), (2, 2, 1), (2, 3, 1)]


def test_line_table_and_patch_probs():
    occ, _ = _random_map((10, 10), 7, p_unknown=0)
    t = count_tables([occ], symmetries=False, line_length=4, progress=False)
    l2 = t.line_table(2)
    assert l2.sum() == t.line_counts.sum()
    with pytest.raises(ValueError):
        t.line_table(5)
    _, probs = t.patch_probs(3, mass=0.999)
    assert probs.sum() >= 0.999 - 1e-9 and (np.diff(probs) <= 0).all()


def test_deterministic_and_truncation():
    from ogm_ppl.datasets.mapgen import iter_corpus

    a = count_tables(iter_corpus(2, (80, 80), seed=1), progress=False)
    b = count_tables(iter_corpus(2, (80, 80), seed=1), progress=False)
    _eq(a, {n: getattr(b, n) for n in ARRAYS})
    c = count_tables(iter_corpus(2, (80, 80), seed=1), min_count_5x5=3, progress=False)
    assert c.truncated_mass == a.counts5x5[a.counts5x5 < 3].sum()
    assert c.counts5x5.sum() + c.truncated_mass == a.counts5x5.sum()


def test_bad_inputs():
    with pytest.raises(ValueError, match="2D"):
        count_tables([np.zeros(5, bool)], progress=False)
    with pytest.raises(ValueError, match="known"):
        count_tables([(np.zeros((5, 5), bool), np.ones((4, 5), bool))], progress=False)
    image = np.full((6, 6), 255, np.uint8)
    image[2, :] = 0  # an image read as it is: 255 would count as occupied
    with pytest.raises(ValueError, match=r"map 1: the map must be bool .* such as 255 \(dtype uint8\)"):
        count_tables([np.zeros((6, 6), bool), image], progress=False)
    with pytest.raises(ValueError, match=r"map 0: occupancy must be bool .* such as 0.5"):
        count_tables([(np.full((6, 6), 0.5), None)], progress=False)
    with pytest.raises(ValueError, match="map 0: known must be a bool array, got dtype <U1"):
        count_tables([(np.zeros((2, 2), bool), np.full((2, 2), "y"))], progress=False)
    with pytest.raises(ValueError, match="no maps to count"):
        count_tables([], progress=False)
    zero_one = (image == 0).astype(np.int64)  # numbers that are all 0 or 1 count as the bool map
    assert np.array_equal(
        count_tables([zero_one], progress=False).counts3x3, count_tables([zero_one == 1], progress=False).counts3x3
    )


def _small_tables():
    occ, known = _random_map((10, 9), 8)
    return count_tables([(occ, known)], progress=False, provenance={"corpus": "test"})


def test_save_load_round_trip(tmp_path):
    t = _small_tables()
    p = save_tables(t, tmp_path / "sub" / "t.npz")
    assert not list(p.parent.glob("*.tmp"))
    u = load_tables(p)
    _eq(u, {n: getattr(t, n) for n in ARRAYS})
    assert u.provenance["corpus"] == "test" and u.symmetries == 8
    assert u.summary() == t.summary()
    # a write that cannot happen names the path given, not a temporary file or only its folder
    with pytest.raises(IsADirectoryError, match="is a folder; give a file name") as e:
        save_tables(t, tmp_path / "sub")
    assert e.value.filename == str(tmp_path / "sub")
    with pytest.raises(OSError, match="cannot write it") as e:
        save_tables(t, p / "x.npz")  # under a file
    assert e.value.filename == str(p / "x.npz")
    assert sorted(q.name for q in p.parent.iterdir()) == ["t.npz"]


def test_malformed_files(tmp_path):
    t = _small_tables()
    good = save_tables(t, tmp_path / "good.npz")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip")
    with pytest.raises(ValueError, match=r"junk\.npz"):
        load_tables(junk)
    with np.load(good) as z:
        arrays = {k: z[k] for k in z.files}

    def write(name, **change):
        d = {**arrays, **change}
        for k in [k for k, v in change.items() if v is None]:
            d.pop(k)
        path = tmp_path / name
        np.savez(path, **d)
        return path

    with pytest.raises(ValueError, match=r"missing.*counts3x3"):
        load_tables(write("a.npz", counts3x3=None))
    with pytest.raises(ValueError, match="shape"):
        load_tables(write("b.npz", counts3x3=np.zeros(10, np.int64)))
    with pytest.raises(ValueError, match="strictly increasing"):
        load_tables(write("c.npz", codes5x5=arrays["codes5x5"][::-1].copy()))
    meta = json.loads(str(arrays["meta"]))
    with pytest.raises(ValueError, match="format_version"):
        load_tables(write("d.npz", meta=np.array(json.dumps({**meta, "format_version": 99}))))
    with pytest.raises(ValueError, match="meta"):
        load_tables(write("e.npz", meta=None))
    # an object array needs pickle: refused
    with pytest.raises(ValueError, match=r"f\.npz"):
        load_tables(write("f.npz", counts3x3=np.array([{"x": 1}], dtype=object)))
    assert zipfile.is_zipfile(good)
    # well formed but edited after saving: the recorded SHA-256 no longer matches
    edited = arrays["counts3x3"].copy()
    edited[0] += 1000
    with pytest.raises(ValueError, match=r"g\.npz: the arrays differ from those saved"):
        load_tables(write("g.npz", counts3x3=edited))
    unchecked = {k: v for k, v in meta.items() if k != "sha256"}  # a file written without one is read
    assert load_tables(write("h.npz", meta=np.array(json.dumps(unchecked)))).counts3x3.sum() == t.counts3x3.sum()
    no_occupied = np.array([arrays["cell_counts"][0], 0])
    with pytest.raises(ValueError, match=r"i\.npz: cell_counts .* must count free and occupied"):
        load_tables(write("i.npz", cell_counts=no_occupied, meta=np.array(json.dumps(unchecked))))


def test_shipped_tables():
    names = available_tables()
    for name in ("generated", "houseexpo", "ipa", "dungeon"):
        assert name in names
    for name in names:
        t = tables_by_name(name)
        assert 0.05 < t.lam < 0.9
        assert t.symmetries == 8
    g = tables_by_name("generated")
    assert g.provenance["n_maps"] == 100
    s = g.summary()
    assert 0.15 < s["lambda"] < 0.35 and s["free3x3"] > 0.5
    with pytest.raises(KeyError, match="available"):
        tables_by_name("nope")


def test_mrf_pseudolikelihood_fit_recovers_the_parameters_of_mrf_samples():
    import torch

    from ogm_ppl.priors import MRFPrior
    from ogm_ppl.priors.learn import count_tables

    torch.manual_seed(0)
    lam, psi = 0.4, 0.6
    maps = MRFPrior((80, 80), order=1, psi=psi, cell_prior=lam).sample((6,)).numpy().astype(bool)
    # interior windows only (the MRF's border cells have fewer neighbours); no symmetries: the MRF is
    # already symmetric
    t = count_tables([m.reshape(80, 80) for m in maps], symmetries=False, progress=False)
    lam_hat, psi_hat = t.mrf_fit(4)
    # ~6 x 76^2 = 35k centre cells: the estimates are good to a few per cent
    assert abs(lam_hat - lam) < 0.03 and abs(psi_hat - psi) < 0.05
