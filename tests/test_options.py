"""The one option system (:mod:`ogm_ppl.options`): declared options and the scalar checks of keyword
arguments, each error naming the option."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from ogm_ppl.options import INT_LIMIT, Float, Int, ParamError, check_float, check_int, param, parse_params


@dataclass(frozen=True)
class _P:
    sweeps: int = param(100, Int(lo=1), "sweeps")
    rate: float = param(0.5, Float(lo=0.0, hi=1.0, lo_open=True), "a rate")


def test_parse_params_values_text_and_errors() -> None:
    assert parse_params(_P, {"sweeps": "20"}, text=True) == _P(sweeps=20)
    with pytest.raises(ParamError, match=r"^sweeps: must be >= 1, got 0$"):
        parse_params(_P, {"sweeps": 0})
    with pytest.raises(ParamError, match="unknown key"):
        parse_params(_P, {"sweep": 3})
    with pytest.raises(ParamError, match=r"rate: must be > 0\.0"):
        parse_params(_P, {"rate": 0.0})
    with pytest.raises(ParamError, match="int64"):
        parse_params(_P, {"sweeps": INT_LIMIT + 1})


class _MyError(ValueError):
    def __init__(self, option: str, message: str) -> None:
        super().__init__(f"{option}: {message}")
        self.option = option


def test_check_int_takes_numpy_integers_and_names_the_option() -> None:
    assert check_int(np.int64(7), "n", 1) == 7 and type(check_int(np.int32(7), "n", 1)) is int
    assert check_int(5, "n", 1, 5) == 5
    for bad, text in [(True, "whole number"), (2.0, "whole number"), (0, "at least 1"), (2**64, "int64")]:
        with pytest.raises(ParamError, match=f"^n: must .*{text}"):
            check_int(bad, "n", 1)
    with pytest.raises(_MyError, match=r"^n: must be between 1 and 5, got 6$") as e:
        check_int(6, "n", 1, 5, error=_MyError)
    assert e.value.option == "n"


def test_check_float_ends_open_and_closed() -> None:
    assert check_float(1, "x", 0.0, 1.0) == 1.0
    assert check_float(np.float32(0.25), "x", 0.0) == 0.25
    assert check_float(0.0, "x", 0.0, lo_open=False) == 0.0
    for bad, kw in [(0.0, {}), (1.0, {"hi": 1.0, "hi_open": True}), (float("nan"), {}), (float("inf"), {}), ("1", {})]:
        with pytest.raises(_MyError, match=r"^x: must"):
            check_float(bad, "x", 0.0, error=_MyError, **kw)
    with pytest.raises(ParamError, match=r"^x: must lie in \(0, 1\], got 2.0$"):
        check_float(2.0, "x", 0.0, 1.0)


def test_a_positive_number_names_the_open_interval() -> None:
    with pytest.raises(ParamError, match=r"^sigma: must lie in \(0, inf\), got 0.0$"):
        check_float(0, "sigma", 0.0)
