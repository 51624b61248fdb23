"""The state a map kernel's chain carries from one sweep to the next, as one declared bundle.

A :class:`~ogm_ppl.inference.mcmc.kernel.MapKernel` owns one :class:`ChainState` (its ``chain``): the current
map, every ray's first hit, the counters and the site value it returned last. The base kernel loads maps into it
(``_load_map``), counts the sweeps (``step`` / ``sample``) and saves and restores it (``state_dict`` /
``load_state_dict``); a subclass's sweep writes the map in place and adds its updates to ``chain.updates``, and a
composite kernel (a cycle, parallel tempering, a guided kernel) drives its parts through their public methods
(``step``, ``set_state``, ``state``, ``updates``), never through their attributes. Like the cache of Pyro's HMC
(``_z_last``), ``last`` lets ``sample(params)`` tell the params it handed out itself from a map given from outside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

__all__ = ["ChainState"]


@dataclass(eq=False)
class ChainState:
    """A map kernel's chain: what a sweep reads and writes, and what a checkpoint saves (module docstring).

    Attributes:
        m: the current full map, a live ``(K,)`` uint8 0/1 array with the pinned cells 0 (``None`` until a map is
            loaded); the sweeps write it in place.
        f: every ray's first occupied kappa (``(R,)``), kept in step with ``m`` by the sweeps; a kernel whose
            compiled state holds the first hits makes ``f`` a view of it. ``None`` for a kernel whose parts sweep
            (a cycle, a guided kernel): its parts keep theirs.
        sweeps: sweeps since the start of the chain.
        changes: updates that changed the map, since the start of the chain.
        updates: updates made (cell or patch updates, proposals) since the start of the chain; a kernel's sweep
            adds its own.
        last: the site value the kernel returned last (``sample`` takes it as the kernel's own and does not reload
            it); ``None`` once the map has changed since.
    """

    m: np.ndarray | None = None
    f: np.ndarray | None = None
    sweeps: int = 0
    changes: int = 0
    updates: int = 0
    last: torch.Tensor | None = None

    @property
    def loaded(self) -> bool:
        """Whether a map has been loaded (``setup``, ``set_state`` or ``load_state_dict``)."""
        return self.m is not None

    def bind(self, m: np.ndarray, f: np.ndarray | None = None) -> None:
        """Make ``m`` (and its first hits ``f``) the current map, owned by the chain from now on; the value
        returned last no longer describes it."""
        self.m, self.f, self.last = m, f, None

    def swept(self, changes: int, sweeps: int = 1) -> None:
        """Count ``sweeps`` sweeps that made ``changes`` changes; the map may have moved, so ``last`` is dropped."""
        self.sweeps += sweeps
        self.changes += changes
        self.last = None

    def restart(self, sweeps: int = 0, changes: int = 0, updates: int = 0) -> None:
        """Set the counters: zero for a new chain, a checkpoint's to continue one."""
        self.sweeps, self.changes, self.updates = sweeps, changes, updates
