"""Generated ground-truth maps (thesis Fig. 5.9 style)."""

import time

import pytest

from ogm_ppl.datasets.mapgen import KINDS, generate_corpus, generate_map, iter_corpus


@pytest.mark.parametrize("kind", KINDS)
def test_basic_properties(kind):
    for seed in range(3):
        m = generate_map(kind, seed=seed)
        assert m.shape == (500, 500) and m.dtype == bool
        assert m[:20].all() and m[-20:].all() and m[:, :20].all() and m[:, -20:].all()
        assert 0.2 < 1 - m.mean() < 0.95  # free fraction in a sane range
        assert not m[20:-20, 20:-20].all()


def test_deterministic_and_seed_dependent():
    a = generate_map("office", seed=5)
    assert (a == generate_map("office", seed=5)).all()
    assert not (a == generate_map("office", seed=6)).all()
    c1 = generate_corpus(6, (120, 100), seed=2)
    c2 = list(iter_corpus(8, (120, 100), seed=2))
    assert all((x == y).all() for x, y in zip(c1, c2))  # map i does not depend on n
    assert [x.shape for x in c1] == [(120, 100)] * 6


def test_corpus_kinds_and_border():
    ms = generate_corpus(2, (100, 100), seed=0, kinds=("hall",), border=3)
    assert all(m[:3].all() and not m[3:-3, 3:-3].all() for m in ms)


def test_fast():
    t = time.perf_counter()
    for i, k in enumerate(KINDS * 2):
        generate_map(k, seed=i)
    assert (time.perf_counter() - t) / 8 < 0.2


def test_bad_arguments():
    with pytest.raises(ValueError, match="kind"):
        generate_map("castle")
    with pytest.raises(ValueError, match="shape"):
        generate_map("office", shape=(10, 10))
    with pytest.raises(ValueError, match="border"):
        generate_map("office", border=0)
