"""Compiled (numba) kernels shared by the inference roles: cell likelihood ratios and first hits, Gibbs
and patch sweeps, patch-map passes and log-odds accumulation. Internal: the public entry points are the
role packages beside this one."""

import warnings

from numba.core.errors import NumbaIRAssumptionWarning

# numba's own pedantic IR check fires on the inlined overloads of the patch sweeps (a variable "not in scope"
# after inlining) while it compiles them, asking users to report it to numba; the compiled code is not affected
# (every sweep is checked against exact posteriors in the tests), so the message is kept out of users' logs.
warnings.filterwarnings("ignore", category=NumbaIRAssumptionWarning)
