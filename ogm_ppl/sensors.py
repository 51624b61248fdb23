"""Forward sensor models p(z_n | f_n) of a narrow-beam range sensor (Section 2.6).

Units are cells along the ray (kappa units, Section 2.4): ``z`` is the reading, ``f`` the kappa of the
first occupied cell, ``F`` the last kappa of the ray (the maximum range in kappa units). Two events are
explicit:

* **no occupied cell within the ray** (``f > F + 1/2``; pass ``f = F + 1``): the beam has nothing to
  reflect off inside the sensor's range. (In the continuous coordinate below a cell of the ray entered at
  ``t_f < L`` has ``f = t_f + 1/2 < F + 1/2``, so it is a hit even when ``f > F``; for integer ``f`` the
  test is ``f > F``);
* **a max-range reading** (``is_max``): the sensor reported no return.

Both models are normalised over the outcome space ``{hit at z} U {max-range}``; ``ogm_ppl.testing``
checks it for any model.

**Where a reading sits (the one convention, see :mod:`ogm_ppl.raycast`).** A beam returns where it enters
the first occupied cell, at its near face. A sensor with ``continuous_range = True`` (``GaussianRange``) is
evaluated by :class:`~ogm_ppl.models.OccupancyModel` on the measured range itself, in the continuous
kappa coordinate ``kappa_c = t + 1/2`` (``t``: distance in cells from the sensor): ``z = r + 1/2`` for a
reading at range ``r``, ``f = t_f + 1/2`` where ``t_f`` is the entry distance of the first occupied cell,
and ``F = L`` for a maximum range of ``L`` cells (so max range is censored at ``F + 1/2 = L + 1/2``,
i.e. at ``r = L``); the sensor's own cell sits at ``kappa_c = 0``. In 1D, from a robot in the middle of cell 0,
cell ``kappa`` is entered at
``kappa - 1/2``: ``kappa_c`` of a wall at ``f`` is exactly ``f``, and the thesis's integer readings are
kappa values. In 2D this keeps ``p(z | f)`` centred where the beam meets the wall at every beam angle
(diagonal rays cross more cells per metre; integer kappa would shift the centre by up to half a cell).
A discrete sensor (``continuous_range = False``, ``PatternMatch``) compares the reading's kappa
``rays.z`` with the first hit's kappa ``f``.

**The compiled face.** The exploration kernels (:mod:`ogm_ppl.exploration.information`) read a sensor through
:meth:`SensorModel.compiled`: a ``typing.NamedTuple`` bundle of its parameters whose kind registers the reading
model as numba functions (:mod:`ogm_ppl.sensors_compiled`: :class:`GaussianRange` gives a
:class:`~ogm_ppl.sensors_compiled.GaussianReading`, :class:`PatternMatch` a
:class:`~ogm_ppl.sensors_compiled.PatternReading`). A sensor of your own returns a bundle of a kind it registers
with :func:`ogm_ppl.sensors_compiled.register`, and :class:`~ogm_ppl.testing.SensorContract` checks the compiled
model against ``log_prob``; without one (``compiled()`` returns ``None``) it maps but does not explore.

**Sensors by name.** The map methods, the command line (``--sensor``) and experiment specs build their
sensor with :func:`sensor_by_name` from a kind, the range noise ``sigma_cells`` and the share of random
readings ``p_rand``. The library ships ``gaussian`` (:class:`GaussianRange`); a sensor of your own registers a
factory ``factory(sigma_cells, p_rand, **options) -> SensorModel`` with :func:`register_sensor`. Name its module in
``$OGM_PPL_METHODS`` (comma-separated modules, imported by :mod:`ogm_ppl.methods` in every process) for the
command line and dask workers to find it:

>>> register_sensor("gaussian2", lambda sigma_cells, p_rand: GaussianRange(2 * sigma_cells, p_rand))
>>> sensor_by_name("gaussian2", 1.5)
GaussianRange(sigma=3.0, p_rand=0.0)
>>> unregister_sensor("gaussian2")

A factory's keyword parameters beyond the two are the kind's options, given in the name as
``KIND:KEY=VALUE,KEY=VALUE`` (numbers), so a spec or the command line can sweep them:

>>> register_sensor("wide", lambda sigma_cells, p_rand, k=2: GaussianRange(k * sigma_cells, p_rand))
>>> sensor_by_name("wide:k=3", 1.5, 0.1)
GaussianRange(sigma=4.5, p_rand=0.1)
>>> unregister_sensor("wide")
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import torch

from ogm_ppl._registry import Registry

if TYPE_CHECKING:
    from ogm_ppl.sensors_compiled import GaussianReading, PatternReading

__all__ = [
    "SENSOR_KINDS",
    "GaussianRange",
    "PatternMatch",
    "SensorFactoryError",
    "SensorModel",
    "register_sensor",
    "sensor_by_name",
    "sensor_kinds",
    "split_sensor_name",
    "unregister_sensor",
]

_LOG_SQRT_2PI = 0.5 * math.log(2 * math.pi)


def _as_tensor(x, dtype=None) -> torch.Tensor:
    if isinstance(x, torch.Tensor):
        return x if dtype is None else x.to(dtype)
    return torch.as_tensor(x, dtype=dtype if dtype is not None else torch.get_default_dtype())


def _common(z, f, F):
    """Readings, first hits and ray ends as tensors of the readings' dtype, and the "none" mask."""
    z = _as_tensor(z)
    f = _as_tensor(f, z.dtype)
    F = _as_tensor(F, z.dtype)
    return z, f, F, f > F + 0.5  # module docstring: a ray's last cell may sit at F < f < F + 1/2


