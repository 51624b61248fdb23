"""Whether a fitted update term Delta is used inside the sensor setting it was fitted for (Section 2.5).

A term fitted to 1D data for one range noise ``sigma`` and one maximum range ``F`` (cells) can erase walls
or blur them elsewhere. :func:`check_delta_setting` is the one check every path that uses a shipped term
calls (the map methods, :func:`~ogm_ppl.inference.log_odds.evidence_grid`, the experiment runner); it warns
with :class:`FittedSettingWarning` and says how to refit
(:func:`~ogm_ppl.inference.variational.fit_delta_for_setting`).
"""

from __future__ import annotations

import math
import re
import warnings

from ogm_ppl.exceptions import FittedSettingWarning
from ogm_ppl.models.delta import DeltaFamily, fitted_setting

__all__ = [
    "F_FACTOR",
    "SIGMA_TOLERANCE",
    "FittedSettingWarning",
    "check_delta_setting",
    "fit_family_for",
    "setting_family_names",
    "setting_mismatches",
]


#: :func:`check_delta_setting` warns when ``|sigma - sigma_fit| > SIGMA_TOLERANCE * sigma_fit``.
SIGMA_TOLERANCE = 0.25


#: ... or when ``F`` and ``F_fit`` differ by more than this factor (either way).
F_FACTOR = 2.0


_OPT = {"moravec_opt", "borenstein_koren_opt", "marshall_barfoot_opt"}


def setting_family_names() -> str:
    """The names :func:`fit_delta_for_setting` fits, in words."""
    return "'pN' (N >= 1, e.g. 'p21'), " + ", ".join(repr(n) for n in sorted(_OPT))


def _check_name(name: str) -> None:
    m = re.fullmatch(r"p(\d+)", name)
    if m and int(m.group(1)) >= 1:
        return
    if name not in _OPT:
        raise ValueError(f"cannot fit a Delta named {name!r} for a setting; known: {setting_family_names()}")


def fit_family_for(delta_name: str) -> tuple[str, str] | None:
    """What :func:`fit_delta_for_setting` refits for the named term, as ``(name, prior)``: ``"p21"`` and
    ``"p21_thesis"`` -> ``("p21", "uniform")``, ``"p21_dd"`` -> ``("p21", "data_driven")``,
    ``"moravec_thesis"`` -> ``("moravec_opt", "uniform")``; ``None`` for a term it cannot fit (``"haehnel"``,
    Elfes, the neural terms).

    >>> fit_family_for("p21_dd"), fit_family_for("moravec_thesis"), fit_family_for("haehnel")
    (('p21', 'data_driven'), ('moravec_opt', 'uniform'), None)
    """
    base, prior = delta_name, "uniform"
    if base.endswith("_dd"):
        base, prior = base[: -len("_dd")], "data_driven"
    if base.endswith("_thesis"):
        base = base[: -len("_thesis")]
        base = base if re.fullmatch(r"p\d+", base) else base + "_opt"
    try:
        _check_name(base)
    except ValueError:
        return None
    return base, prior


def _fit_hint(name: str, sigma: float, F: float | None) -> str:
    fam = fit_family_for(name)
    base, prior = fam if fam is not None else ("p21", "data_driven" if name.endswith("_dd") else "uniform")
    extra = "" if prior == "uniform" else f", prior={prior!r}"
    f = "" if F is None else f", F={round(F)}"
    call = f"delta, _ = fit_delta_for_setting({base!r}, sigma={sigma:g}{f}{extra})"
    return call + ("  (the closest family it fits)" if fam is None else "")


def setting_mismatches(
    sigma_fit: float | None, F_fit: float | None, sigma_cells: float | None, F_cells: float | None
) -> list[str]:
    """Why a sensor setting lies outside the one something was fitted or trained for (empty: inside): the
    noise ``|sigma_cells - sigma_fit| > SIGMA_TOLERANCE * sigma_fit`` (:data:`SIGMA_TOLERANCE`), the range
    ``F_cells`` and ``F_fit`` more than a factor :data:`F_FACTOR` apart; a pair with a ``None`` (or a
    non-positive fitted value) is not compared. All in cells.

    >>> setting_mismatches(3.0, 75.0, 3.5, 120.0)
    []
    >>> setting_mismatches(3.0, 75.0, 1.0, 400.0)
    ['sigma 1 cells is not within 25% of 3', 'range F 400 cells is not within a factor 2 of 75']
    """
    bad = []
    if sigma_cells is not None and sigma_fit is not None and abs(sigma_cells - sigma_fit) > SIGMA_TOLERANCE * sigma_fit:
        bad.append(f"sigma {sigma_cells:g} cells is not within {SIGMA_TOLERANCE:.0%} of {sigma_fit:g}")
    if F_cells is not None and F_fit is not None and F_fit > 0 and F_cells > 0:
        if max(F_cells / F_fit, F_fit / F_cells) > F_FACTOR:
            bad.append(f"range F {F_cells:g} cells is not within a factor {F_FACTOR:g} of {F_fit:g}")
    return bad


