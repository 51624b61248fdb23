r"""Update terms Delta of traditional OGM: the log-odds inverse sensor models of Table 2.1 and pN.

Traditional OGM (Section 2.4, Eq. 2.10) adds an update term ``Delta`` to the evidence of every cell
``m_kappa`` on the ray of reading ``z_n``. Every family here is a ``torch.nn.Module`` whose named
parameters are differentiable (:mod:`ogm_ppl.inference.variational.delta_fit` fits them as amortised
variational parameters, Section 2.5),
and produces a lookup table

.. math:: T[\kappa, z] = \Delta(\kappa; z_n = z), \qquad T[\kappa, Z] = \Delta(\kappa; \text{max range})

over ``kappa = 0..n_kappa-1`` and ``z = 0..Z-1``; the last column is the update of a max-range reading.
Families that depend on ``d = kappa - z_n`` only give a max-range reading their far-before-the-reading
value ``Delta(d -> -inf)`` (the "free" value), so a max-range reading frees the whole ray.

The parameter values the thesis reports (Table 2.1 "Optimized Values", Table 2.2 for p21, Hähnel 2004
for traditional OGM) are available through :func:`delta_by_name`.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from ogm_ppl.sensors import GaussianRange

__all__ = [
    "NeuralDelta",
    "DeltaFamily",
    "BorensteinKoren",
    "Moravec",
    "MarshallBarfoot",
    "Stachniss",
    "Elfes",
    "PN",
    "delta_by_name",
    "load_delta",
    "DeltaFileError",
    "THESIS_P21",
    "THESIS_SETTING",
    "fitted_setting",
]


def _param(value: float) -> nn.Parameter:
    return nn.Parameter(torch.tensor(float(value), dtype=torch.float64))


class DeltaFamily(nn.Module):
    """Base class. Subclasses of the offset form implement ``delta(d)`` and ``far()``.

    ``fitted_setting``: for a term fitted to 1D data (Section 2.5), the sensor setting it was fitted for
    (the artefact's ``training`` block: ``sigma``, ``F``, ``wall`` in cells, ..., plus its ``name``);
    ``None`` for a term that holds no setting (hand-set values such as Hähnel's, or a fresh family).
    Set by :func:`load_delta`, :func:`delta_by_name` and the setting fit; read it with
    :func:`fitted_setting`. (Not ``training``: that is ``nn.Module``'s train/eval flag.)
    """

    fitted_setting: dict | None = None

    def delta(self, d: torch.Tensor) -> torch.Tensor:  # pragma: no cover - interface
        """Delta at integer offsets ``d = kappa - z_n`` (float64 tensor of any shape)."""
        raise NotImplementedError

    def far(self) -> torch.Tensor:
        """Delta far before the reading (``d -> -inf``): the update of a max-range reading."""
        return self.delta(torch.tensor([-1.0e9], dtype=torch.float64))[0]

    def table(self, n_kappa: int, n_z: int) -> torch.Tensor:
        """``n_kappa x (n_z + 1)`` float64 table; column ``n_z`` is the max-range reading."""
        kappa = torch.arange(n_kappa, dtype=torch.float64)[:, None]
        z = torch.arange(n_z, dtype=torch.float64)[None, :]
        hits = self.delta(kappa - z)
        mx = self.far().expand(n_kappa, 1)
        return torch.cat([hits, mx], dim=1)

    def table_bytes(self, n_kappa: int, n_z: int) -> int:
        """Bytes :meth:`table` holds at its peak for these sizes (an upper bound, so that a caller can refuse a
        table that would not fit before building it): the offset form, 6 float64 tables (measured: 3.1 for haehnel,
        5.1 for p21)."""
        return 6 * 8 * n_kappa * (n_z + 1)

    def forward(self, n_kappa: int, n_z: int) -> torch.Tensor:
        """Same as :meth:`table` (so that ``torch.func.functional_call`` works on a family)."""
        return self.table(n_kappa, n_z)

    def extra_repr(self) -> str:
        return ", ".join(f"{k}={v.item():.4f}" for k, v in self.named_parameters())


class BorensteinKoren(DeltaFamily):
    r"""Borenstein & Koren (1991): information only at the reading, ``Delta = l_occ`` at ``d = 0``."""

    def __init__(self, l_occ: float = 1.3863) -> None:
        super().__init__()
        self.l_occ = _param(l_occ)

    def delta(self, d):
        return torch.where(d == 0, self.l_occ, torch.zeros((), dtype=torch.float64))


class Moravec(DeltaFamily):
    r"""Moravec (1988), Fig. 2.2: ``l_free`` for ``d < 0``, ``l_occ`` at ``d = 0``, 0 beyond.

    Hähnel's (2004) ``l_occ = -l_free = log(0.8/0.2) = 1.3863`` is the thesis's *traditional OGM*
    (``Moravec.haehnel()``).
    """

    def __init__(self, l_occ: float = 1.3863, l_free: float = -1.3863) -> None:
        super().__init__()
        self.l_occ = _param(l_occ)
        self.l_free = _param(l_free)

    @classmethod
    def haehnel(cls) -> Moravec:
        """Traditional OGM: ``p_occ = 0.8``, ``p_free = 0.2`` (Hähnel 2004), natural log-odds."""
        return cls(math.log(4.0), -math.log(4.0))

    def delta(self, d):
        zero = torch.zeros((), dtype=torch.float64)
        return torch.where(d < 0, self.l_free, torch.where(d == 0, self.l_occ, zero))


class MarshallBarfoot(DeltaFamily):
    r"""Marshall & Barfoot (2007): ``l_occ = -l_free``, occupied for ``beta`` cells ``0 <= d < beta``.

    ``beta`` is an integer (not differentiable).
    """

    def __init__(self, l_occ: float = 1.3863, beta: int = 1) -> None:
        super().__init__()
        if int(beta) != beta or beta < 1:
            raise ValueError(f"MarshallBarfoot.beta must be a positive integer, got {beta!r}")
        self.l_occ = _param(l_occ)
        self.beta = int(beta)

    def delta(self, d):
        zero = torch.zeros((), dtype=torch.float64)
        occ = (d >= 0) & (d < self.beta)
        return torch.where(d < 0, -self.l_occ, torch.where(occ, self.l_occ, zero))

    def extra_repr(self) -> str:
        return f"l_occ={self.l_occ.item():.4f}, beta={self.beta}"


class Stachniss(DeltaFamily):
    r"""Stachniss (2006), sonar: linear interpolation of width ``alpha`` centred on the reading.

    Our reading of Fig. 2.3: ``l_free`` up to ``d = -alpha/2``, rising linearly to ``l_occ`` at
    ``d = 0``, falling linearly to 0 at ``d = alpha/2``, 0 beyond. ``alpha -> 0`` recovers Moravec.
    """

    def __init__(self, l_occ: float = 1.3863, l_free: float = -1.3863, alpha: float = 2.0) -> None:
        super().__init__()
        if not alpha > 0:
            raise ValueError(f"Stachniss.alpha must be positive, got {alpha!r}")
        self.l_occ = _param(l_occ)
        self.l_free = _param(l_free)
        self.alpha = _param(alpha)

    def delta(self, d):
        h = self.alpha.abs() / 2 + 1e-12
        rise = self.l_free + (self.l_occ - self.l_free) * torch.clamp((d + h) / h, 0.0, 1.0)
        fall = self.l_occ * torch.clamp(1.0 - d / h, 0.0, 1.0)
        return torch.where(d <= 0, rise, fall)


class Elfes(DeltaFamily):
    r"""Elfes (1989a): the exact single-reading update of a Gaussian range sensor, floored at ``l_min``.

    .. math::
        \Delta = \max\Bigl(l_{min}, \log \frac{\sum_f p(z_n \mid f)\, p(f \mid m_\kappa = 1)}
                                             {\sum_f p(z_n \mid f)\, p(f \mid m_\kappa = 0)}\Bigr)

    with ``p(z | f) = N(f, sigma^2)`` (:class:`~ogm_ppl.sensors.GaussianRange`, censored at the ray's
    end for max-range readings) and ``p(f | m_kappa)`` from independent cells of prior ``prior`` along a
    ray of ``n_kappa`` cells (Section 2.5). Depends on ``kappa`` and ``z`` separately, not only on
    ``kappa - z``. ``max_kappa`` fixes the ray's last kappa ``F`` (the sensor's range in kappa units,
    75 in the thesis's 1D setting); by default it is the table's last row.
    """

    def __init__(
        self,
        sigma: float = 3.0,
        l_min: float = -12.9047,
        prior: float = 0.5,
        max_kappa: int | None = None,
    ) -> None:
        super().__init__()
        if not sigma > 0:
            raise ValueError(f"Elfes.sigma must be positive, got {sigma!r}")
        if not 0.0 < prior < 1.0:
            raise ValueError(f"Elfes.prior must lie in (0, 1), got {prior!r}")
        self.sigma = _param(sigma)
        self.l_min = _param(l_min)
        if max_kappa is not None and (isinstance(max_kappa, bool) or int(max_kappa) != max_kappa or max_kappa < 0):
            raise ValueError(f"Elfes.max_kappa must be None or an integer >= 0 (cells), got {max_kappa!r}")
        self.prior = float(prior)
        self.max_kappa = None if max_kappa is None else int(max_kappa)

    def table(self, n_kappa: int, n_z: int) -> torch.Tensor:
        F = n_kappa - 1 if self.max_kappa is None else self.max_kappa
        out_rows = n_kappa
        n_kappa = F + 1
        dt = torch.float64
        lam = self.prior
        j = torch.arange(n_kappa + 1, dtype=dt)  # f = 0..F, and F + 1 = none
        kap = torch.arange(n_kappa, dtype=dt)[:, None]
        log_l, log_1l = math.log(lam), math.log1p(-lam)
        base = torch.where(j <= F, log_l + j * log_1l, (F + 1) * log_1l)  # p(f) with iid cells
        ninf = torch.tensor(-math.inf, dtype=dt)
        # m_kappa = 1: f <= kappa only; f = kappa loses its log(lam) factor
        lp1 = torch.where(j < kap, base, torch.where(j == kap, j * log_1l, ninf))
        # m_kappa = 0: f != kappa; cells past kappa lose one log(1 - lam) factor
        lp0 = torch.where(j < kap, base, torch.where(j == kap, ninf, base - log_1l))
        sensor = GaussianRange(self.sigma.abs() + 1e-12)
        # readings past the range (z > F) cannot occur: computed at z = F, then given no information
        z = torch.arange(n_z, dtype=dt).clamp(max=F)
        zz = torch.cat([z, torch.tensor([F + 1.0], dtype=dt)])[:, None]  # n_z + 1 readings
        is_max = torch.zeros(n_z + 1, 1, dtype=torch.bool)
        is_max[-1] = True
        lz = sensor.log_prob(zz, j[None, :], torch.tensor(float(F), dtype=dt), is_max)  # (n_z+1, F+2)
        num = torch.logsumexp(lp1[:, None, :] + lz[None, :, :], dim=-1)
        den = torch.logsumexp(lp0[:, None, :] + lz[None, :, :], dim=-1)
        table = torch.maximum(num - den, self.l_min)
        if n_z > F + 1:
            table = torch.cat([table[:, : F + 1], table.new_zeros(n_kappa, n_z - F - 1), table[:, -1:]], 1)
        if out_rows > n_kappa:  # rows past the sensor's range: no information
            table = torch.cat([table, table.new_zeros(out_rows - n_kappa, n_z + 1)])
        return table[:out_rows]

    def table_bytes(self, n_kappa: int, n_z: int) -> int:
        """:meth:`table` sums over the first hit for every ``(kappa, z)``: two ``n_kappa x (n_z + 1) x (F + 2)``
        float64 temporaries (``F + 1`` the rows within the range), cubic in the table's side."""
        rows = n_kappa if self.max_kappa is None else min(n_kappa, self.max_kappa + 1)
        return 2 * 8 * rows * (n_z + 1) * (rows + 1) + super().table_bytes(n_kappa, n_z)

    def delta(self, d):  # pragma: no cover - Elfes is not a function of d alone
        raise TypeError("Elfes depends on kappa and z separately; use table()")

    def far(self):  # pragma: no cover
        raise TypeError("Elfes depends on kappa and z separately; use table()")


class PN(DeltaFamily):
    r"""The free-form update term pN of Section 2.5: ``N`` values of ``Delta(kappa - z_n)``.

    The values sit at offsets ``d = lo..lo+N-1`` with ``lo = -ceil(N/2)``; cells nearer the robot than
    ``lo`` take the first value and cells past the last offset take 0. This is the thesis's layout:
    p1 is a single "free" value before the reading, p2 is Moravec, and p21 spans ``d = -11..9``
    (Table 2.2).
    """

    def __init__(self, values) -> None:
        super().__init__()
        values = torch.as_tensor(values, dtype=torch.float64).flatten()
        if values.numel() < 1:
            raise ValueError("PN needs at least one value")
        self.values = nn.Parameter(values.clone())

    @property
    def N(self) -> int:
        return self.values.numel()

    @property
    def lo(self) -> int:
        return -((self.N + 1) // 2)

    @classmethod
    def zeros(cls, N: int) -> PN:
        return cls(torch.zeros(N, dtype=torch.float64))

    def delta(self, d):
        idx = (d - self.lo).clamp(min=0)
        inside = idx < self.N
        vals = self.values[idx.clamp(max=self.N - 1).long()]
        return torch.where(inside, vals, torch.zeros((), dtype=torch.float64))

    def extra_repr(self) -> str:
        return f"N={self.N}, lo={self.lo}"


class NeuralDelta(DeltaFamily):
    """An MLP inverse sensor model: ``Delta(kappa, z) = g([(kappa - z) / 10, z / F, is_max])``.

    Args:
        F: the sensor's range in cells (to scale ``z``).
        hidden: hidden units per layer (two ``tanh`` layers).
        seed: initial weights (deterministic).
    """

    #: the most hidden units per layer accepted (a ``hidden x hidden`` weight matrix: 4096 is 128 MiB)
    MAX_HIDDEN = 4096

    def __init__(self, F: int = 75, hidden: int = 16, seed: int = 0) -> None:
        super().__init__()
        if isinstance(F, bool) or not isinstance(F, int | float) or int(F) != F or F < 1:
            raise ValueError(f"NeuralDelta.F (the sensor's range in cells) must be an integer >= 1, got {F!r}")
        if isinstance(hidden, bool) or not isinstance(hidden, int | float) or int(hidden) != hidden:
            raise ValueError(f"NeuralDelta.hidden must be an integer, got {hidden!r}")
        if not 1 <= hidden <= self.MAX_HIDDEN:
            raise ValueError(f"NeuralDelta.hidden must lie in 1..{self.MAX_HIDDEN} (units per layer), got {hidden!r}")
        g = torch.Generator().manual_seed(seed)
        self.F = int(F)
        self.hidden = int(hidden)
        self.net = nn.Sequential(
            nn.Linear(3, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh(), nn.Linear(hidden, 1)
        )
        with torch.no_grad():
            for p in self.net.parameters():
                p.copy_(torch.randn(p.shape, generator=g) * (0.5 / math.sqrt(max(p.shape[-1], 1))))
        self.double()

    def table(self, n_kappa: int, n_z: int) -> torch.Tensor:
        kappa = torch.arange(n_kappa, dtype=torch.float64)[:, None].expand(n_kappa, n_z + 1)
        z = torch.cat([torch.arange(n_z, dtype=torch.float64), torch.tensor([self.F + 1.0])])[None, :].expand(
            n_kappa, -1
        )
        is_max = torch.zeros(n_kappa, n_z + 1, dtype=torch.float64)
        is_max[:, -1] = 1.0
        x = torch.stack([(kappa - z) / 10.0, z / self.F, is_max], -1)
        return self.net(x)[..., 0]

    def table_bytes(self, n_kappa: int, n_z: int) -> int:
        """:meth:`table` runs the MLP on every ``(kappa, z)``: its 3 inputs, two ``hidden``-wide activations and
        a few float64 tables."""
        return 8 * n_kappa * (n_z + 1) * (3 + 2 * self.hidden + 4)

    def delta(self, d):  # pragma: no cover - not a function of d alone
        raise TypeError("NeuralDelta depends on kappa and z; use table()")

    def extra_repr(self) -> str:
        return f"F={self.F}, hidden={self.hidden}"


# Table 2.2: p21, offsets -11 (and below) .. 9; 0 from 10 on.
THESIS_P21 = (
    -5.4028,
    -2.2993,
    -1.7025,
    -1.2979,
    -0.9722,
    -0.6836,
    -0.4341,
    -0.2476,
    -0.1083,
    0.0051,
    0.0719,
    0.0995,
    0.0877,
    0.0564,
    0.0242,
    -0.0077,
    -0.0215,
    -0.0213,
    -0.0149,
    -0.0068,
    0.0034,
)


#: The 1D setting of the thesis's fits (Section 2.5: ``F = 75`` cells, wall at ``f = 60``, ``sigma = 3``
#: cells, 1000 datasets): the ``fitted_setting`` of the ``*_thesis`` terms of :func:`delta_by_name`.
THESIS_SETTING = {
    "F": 75,
    "wall": 60,
    "sigma": 3.0,
    "num": 1000,
    "prior": "uniform",
    "source": "Merali 2020, Section 2.5 (Tables 2.1, 2.2)",
}


_FAMILIES: dict[str, type[DeltaFamily]] = {}  # filled below: class name -> class, for artefacts


def family_to_dict(family: DeltaFamily) -> dict:
    """A JSON-able description of a family and its parameter values (see :func:`family_from_dict`)."""
    fixed: dict[str, object] = {}
    if isinstance(family, MarshallBarfoot):
        fixed["beta"] = family.beta
    if isinstance(family, Elfes):
        fixed.update(prior=family.prior, max_kappa=family.max_kappa)
    if isinstance(family, NeuralDelta):
        fixed.update(F=family.F, hidden=family.hidden)
    params = {k: v.detach().tolist() for k, v in family.state_dict().items()}
    return {"family": type(family).__name__, "params": params, "fixed": fixed}


class DeltaFileError(ValueError):
    """A Delta artefact (JSON) that cannot be loaded: the message names the path and what is wrong."""


def family_from_dict(spec: dict) -> DeltaFamily:
    """Rebuild a family from :func:`family_to_dict`'s output (no code is executed from the file).

    Validated: a known family, parameters by name with the shapes the family expects, finite values.
    """
    if not isinstance(spec, dict) or not isinstance(spec.get("family"), str):
        raise ValueError("'delta' must be an object with a 'family' name")
    name = spec["family"]
    cls = _FAMILIES.get(name)
    if cls is None:
        raise ValueError(f"unknown Delta family {name!r} (known: {sorted(_FAMILIES)})")
    fixed = spec.get("fixed", {})
    params = spec.get("params")
    if not isinstance(fixed, dict) or not isinstance(params, dict):
        raise ValueError("'params' and 'fixed' must be objects")
    tensors = {}
    for k, v in params.items():
        try:
            t = torch.as_tensor(v, dtype=torch.float64)
        except (TypeError, ValueError, RuntimeError):
            raise ValueError(f"parameter {k!r} is not numeric") from None
        if not torch.isfinite(t).all():
            raise ValueError(f"parameter {k!r} holds a non-finite value")
        tensors[k] = t
    for k, v in fixed.items():
        if isinstance(v, bool) or not isinstance(v, (int, float, list)):
            raise ValueError(f"fixed setting {k!r} must be a number, got {v!r}")
    if cls is PN:
        if set(tensors) != {"values"} or tensors["values"].dim() != 1 or len(tensors["values"]) < 1:
            raise ValueError("PN needs one parameter 'values', a non-empty list")
        return PN(tensors["values"].tolist())
    try:
        fam = cls(**fixed) if fixed else cls()
    except (TypeError, ValueError) as e:
        raise ValueError(f"bad fixed settings for {name}: {e}") from None
    expected = {k: tuple(v.shape) for k, v in fam.state_dict().items()}
    got = {k: tuple(v.shape) for k, v in tensors.items()}
    if expected != got:
        raise ValueError(f"{name} expects parameters {expected}, the file has {got}")
    fam.load_state_dict(tensors)
    return fam


def load_delta(path) -> DeltaFamily:
    """Load a Delta artefact (``delta_<name>.json``, as :func:`ogm_ppl.learn.fit_deltas` and
    :func:`~ogm_ppl.learn.fit_delta_setting` write it: ``ogm-ppl fit-prior deltas|delta-setting``) from ``path``,
    validating keys, shapes and finiteness (:class:`DeltaFileError` names what is wrong)."""
    from pathlib import Path

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DeltaFileError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise DeltaFileError(f"{path}: cannot read it as text ({e})") from None
    return _delta_from_record_text(text, str(path))[0]


def _delta_from_record_text(text: str, where: str) -> tuple[DeltaFamily, dict]:
    import json

    if not text.strip():
        raise DeltaFileError(f"{where}: empty file; expected a Delta artefact (JSON with 'format' and 'delta')")
    try:
        record = json.loads(text)
    except json.JSONDecodeError as e:
        raise DeltaFileError(
            f"{where}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg}); "
            "expected a Delta artefact written by ogm-ppl fit-prior deltas (ogm_ppl.learn.fit_deltas)"
        ) from None
    if not isinstance(record, dict):
        raise DeltaFileError(f"{where}: expected a JSON object, got {type(record).__name__}")
    if record.get("format") != 1:
        raise DeltaFileError(f"{where}: unknown artefact format {record.get('format')!r} (this version reads 1)")
    if "delta" not in record:
        raise DeltaFileError(f"{where}: no 'delta' entry: not a Delta artefact")
    training = record.get("training")
    if training is not None and not isinstance(training, dict):
        raise DeltaFileError(f"{where}: 'training' must be an object, got {type(training).__name__}")
    if training is not None:
        _check_training(training, where)
    try:
        family = family_from_dict(record["delta"])
    except ValueError as e:
        raise DeltaFileError(f"{where}: {e}") from None
    if training is not None:
        name = record.get("name")
        family.fitted_setting = {**training, **({"name": name} if isinstance(name, str) else {})}
    return family, record


#: the training block's fields read as numbers (the 1D setting, Section 2.5), and whether they must be > 0
_TRAINING_NUMBERS = {"sigma": True, "F": True, "wall": False, "num": True}


def _non_finite(value, where: str) -> str | None:
    """The dotted path of the first NaN / infinity in a JSON value, or None."""
    if isinstance(value, float) and not math.isfinite(value):
        return where
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for k, v in items:
        bad = _non_finite(v, f"{where}.{k}" if isinstance(value, dict) else f"{where}[{k}]")
        if bad is not None:
            return bad
    return None


def _check_training(training: dict, where: str) -> None:
    """A ``training`` block: no NaN / infinity anywhere (they would switch the fitted-setting check off),
    and the setting's numbers (``sigma``, ``F``, ``wall``, ``num``) numbers in range."""
    bad = _non_finite(training, "training")
    if bad is not None:
        raise DeltaFileError(f"{where}: field {bad!r} is not a finite number")
    for key, positive in _TRAINING_NUMBERS.items():
        if key not in training:
            continue
        v = training[key]
        if isinstance(v, bool) or not isinstance(v, int | float) or (v <= 0 if positive else v < 0):
            raise DeltaFileError(
                f"{where}: field 'training.{key}' must be a number {'>' if positive else '>='} 0, got {v!r}"
            )


def fitted_names() -> list[str]:
    """Names of the fitted artefacts shipped in ``ogm_ppl/fitted`` (``delta_<name>.json``)."""
    from importlib import resources

    root = resources.files("ogm_ppl") / "fitted"
    return sorted(
        p.name[len("delta_") : -len(".json")]
        for p in root.iterdir()
        if p.name.startswith("delta_") and p.name.endswith(".json") and p.name != "delta_cv.json"
    )


def load_fitted(name: str) -> tuple[DeltaFamily, dict]:
    """A shipped fitted family and its record (training settings, scores)."""
    from importlib import resources

    path = resources.files("ogm_ppl") / "fitted" / f"delta_{name}.json"
    if not path.is_file():
        raise ValueError(f"no fitted Delta named {name!r}; shipped: {fitted_names()}")
    return _delta_from_record_text(path.read_text(encoding="utf-8"), str(path))


def delta_by_name(name: str, path=None) -> DeltaFamily:
    """A Delta family with published or fitted values.

    Names: ``"haehnel"`` (traditional OGM); the thesis's optimised values (Table 2.1, 2.2):
    ``"borenstein_koren_thesis"``, ``"moravec_thesis"``, ``"marshall_barfoot_thesis"``,
    ``"stachniss_thesis"``, ``"elfes_thesis"``, ``"p21_thesis"``; and our fits shipped with the library
    (:func:`fitted_names`: ``"moravec_opt"``, ``"elfes_opt"``, ``"p1"`` .. ``"p21"``, ``"neural_opt"``, ...).

    ``path``: a fit of one's own instead: the artefact file itself, or a folder holding ``delta_<name>.json``
    (the folder ``ogm-ppl fit-prior deltas|delta-setting --out`` wrote), read by :func:`load_delta`.

    Fitted and thesis terms carry the setting they were fitted for (:func:`fitted_setting`).
    """
    if path is not None:
        from pathlib import Path

        p = Path(path)
        return load_delta(p / f"delta_{name}.json" if p.is_dir() else p)
    makers = {
        "haehnel": Moravec.haehnel,
        "borenstein_koren_thesis": lambda: BorensteinKoren(-0.2197),
        "moravec_thesis": lambda: Moravec(0.9787, -0.7021),
        "marshall_barfoot_thesis": lambda: MarshallBarfoot(0.7183, 2),
        "stachniss_thesis": lambda: Stachniss(0.5115, -0.8135, 7.0),
        "elfes_thesis": lambda: Elfes(2.9627, -12.9047),
        "p21_thesis": lambda: PN(THESIS_P21),
    }
    if name in makers:
        family = makers[name]()
        if name.endswith("_thesis"):
            family.fitted_setting = {**THESIS_SETTING, "name": name}
        return family
    if name in fitted_names():
        return load_fitted(name)[0]
    raise ValueError(f"unknown Delta name {name!r}; known: {sorted(makers) + fitted_names()}")


def fitted_setting(delta_or_name: DeltaFamily | str) -> dict | None:
    """The 1D sensor setting a term was fitted for, or ``None`` if it holds none (Section 2.5).

    For a shipped artefact (``ogm_ppl/fitted/delta_<name>.json``) or a file read by :func:`load_delta`:
    its ``training`` block (``sigma``, ``F``, ``wall``, ``num``, ``seed``, ... in cells) plus ``name``.
    For the thesis's published values (``*_thesis``): :data:`THESIS_SETTING`, which Section 2.5 states
    (sigma 3, F 75, wall 60). ``"haehnel"`` (hand-set ``p = 0.8 / 0.2``) and a fresh family: ``None``.
    A copy: changing it changes nothing.
    """
    fam = delta_by_name(delta_or_name) if isinstance(delta_or_name, str) else delta_or_name
    setting = fam.fitted_setting
    return None if setting is None else dict(setting)


_FAMILIES.update(
    {c.__name__: c for c in (BorensteinKoren, Moravec, MarshallBarfoot, Stachniss, Elfes, PN, NeuralDelta)}
)