def _check_prob(name: str, value: float, open_right: bool = True) -> float:
    value = float(value)
    ok = 0.0 < value < 1.0 if open_right else 0.0 < value <= 1.0
    if not ok:
        raise ValueError(f"{name} must lie in (0, 1{')' if open_right else ']'}, got {value}")
    return value


class SensorModel:
    """Base class: ``log_prob(z, f, F, is_max)`` -> ``log p(z | f)`` elementwise (broadcasting).

    Args of ``log_prob``:
        z: readings in kappa units (ignored where ``is_max``).
        f: kappa of the first occupied cell; any value ``> F + 1/2`` means none within the ray.
        F: last kappa of the ray.
        is_max: True where the reading is a max-range reading (default: none are).
    """

    #: evaluated on continuous ranges (True) or on integer kappa (False); see the module docstring
    continuous_range: bool = False

    def log_prob(self, z, f, F, is_max=None) -> torch.Tensor:  # pragma: no cover - interface
        raise NotImplementedError

    def sample(self, f, F, generator: torch.Generator | None = None):
        """Draw readings given first-occupied cells: returns ``(z, is_max)``."""
        raise NotImplementedError  # pragma: no cover - interface

    def compiled(self, bin_width: float | None = None) -> NamedTuple | None:
        """The sensor's compiled face: a reading bundle of a kind registered with
        :func:`ogm_ppl.sensors_compiled.register` (its reading model as numba functions), which the
        exploration kernels read, or ``None`` (the default): no compiled reading model, and
        :func:`~ogm_ppl.exploration.information.beam_information` and its kin refuse the sensor.

        Args:
            bin_width: a continuous sensor's range bins, in cells (``None``: one cell), for the outcomes the
                information gain sums over; a discrete sensor's outcomes are its cells and it may ignore it.

        Raises:
            ValueError: parameters the compiled model cannot take (say, a different noise per beam).
        """
        return None


