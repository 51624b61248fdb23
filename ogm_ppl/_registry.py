"""Factories registered by name: the one mechanism behind prior kinds, sensor kinds and input kinds."""

from __future__ import annotations

from collections.abc import Callable
from typing import Generic, TypeVar

from ogm_ppl.extensions import load_extensions

F = TypeVar("F")

__all__ = ["Registry"]


def _where(factory) -> tuple[str, str]:
    """Where a factory was defined: ``(module, qualified name)``, a lambda's line too (every lambda of a module
    has the qualified name ``<lambda>``)."""
    name = getattr(factory, "__qualname__", repr(factory))
    code = getattr(factory, "__code__", None)
    if name.endswith("<lambda>") and code is not None:
        name = f"{name} (line {code.co_firstlineno})"
    return getattr(factory, "__module__", "?") or "?", name


class Registry(Generic[F]):
    """Kinds of one role (``"prior"``, ``"sensor"``, ``"input"``) and their factories.

    ``shipped`` kinds cannot be unregistered. A kind is a non-empty name without ``:``; registering a name
    another factory took is refused; a factory defined at the same place (module, qualified name, and a
    lambda's line: a module reloaded, a notebook cell run again) replaces the old one. ``origin(entry)``: the
    function an entry that is no function itself is placed by (an input kind: its ``read``); by default the
    entry.
    """

    def __init__(self, role: str, shipped: tuple[str, ...], origin: Callable[[F], Callable] | None = None) -> None:
        self.role = role
        self.shipped = shipped
        self.factories: dict[str, F] = {}
        self._origin = origin

    def _function(self, entry: F) -> Callable:
        return self._origin(entry) if self._origin is not None else entry  # type: ignore[return-value]

    def check_kind(self, kind: str) -> None:
        """Refuse a kind that is not a non-empty name without ``:`` (``ValueError``)."""
        if not isinstance(kind, str) or not kind or ":" in kind:
            raise ValueError(f"a {self.role} kind is a non-empty name without ':', got {kind!r}")

    def register(self, kind: str, factory: F) -> None:
        self.check_kind(kind)
        function = self._function(factory)
        if not callable(function):
            raise TypeError(f"the factory of {self.role} kind {kind!r} must be callable, got {type(function).__name__}")
        old = self.factories.get(kind)
        if old is not None and _where(self._function(old)) != _where(function):  # the same place: a module reloaded
            where = _where(self._function(old))
            raise ValueError(f"{self.role} kind {kind!r} is already registered ({where[0]}.{where[1]})")
        self.factories[kind] = factory

    def unregister(self, kind: str) -> None:
        if kind in self.shipped:
            raise ValueError(f"{kind!r} is a shipped {self.role} kind")
        self.factories.pop(kind, None)

    def kinds(self) -> tuple[str, ...]:
        return tuple(self.factories)

    def get(self, kind: str, name: str) -> F:
        """The factory of ``kind`` (from the name ``name``), or a ``ValueError`` listing the kinds. A kind not
        registered yet first imports the extension modules (``$OGM_PPL_METHODS`` and the entry points,
        :func:`ogm_ppl.extensions.load_extensions`), where it may be registered."""
        if kind not in self.factories:
            load_extensions()
        if kind not in self.factories:
            where = f" in {name!r}" if name != kind else ""
            raise ValueError(
                f"unknown {self.role} kind {kind!r}{where}; kinds: {', '.join(self.kinds())} (a kind "
                "registered in a module of your own: import it first, or name the module in $OGM_PPL_METHODS for "
                "the command line and dask workers)"
            )
        return self.factories[kind]
