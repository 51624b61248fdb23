"""The ``ogm`` method's threads: the same map for any number of threads, from Python and the command line; a
clamped map refuses more than one thread."""

from __future__ import annotations

import numpy as np
import pytest

from ogm_ppl.methods import ParamError, get_method


def test_ogm_threads_give_the_same_map_and_clamp_refuses_them(tmp_path):
    from ogm_ppl.cli import load_map, main
    from ogm_ppl.inference.mcmc.parallel import max_threads
    from tests.test_cli import write_log

    log = write_log(tmp_path / "tiny.log")
    argv = ["map", str(log), "--resolution", "0.1", "--method", "p21"]
    assert main([*argv, "--threads", "1", "--out", str(tmp_path / "a")]) == 0
    assert main([*argv, "--threads", str(max_threads()), "--out", str(tmp_path / "b")]) == 0
    a, b = load_map(tmp_path / "a" / "map.npz"), load_map(tmp_path / "b" / "map.npz")
    np.testing.assert_array_equal(a["probabilities"], b["probabilities"])
    ogm = get_method("ogm")
    with pytest.raises(ParamError, match="one thread"):
        ogm.parse({"threads": 2, "clamp": [-2.0, 3.5]})
    with pytest.raises(ParamError, match="at most"):
        ogm.parse({"threads": max_threads() + 1})