class GaussianRange(SensorModel):
    r"""Gaussian noise about the first occupied cell, censored at the maximum range.

    .. math::
        p(z_n \mid f) = (1 - p_{rand})\,\mathcal{N}(z_n; f, \sigma^2) + \frac{p_{rand}}{F + 1}
        \quad (z_n \le F + \tfrac12), \qquad
        P(\text{max} \mid f) = (1 - p_{rand})\,\bigl(1 - \Phi(\tfrac{F + 1/2 - f}{\sigma})\bigr)

    for a first hit within the ray (``f <= F + 1/2``): a noisy range beyond ``F + 1/2`` is reported as max
    range. With no
    occupied cell in the ray the reading is max range with probability ``1 - p_rand`` and a uniform
    random hit on ``[-1/2, F + 1/2]`` otherwise (the ``p_rand`` term lives on that interval only). ``p_rand = 0``
    (default) is the thesis's model
    ``N(f, sigma^2)`` (Section 2.6); a hit then has zero likelihood under a map with nothing to reflect it.

    >>> s = GaussianRange(3.0)
    >>> round(float(s.log_prob(8.0, 8, 75)), 4)
    -2.0176
    """

    continuous_range = True

    def __init__(self, sigma: float, p_rand: float = 0.0) -> None:
        sigma_t = _as_tensor(sigma)
        if not torch.isfinite(sigma_t).all() or (sigma_t <= 0).any():
            raise ValueError(f"GaussianRange.sigma must be positive and finite, got {sigma}")
        if not 0.0 <= float(p_rand) < 1.0:
            raise ValueError(f"GaussianRange.p_rand must lie in [0, 1), got {p_rand}")
        self.sigma = sigma
        self.p_rand = float(p_rand)

    def __repr__(self) -> str:
        return f"GaussianRange(sigma={float(self.sigma)}, p_rand={self.p_rand})"

    def log_prob(self, z, f, F, is_max=None) -> torch.Tensor:
        z, f, F, none = _common(z, f, F)
        sigma = _as_tensor(self.sigma, z.dtype)
        f_safe = torch.where(none, F, f)
        log_n = -0.5 * ((z - f_safe) / sigma) ** 2 - torch.log(sigma) - _LOG_SQRT_2PI
        log_tail = torch.special.log_ndtr((f_safe - F - 0.5) / sigma)  # log(1 - Phi((F+1/2-f)/sigma))
        beyond = z > F + 0.5  # such a noisy range is reported as max range, never as a hit
        if self.p_rand > 0:
            in_support = (z >= -0.5) & ~beyond
            lr = torch.where(in_support, math.log(self.p_rand) - torch.log(F + 1.0), -math.inf)
            lk = math.log1p(-self.p_rand)
            hit = torch.where(none, lr, torch.logaddexp(lk + log_n, lr))
            mx = torch.where(none, torch.full_like(log_tail, lk), lk + log_tail)
        else:
            hit = torch.where(none, torch.full_like(log_n, -math.inf), log_n)
            mx = torch.where(none, torch.zeros_like(log_tail), log_tail)
        hit = torch.where(beyond, -math.inf, hit)
        if is_max is None:
            return hit
        return torch.where(torch.as_tensor(is_max, dtype=torch.bool), mx, hit)

    def sample(self, f, F, generator: torch.Generator | None = None):
        f = _as_tensor(f)
        F = _as_tensor(F, f.dtype).expand_as(f)
        none = f > F + 0.5
        y = f + float(self.sigma) * torch.randn(f.shape, generator=generator, dtype=f.dtype)
        if self.p_rand > 0:
            rand = torch.rand(f.shape, generator=generator, dtype=f.dtype) < self.p_rand
            u = -0.5 + (F + 1.0) * torch.rand(f.shape, generator=generator, dtype=f.dtype)
            y = torch.where(rand, u, y)
            none = none & ~rand
        is_max = none | (y > F + 0.5)
        return torch.where(is_max, F + 1.0, y), is_max

    def compiled(self, bin_width: float | None = None) -> GaussianReading:
        """:class:`~ogm_ppl.sensors_compiled.GaussianReading` ``(sigma, p_rand, width)``: ranges in bins of
        ``bin_width`` cells (default 1). ``ValueError`` if ``sigma`` is not one number for every beam or
        ``bin_width`` is not a positive finite number."""
        from ogm_ppl.sensors_compiled import GaussianReading

        sigma = torch.as_tensor(self.sigma)
        if sigma.numel() != 1:
            raise ValueError(
                f"the compiled reading model needs one GaussianRange.sigma for every beam (got a tensor of "
                f"{sigma.numel()})"
            )
        w = 1.0 if bin_width is None else float(bin_width)
        if not (math.isfinite(w) and w > 0):
            raise ValueError(f"bin_width must be a positive number of cells, got {bin_width!r}")
        return GaussianReading(sigma=float(sigma), p_rand=float(self.p_rand), width=w)


