"""Factories registered by name: the one mechanism behind prior kinds and sensor kinds."""

from __future__ import annotations

from collections.abc import Callable
from typing import Generic, TypeVar

from ogm_ppl.extensions import load_extensions

F = TypeVar("F", bound=Callable)

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
    """Kinds of one role (``"prior"``, ``"sensor"``) and their factories.

    ``shipped`` kinds cannot be unregistered. A kind is a non-empty name without ``:``; registering a name
    another factory took is refused; a factory defined at the same place (module, qualified name, and a
    lambda's line: a module reloaded, a notebook cell run again) replaces the old one.
    """

    def __init__(self, role: str, shipped: tuple[str, ...]) -> None:
        self.role = role
        self.shipped = shipped
        self.factories: dict[str, F] = {}

    def check_kind(self, kind: str) -> None:
        """Refuse a kind that is not a non-empty name without ``:`` (``ValueError``)."""
        if not isinstance(kind, str) or not kind or ":" in kind:
            raise ValueError(f"a {self.role} kind is a non-empty name without ':', got {kind!r}")

    def register(self, kind: str, factory: F) -> None:
        self.check_kind(kind)
        if not callable(factory):
            raise TypeError(f"the factory of {self.role} kind {kind!r} must be callable, got {type(factory).__name__}")
        old = self.factories.get(kind)
        if old is not None and _where(old) != _where(factory):  # the same place again: a module reloaded
            raise ValueError(f"{self.role} kind {kind!r} is already registered ({_where(old)[0]}.{_where(old)[1]})")
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
