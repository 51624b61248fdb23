"""Compiled (numba) kernels shared by the inference roles: cell likelihood ratios and first hits, Gibbs
and patch sweeps, patch-map passes and log-odds accumulation. Internal: the public entry points are the
role packages beside this one."""
