"""The machine's free memory and the one refusal of work that would not fit in it.

A size check states its estimate and what it is made of, and names the limit: the memory this machine has free
(``MemAvailable`` of ``/proc/meminfo``). Where that is unknown (not Linux) nothing is refused. This module imports
nothing of the library: every layer may use it.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["available_memory", "check_fits", "in_units"]


def available_memory() -> int | None:
    """Bytes this machine can still give (``MemAvailable`` of ``/proc/meminfo``); ``None`` where unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def in_units(n: float) -> str:
    """``n`` bytes in KiB, MiB or GiB, one decimal (``"46.5 GiB"``, ``"212.0 KiB"``)."""
    for unit, size in (("GiB", 2**30), ("MiB", 2**20)):
        if n >= size:
            return f"{n / size:,.1f} {unit}"
    return f"{n / 2**10:,.1f} KiB"


def check_fits(need: int, what: str, advice: str, error: Callable[[str], Exception] = MemoryError) -> None:
    """Raise ``error(message)`` when ``need`` bytes exceed :func:`available_memory`:
    ``"WHAT needs about N GiB, more than the M GiB this machine has free (MemAvailable); ADVICE"`` (``what``
    states the estimate's basis)."""
    have = available_memory()
    if have is not None and need > have:
        raise error(
            f"{what} needs about {in_units(need)}, more than the {in_units(have)} this machine has free "
            f"(MemAvailable of /proc/meminfo); {advice}"
        )