class PatternMatch(SensorModel):
    r"""The pattern-matching (piecewise-constant) sensor model of Section 2.6.

    Readings are discrete outcomes: a hit at ``z in {0..F}`` or max range. The outcome that matches the
    map (``z = f``, or max range when no cell in the ray is occupied) has probability ``p_occ``; the
    other ``F + 1`` outcomes share ``1 - p_occ`` equally:

    .. math:: p(z_n \mid f) = p_{occ} \text{ if } z_n = f, \quad (1 - p_{occ}) / (F + 1) \text{ otherwise.}

    (The thesis counts ``F`` other outcomes because its rays start at ``kappa = 1``; ours include the
    sensor's own cell ``kappa = 0``.)
    """

    def __init__(self, p_occ: float) -> None:
        self.p_occ = _check_prob("PatternMatch.p_occ", p_occ, open_right=False)

    def __repr__(self) -> str:
        return f"PatternMatch(p_occ={self.p_occ})"

    def log_prob(self, z, f, F, is_max=None) -> torch.Tensor:
        z, f, F, none = _common(z, f, F)
        dtype = z.dtype
        if is_max is None:
            is_max = torch.zeros(torch.broadcast_shapes(z.shape, f.shape), dtype=torch.bool)
        is_max = torch.as_tensor(is_max, dtype=torch.bool)
        match = torch.where(is_max, none, (~none) & (torch.round(z) == f))
        other = (
            torch.log1p(torch.tensor(-self.p_occ, dtype=dtype)) - torch.log(F + 1.0)
            if self.p_occ < 1
            else torch.full_like(F, -math.inf)
        )
        return torch.where(match, torch.tensor(math.log(self.p_occ), dtype=dtype), other)

    def sample(self, f, F, generator: torch.Generator | None = None):
        f = _as_tensor(f)
        F = _as_tensor(F, f.dtype).expand_as(f)
        none = f > F
        keep = torch.rand(f.shape, generator=generator, dtype=f.dtype) < self.p_occ
        # an "other" outcome: uniform over the F + 1 outcomes that differ from the matching one
        u = torch.floor(torch.rand(f.shape, generator=generator, dtype=f.dtype) * (F + 1.0))
        truth = torch.where(none, F + 1.0, f)  # F + 1 encodes max range
        other = torch.where(u >= truth, u + 1.0, u)
        out = torch.where(keep, truth, other)
        is_max = out > F
        return torch.where(is_max, F + 1.0, out), is_max

    def compiled(self, bin_width: float | None = None) -> PatternReading:
        """:class:`~ogm_ppl.sensors_compiled.PatternReading` ``(p_occ)`` (the outcomes are the cells:
        ``bin_width`` is ignored)."""
        from ogm_ppl.sensors_compiled import PatternReading

        return PatternReading(p_occ=float(self.p_occ))


#: the kinds the library ships: ``gaussian`` is ``GaussianRange(sigma_cells, p_rand)``
SENSOR_KINDS: tuple[str, ...] = ("gaussian",)

#: ``factory(sigma_cells, p_rand) -> SensorModel``, called with the two positionally: the range noise in cells
#: (the data's, or the method's ``sigma_cells``) and the share of random readings in ``[0, 1)``; a factory may
#: ignore either
SensorFactory = Callable[[float, float], SensorModel]
_REGISTRY: Registry[SensorFactory] = Registry("sensor", SENSOR_KINDS)


class SensorFactoryError(TypeError, ValueError):
    """A sensor factory that cannot be called as ``factory(sigma_cells, p_rand)`` or returns no
    :class:`SensorModel` (a ``TypeError``, and a ``ValueError`` as every bad setting is)."""


def register_sensor(kind: str, factory: SensorFactory) -> None:
    """Make ``sensor_by_name(kind, sigma_cells, p_rand)`` build ``factory(sigma_cells, p_rand)``.

    The factory is called with the two *positionally*: a class whose first two parameters mean something else
    is registered through a ``lambda sigma_cells, p_rand: MySensor(...)``. ``kind`` is a non-empty name without
    ``:``; a name another factory took is refused (:func:`unregister_sensor` first), and a factory defined at
    the same place (module, qualified name, and a lambda's line: a module reloaded, a notebook cell run again)
    replaces the old one. A factory that cannot
    take the two arguments is refused here (:class:`SensorFactoryError`). Test the sensor with
    :class:`~ogm_ppl.testing.SensorContract`.
    """
    _REGISTRY.check_kind(kind)
    if callable(factory):
        _check_call(factory, {}, f"sensor kind {kind!r}", "cannot be called as factory(sigma_cells, p_rand)")
    _REGISTRY.register(kind, factory)


