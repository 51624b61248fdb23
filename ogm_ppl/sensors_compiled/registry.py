r"""The compiled reading model of each reading kind, chosen by the bundle's type when a kernel compiles.

A kind registers its numba-compilable functions once (:func:`register`); the generic entry points below are
``numba.extending.overload``\ s that hand a kernel the registered function of the bundle type it is compiled
for (inlined: one specialisation of the kernel per kind, no branch on the kind). On a ray whose last kappa is
``F`` (a continuous sensor: the max range in cells; a discrete one: the ray's last cell), with first hit ``f``
in the sensor's coordinate (:func:`coord`) and ``none`` when no cell of the ray is occupied, the readings are
``J + 1`` outcomes: ``J`` hit outcomes (a discrete sensor's kappa ``0..F``; a continuous sensor's range bins)
and the max-range outcome ``J``:

* :func:`num_outcomes` ``(reading, F)`` — ``J``;
* :func:`bin_prob` ``(reading, j, J, f, none, F)`` — ``P(outcome j | f)``, the outcomes summing to one;
* :func:`fill_row` ``(reading, row, J, f, none, F, tails)`` — ``row[j] = P(outcome j | f)`` for ``j = 0..J``,
  where a kind may be faster than ``J + 1`` calls of :func:`bin_prob` (``tails``: scratch of ``J + 2``
  float64); default: those calls;
* :func:`log_reading` ``(reading, binned, y, jb, is_max, J, f, none, F)`` — ``log p(reading | f)``: for a
  continuous sensor and ``binned`` false, the log density of a hit at range ``y`` in kappa units
  (``y = r + 1/2 <= F + 1/2``), or the log max-range probability where ``is_max``; otherwise
  ``log P(outcome jb | f)``;
* :func:`coord` ``(reading, t_enter, off, kap)`` — the coordinate of a first hit at kappa ``kap`` of the ray
  whose entry distances are ``t_enter[off:]`` (a continuous sensor: ``t_enter[off + kap] + 1/2``; a discrete
  one: ``kap``);
* :func:`draw` ``(reading, J, f, none, F, u_a, u_b, e)`` — a reading drawn given the first hit from two
  uniforms ``u_a, u_b`` on ``[0, 1)`` and a standard normal ``e``: ``(y, is_max, jb)``, the range (continuous
  sensors; ``0.0`` otherwise), the max-range flag and the outcome, following :func:`log_reading`.

A kind also says whether its readings are continuous ranges (``continuous``: ``F`` is then the max range in
cells for every ray) or whole cells (``F`` the ray's last kappa); see :func:`is_continuous`.

Each entry point is also callable from Python (slowly, for tests and the sensor contract).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numba as nb
from numba.extending import overload

__all__ = [
    "ReadingKind",
    "bin_prob",
    "coord",
    "draw",
    "fill_row",
    "is_continuous",
    "kind_of",
    "log_reading",
    "num_outcomes",
    "register",
    "registered",
]


class ReadingKind(NamedTuple):
    """The compiled functions of one reading kind (numba functions or plain Python functions numba compiles
    inline) and whether its readings are continuous ranges."""

    num_outcomes: Callable
    bin_prob: Callable
    fill_row: Callable
    log_reading: Callable
    coord: Callable
    draw: Callable
    continuous: bool


_KINDS: dict[type, ReadingKind] = {}


def _rows_by_bin(kind_bin_prob: Callable) -> Callable:
    """The default ``fill_row`` of a kind: its ``bin_prob`` for each outcome."""
    one = kind_bin_prob if hasattr(kind_bin_prob, "py_func") else nb.njit(inline="always")(kind_bin_prob)

    def rows(reading, row, J, f, none, F, tails):
        for j in range(J + 1):
            row[j] = one(reading, j, J, f, none, F)

    return rows


def register(
    bundle: type,
    *,
    num_outcomes: Callable,
    bin_prob: Callable,
    log_reading: Callable,
    coord: Callable,
    draw: Callable,
    continuous: bool,
    fill_row: Callable | None = None,
) -> None:
    """Register the compiled reading model of the bundle class ``bundle`` (a ``typing.NamedTuple``; see the
    module docstring for each function's signature and meaning). ``fill_row`` defaults to :func:`bin_prob`
    for each outcome. Registering a class again replaces its functions."""
    if not (isinstance(bundle, type) and issubclass(bundle, tuple) and hasattr(bundle, "_fields")):
        raise TypeError(f"a reading bundle is a typing.NamedTuple class, got {bundle!r}")
    _KINDS[bundle] = ReadingKind(
        num_outcomes, bin_prob, fill_row or _rows_by_bin(bin_prob), log_reading, coord, draw, bool(continuous)
    )


def registered() -> tuple[type, ...]:
    """The registered reading bundle classes."""
    return tuple(_KINDS)


def kind_of(reading) -> ReadingKind:
    """The registered functions of a reading bundle (a Python object) or of its numba type."""
    cls = getattr(reading, "instance_class", None) or type(reading)
    try:
        return _KINDS[cls]
    except KeyError:
        raise TypeError(
            f"no compiled reading kind is registered for {cls.__name__} "
            "(ogm_ppl.sensors_compiled.register(bundle, num_outcomes=..., bin_prob=..., ...))"
        ) from None


def is_continuous(reading) -> bool:
    """Whether the bundle's readings are continuous ranges (``F``: the max range in cells)."""
    return kind_of(reading).continuous


def _registered(reading, name):
    kind = _KINDS.get(getattr(reading, "instance_class", None))
    if kind is None:
        return None
    fn = getattr(kind, name)
    return getattr(fn, "py_func", fn)  # a numba function: its Python source, compiled inline here


def num_outcomes(reading, F):
    return kind_of(reading).num_outcomes(reading, F)


def bin_prob(reading, j, J, f, none, F):
    return kind_of(reading).bin_prob(reading, j, J, f, none, F)


def fill_row(reading, row, J, f, none, F, tails):
    return kind_of(reading).fill_row(reading, row, J, f, none, F, tails)


def log_reading(reading, binned, y, jb, is_max, J, f, none, F):
    return kind_of(reading).log_reading(reading, binned, y, jb, is_max, J, f, none, F)


def coord(reading, t_enter, off, kap):
    return kind_of(reading).coord(reading, t_enter, off, kap)


def draw(reading, J, f, none, F, u_a, u_b, e):
    return kind_of(reading).draw(reading, J, f, none, F, u_a, u_b, e)


# numba checks that an implementation's signature is the overload's, so each typer spells it out
@overload(num_outcomes, inline="always")
def _num_outcomes(reading, F):
    return _registered(reading, "num_outcomes")


@overload(bin_prob, inline="always")
def _bin_prob(reading, j, J, f, none, F):
    return _registered(reading, "bin_prob")


@overload(fill_row, inline="always")
def _fill_row(reading, row, J, f, none, F, tails):
    return _registered(reading, "fill_row")


@overload(log_reading, inline="always")
def _log_reading(reading, binned, y, jb, is_max, J, f, none, F):
    return _registered(reading, "log_reading")


@overload(coord, inline="always")
def _coord(reading, t_enter, off, kap):
    return _registered(reading, "coord")


@overload(draw, inline="always")
def _draw(reading, J, f, none, F, u_a, u_b, e):
    return _registered(reading, "draw")
