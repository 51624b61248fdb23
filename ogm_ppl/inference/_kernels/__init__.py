"""Compiled (numba) kernels shared by the inference roles: cell likelihood ratios and first hits, Gibbs
and patch sweeps, patch-map passes and log-odds accumulation. Internal: the public entry points are the
role packages beside this one."""

import warnings

from numba.core.errors import NumbaIRAssumptionWarning


def quiet_numba_ir_check() -> None:
    """Filter numba's own pedantic IR check, which fires on the inlined overloads of the patch sweeps (a
    variable "not in scope" after inlining) while it compiles them and asks users to report it to numba. The
    compiled code is not affected (every sweep is checked against exact posteriors in the tests), so the message
    is kept out of users' logs. Called on import, and again by code that resets the warning filters."""
    warnings.filterwarnings("ignore", category=NumbaIRAssumptionWarning)


quiet_numba_ir_check()