def check_delta_setting(
    delta_or_name: DeltaFamily | str,
    sigma_cells: float | None,
    F_cells: float | None = None,
    *,
    where: str = "",
    fit_sigma: float | None = None,
) -> bool:
    """Whether a term is used inside the setting it was fitted for; warns (:class:`FittedSettingWarning`)
    if not.

    The term's setting is :func:`~ogm_ppl.models.delta.fitted_setting` (the artefact's ``training``
    block). Outside means ``|sigma_cells - sigma_fit| > 25 %`` of ``sigma_fit`` (:data:`SIGMA_TOLERANCE`)
    or, if ``F_cells`` is given, ``F_cells`` and ``F_fit`` differ by more than a factor 2
    (:data:`F_FACTOR`); ``sigma_cells=None`` (the noise is not known, e.g. a real log) checks ``F`` alone. Both
    are in cells at the map's resolution (``sigma_m / resolution``,
    ``max_range_m / resolution``). Terms that hold no setting (``"haehnel"``: hand-set, or a family made by
    hand) never warn and return ``True``; the thesis's ``*_thesis`` values hold the setting Section 2.5
    states (sigma 3, F 75) and do warn. ``where`` (e.g. ``"experiment intel_5cm"``) goes into the message.
    ``fit_sigma``: the noise the message's refit call names when ``sigma_cells`` is not known (the one a
    refit of the map would use; default the term's own).

    >>> import warnings
    >>> check_delta_setting("p21", sigma_cells=3.0, F_cells=75)  # the shipped p21's own setting
    True
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     check_delta_setting("p21", sigma_cells=1.0, F_cells=400, where="intel at 5 cm")
    False
    >>> caught[0].category.__name__, "fit_delta_for_setting('p21', sigma=1, F=400)" in str(caught[0].message)
    ('FittedSettingWarning', True)
    """
    if sigma_cells is not None and not (math.isfinite(sigma_cells) and sigma_cells > 0):
        raise ValueError(f"sigma_cells must be a positive number or None, got {sigma_cells!r}")
    if F_cells is not None and not (math.isfinite(F_cells) and F_cells > 0):
        raise ValueError(f"F_cells must be a positive number or None, got {F_cells!r}")
    setting = fitted_setting(delta_or_name)
    if setting is None or not isinstance(setting.get("sigma"), (int, float)):
        return True
    sigma_fit = float(setting["sigma"])
    F_fit = setting.get("F")
    bad = setting_mismatches(sigma_fit, F_fit if isinstance(F_fit, (int, float)) else None, sigma_cells, F_cells)
    if not bad:
        return True
    name = setting.get("name") or (delta_or_name if isinstance(delta_or_name, str) else type(delta_or_name).__name__)
    fitted = f"sigma = {sigma_fit:g} cells" + (f", F = {F_fit:g} cells" if isinstance(F_fit, (int, float)) else "")
    at = ", ".join(
        ([] if sigma_cells is None else [f"sigma = {sigma_cells:g} cells"])
        + ([] if F_cells is None else [f"F = {F_cells:g} cells"])
    )
    loc = f" in {where}" if where else ""
    hint_sigma = sigma_cells if sigma_cells is not None else fit_sigma if fit_sigma is not None else sigma_fit
    warnings.warn(
        FittedSettingWarning(
            f"Delta term {name!r} was fitted for {fitted} but is used at {at}{loc} ({'; '.join(bad)}); "
            f"outside its setting it can erase walls or blur them. Fit it for this setting (from "
            f'ogm_ppl.inference.variational; or fit = "setting" in an experiment spec, --param fit=setting on '
            f"the command line): {_fit_hint(str(name), hint_sigma, F_cells)}"
        ),
        stacklevel=2,
    )
    return False