def _check_call(factory, options: dict, what: str, cannot: str) -> None:
    """Raise :class:`SensorFactoryError` (``"{what}: the factory NAME(SIGNATURE) {cannot} (why)"``) if
    ``factory(sigma_cells, p_rand, **options)`` does not bind to the factory's signature (a factory without one,
    a builtin, passes)."""
    try:
        signature = inspect.signature(factory)
    except (TypeError, ValueError):
        return
    name = getattr(factory, "__qualname__", repr(factory))
    positional = [
        p.name for p in signature.parameters.values() if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)
    ][:2]
    taken = [k for k in options if k in positional]
    if taken:  # the two arguments every factory gets: from the method's parameters, never from the name
        raise SensorFactoryError(
            f"{what}: the factory's first two arguments ({', '.join(positional)}) are the range noise and the "
            "share of random readings, set by the method's parameters sigma_cells and p_rand (the command "
            f"line's --sigma and --param p_rand=...), not by the options of a name ({', '.join(taken)})"
        )
    try:
        signature.bind(1.0, 0.0, **options)
    except TypeError as e:
        raise SensorFactoryError(f"{what}: the factory {name}{signature} {cannot} ({e})") from None


def unregister_sensor(kind: str) -> None:
    """Remove a kind added by :func:`register_sensor` (the shipped kinds stay)."""
    _REGISTRY.unregister(kind)


def sensor_kinds() -> tuple[str, ...]:
    """Every kind :func:`sensor_by_name` knows: the shipped ones, then the registered ones."""
    return _REGISTRY.kinds()


def split_sensor_name(name: str) -> tuple[str, dict[str, int | float]]:
    """``"KIND"`` or ``"KIND:KEY=VALUE,KEY=VALUE"`` as ``(KIND, {KEY: VALUE})``; values are numbers (an integer
    literal stays an ``int``). ``ValueError`` on anything else."""
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"a sensor name is KIND or KIND:KEY=VALUE,..., got {name!r}")
    kind, colon, rest = name.strip().partition(":")
    kind = kind.strip()
    options: dict[str, int | float] = {}
    if colon:
        for item in rest.split(","):
            key, eq, text = item.partition("=")
            key, text = key.strip(), text.strip()
            if not eq or not key.isidentifier() or key in options:
                raise ValueError(f"sensor {name!r}: options are KEY=VALUE pairs with distinct keys, got {item!r}")
            value: int | float
            try:
                value = int(text)
            except ValueError:
                try:
                    value = float(text)
                except ValueError:
                    raise ValueError(f"sensor {name!r}: option {key} must be a number, got {text!r}") from None
            if not math.isfinite(value):
                raise ValueError(f"sensor {name!r}: option {key} must be finite, got {text!r}")
            options[key] = value
    return kind, options


def sensor_by_name(name: str, sigma_cells: float = 1.0, p_rand: float = 0.0) -> SensorModel:
    """The sensor ``name`` (``KIND`` or ``KIND:KEY=VALUE,...``, module docstring) for range noise
    ``sigma_cells`` (cells, ``> 0``) and a share ``p_rand`` of random readings (``[0, 1)``): the kind's
    ``factory(sigma_cells, p_rand, **options)``. ``ValueError`` on an unknown kind (listing the kinds), a
    malformed name or parameters out of range; :class:`SensorFactoryError` if the factory does not take the
    options or returns no :class:`SensorModel`."""
    kind, options = split_sensor_name(name)
    factory = _REGISTRY.get(kind, name)
    sigma_cells, p_rand = float(sigma_cells), float(p_rand)
    if not (math.isfinite(sigma_cells) and sigma_cells > 0):
        raise ValueError(f"sigma_cells must be positive and finite, got {sigma_cells}")
    if not 0.0 <= p_rand < 1.0:
        raise ValueError(f"p_rand must lie in [0, 1), got {p_rand}")
    if options:
        _check_call(factory, options, f"sensor {name!r}", f"does not take the options {', '.join(options)}")
    sensor = factory(sigma_cells, p_rand, **options)
    if not isinstance(sensor, SensorModel):
        raise SensorFactoryError(
            f"the factory of sensor kind {kind!r} returned {type(sensor).__name__}, not a SensorModel"
        )
    return sensor


register_sensor("gaussian", GaussianRange)
