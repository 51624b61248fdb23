"""The core modules that ``tools/mutate.py`` mutates, each with the test files that exercise it."""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class Module:
    path: str
    tests: tuple[str, ...]
    #: random sites (one mutant each) per run, unless ``--per-module`` says otherwise
    sites: int = 24
    #: tests slower than this in the baseline are left out (the long MCMC tests of the Gibbs kernels)
    max_test_s: float = 1e9


_GIBBS_TESTS = (
    "tests/inference/mcmc/test_gibbs.py",
    "tests/inference/mcmc/test_gibbs_priors.py",
    "tests/inference/mcmc/test_metropolis_cell.py",
    "tests/inference/mcmc/test_patch_python_sweep.py",
    "tests/inference/mcmc/test_resume_rng.py",
)

#: core module -> the test files that exercise it (read from their imports and call chains); a listed
#: file that does not exist yet is ignored
MODULES: dict[str, Module] = {
    "sensors": Module(
        "ogm_ppl/sensors.py",
        ("tests/test_sensors.py", "tests/test_sensor_contracts.py", "tests/test_range_convention.py"),
    ),
    "raycast": Module(
        "ogm_ppl/raycast.py",
        ("tests/test_raycast.py", "tests/test_range_convention.py"),
    ),
    "raycast_kernels": Module(
        "ogm_ppl/_raycast_kernels.py",
        ("tests/test_raycast.py", "tests/test_range_convention.py", "tests/inference/log_odds/test_log_odds.py"),
    ),
    "log_odds": Module(
        "ogm_ppl/inference/log_odds/maps.py",
        ("tests/inference/log_odds/test_log_odds.py",),
        sites=12,
    ),
    "log_odds_kernels": Module(
        "ogm_ppl/inference/_kernels/log_odds.py",
        ("tests/inference/log_odds/test_log_odds.py",),
        sites=12,
    ),
    "exact": Module(
        "ogm_ppl/inference/exact/posteriors.py",
        (
            "tests/inference/exact/test_exact.py",
            "tests/inference/exact/test_exact_input_checks.py",
            "tests/inference/exact/test_pose_constrained_evidence.py",
            "tests/test_posterior.py",
        ),
        sites=12,
        max_test_s=5,
    ),
    "posterior": Module(
        "ogm_ppl/posterior.py",
        ("tests/inference/exact/test_exact.py", "tests/test_posterior.py"),
        sites=12,
        max_test_s=5,
    ),
    "metrics": Module("ogm_ppl/metrics.py", ("tests/test_metrics.py",), sites=16),
    "cells_kernels": Module(
        "ogm_ppl/inference/_kernels/cells.py",
        ("tests/inference/exact/test_map_estimate.py", "tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=6,
        max_test_s=5,
    ),
    "patch_state_kernels": Module(
        "ogm_ppl/inference/_kernels/patch_state.py",
        ("tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=1,
        max_test_s=5,
    ),
    "patch_rays_kernels": Module(
        "ogm_ppl/inference/_kernels/patch_rays.py",
        ("tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=2,
        max_test_s=5,
    ),
    "patch_lik_kernels": Module(
        "ogm_ppl/inference/_kernels/patch_lik.py",
        ("tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=2,
        max_test_s=5,
    ),
    "additive_sweep_kernels": Module(
        "ogm_ppl/inference/_kernels/additive_sweep.py",
        ("tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=1,
        max_test_s=5,
    ),
    "candidate_sweep_kernels": Module(
        "ogm_ppl/inference/_kernels/candidate_sweep.py",
        ("tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=2,
        max_test_s=5,
    ),
    "patch_sweep_kernels": Module(
        "ogm_ppl/inference/_kernels/patch_sweep.py",
        ("tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=1,
        max_test_s=5,
    ),
    "patches_kernels": Module(
        "ogm_ppl/inference/_kernels/patches.py",
        ("tests/inference/patch_map/test_patch_map.py", "tests/inference/patch_map/test_patch_map_weights.py"),
        sites=6,
        max_test_s=5,
    ),
    "runner": Module(
        "ogm_ppl/inference/mcmc/runner.py",
        ("tests/inference/mcmc/test_checkpoint.py", "tests/inference/mcmc/test_running_stats.py", *_GIBBS_TESTS),
        sites=8,
        max_test_s=5,
    ),
}
