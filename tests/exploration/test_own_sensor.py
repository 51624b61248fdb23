"""A sensor of one's own explores once it has a compiled face: a Laplace range sensor registers a reading kind
(:mod:`ogm_ppl.sensors_compiled`), passes the sensor contract (its compiled reading model against its
``log_prob`` included), and ``beam_information`` / ``scan_information`` give the exact mutual information of
an enumerable problem under it."""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np
import pytest
import torch

from ogm_ppl.exploration import beam_information, candidate_rays, independent_information, scan_information
from ogm_ppl.inference.exact import brute_force
from ogm_ppl.sensors import GaussianRange, SensorModel
from ogm_ppl.sensors_compiled import register
from ogm_ppl.testing import SensorContract
from ogm_ppl.testing.kernels import enumerable_2d, enumerate_maps


# ------------------------------------------------------------------ the sensor and its compiled face
class LaplaceReading(NamedTuple):
    scale: float
    width: float


@nb.njit(inline="always")
def _cdf(x, f, b):
    if x < f:
        return 0.5 * math.exp((x - f) / b)
    return 1.0 - 0.5 * math.exp(-(x - f) / b)


@nb.njit(inline="always")
def laplace_num_outcomes(reading, F):
    return math.ceil((F + 1.0) / reading.width - 1e-12)


@nb.njit(inline="always")
def laplace_bin_prob(reading, j, J, f, none, F):
    if none:
        return 1.0 if j == J else 0.0
    b, w = reading.scale, reading.width
    if j == J:
        return 0.5 * math.exp(-(F + 0.5 - f) / b)
    lo = 0.0 if j == 0 else _cdf(-0.5 + j * w, f, b)
    hi = _cdf(F + 0.5 if j == J - 1 else -0.5 + (j + 1) * w, f, b)
    return hi - lo


@nb.njit(inline="always")
def laplace_log_reading(reading, binned, y, jb, is_max, J, f, none, F):
    if binned or is_max:
        v = laplace_bin_prob(reading, J if is_max else jb, J, f, none, F)
        return math.log(v) if v > 0.0 else -math.inf
    if none:
        return -math.inf
    return -abs(y - f) / reading.scale - math.log(2.0 * reading.scale)


@nb.njit(inline="always")
def laplace_coord(reading, t_enter, off, kap):
    return t_enter[off + kap] + 0.5


@nb.njit(inline="always")
def laplace_draw(reading, J, f, none, F, u_a, u_b, e):
    if none:
        return 0.0, True, J
    u = max(u_b, 1e-300)
    y = f + reading.scale * math.log(2.0 * u) if u < 0.5 else f - reading.scale * math.log(2.0 * (1.0 - u))
    if y > F + 0.5:
        return y, True, J
    return y, False, min(max(math.floor((y + 0.5) / reading.width), 0), J - 1)


register(
    LaplaceReading,
    num_outcomes=laplace_num_outcomes,
    bin_prob=laplace_bin_prob,
    log_reading=laplace_log_reading,
    coord=laplace_coord,
    draw=laplace_draw,
    continuous=True,
)


class LaplaceRange(SensorModel):
    """``p(z | f) = exp(-|z - f| / b) / 2b`` for ``z <= F + 1/2``, max range beyond (and with nothing on the ray)."""

    continuous_range = True

    def __init__(self, scale: float) -> None:
        self.scale = float(scale)

    def log_prob(self, z, f, F, is_max=None):
        z = torch.as_tensor(z, dtype=torch.float64)
        f = torch.as_tensor(f, dtype=torch.float64)
        F = torch.as_tensor(F, dtype=torch.float64)
        none = f > F + 0.5
        f_safe = torch.where(none, F, f)
        hit = -(z - f_safe).abs() / self.scale - math.log(2.0 * self.scale)
        hit = torch.where(none | (z > F + 0.5), -math.inf, hit)
        mx = torch.where(none, 0.0, math.log(0.5) - (F + 0.5 - f_safe) / self.scale)
        if is_max is None:
            return hit
        return torch.where(torch.as_tensor(is_max, dtype=torch.bool), mx, hit)

    def sample(self, f, F, generator=None):
        f = torch.as_tensor(f, dtype=torch.float64)
        F = torch.as_tensor(F, dtype=torch.float64).expand_as(f)
        u = torch.rand(f.shape, generator=generator, dtype=torch.float64).clamp(min=1e-300)
        y = torch.where(u < 0.5, f + self.scale * torch.log(2 * u), f - self.scale * torch.log(2 * (1 - u)))
        is_max = (f > F + 0.5) | (y > F + 0.5)
        return torch.where(is_max, F + 1.0, y), is_max

    def compiled(self, bin_width=None):
        return LaplaceReading(scale=self.scale, width=1.0 if bin_width is None else float(bin_width))


class TestLaplaceRange(SensorContract):
    def make_sensor(self):
        return LaplaceRange(0.8)


# ------------------------------------------------------------------ it explores
POSES = np.array([[2.5, 0.5, 0.0], [1.5, 1.5, -0.3]])
ANGLES = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2, math.pi / 4])


@pytest.fixture(scope="module")
def problem():
    model = enumerable_2d()
    maps = enumerate_maps(model)
    pi = brute_force(model).log_probs.exp().double()
    cr = candidate_rays(model.grid, POSES, ANGLES, 3.0)
    return model, maps, pi, cr


def _rows(scale: float, f: float | None, F: float, w: float) -> torch.Tensor:
    """The Laplace outcome probabilities by the CDF in torch (bins of ``w`` cells, then max range)."""
    J = math.ceil((F + 1) / w - 1e-12)
    if f is None:
        return torch.cat([torch.zeros(J, dtype=torch.float64), torch.ones(1, dtype=torch.float64)])
    e = torch.tensor([-0.5 + j * w for j in range(J + 1)], dtype=torch.float64)
    e[J] = F + 0.5
    d = (e - f) / scale
    cdf = torch.where(d < 0, 0.5 * torch.exp(d), 1 - 0.5 * torch.exp(-d))
    cdf[0] = 0.0
    return torch.cat([cdf[1:] - cdf[:-1], (1 - cdf[J])[None]])


def _exact_mi_bits(model, maps, pi, cr, c, b, scale, w):
    """``I(m; z_b)`` by enumerating the maps (first hits found by walking the ray), the candidate's cell free."""
    keep = maps[:, int(cr.pose_cells[c])] == 0
    p = torch.where(keep, pi, 0.0)
    p = p / p.sum()
    r = c * cr.num_beams + b
    cells = cr.ray(c, b)
    t = cr.t_enter[cr.offsets[r] : cr.offsets[r + 1]].astype(np.float64)
    rows = []
    for m in maps:
        hits = [k for k in range(1, len(cells)) if m[cells[k]] == 1]
        rows.append(_rows(scale, float(t[hits[0]]) + 0.5 if hits else None, cr.max_range_cells, w))
    R = torch.stack(rows)
    q = p @ R
    ok = R > 0
    terms = torch.where(ok, R * torch.log(torch.where(ok, R, 1.0) / q), 0.0)
    return float((p[:, None] * terms).sum()) / math.log(2.0)


@pytest.mark.parametrize("w", [1.0, 0.4])
def test_own_sensor_beam_information_is_the_exact_mi(problem, w):
    model, maps, pi, cr = problem
    sensor = LaplaceRange(0.6)
    got = beam_information(model.grid, sensor, maps.to(torch.uint8), cr, weights=pi, bin_width=w)
    for c in range(len(POSES)):
        for b in range(len(ANGLES)):
            exact = _exact_mi_bits(model, maps, pi, cr, c, b, 0.6, w)
            assert abs(float(got[c, b]) - exact) < 1e-10, (c, b, float(got[c, b]), exact)
    assert (got > 1e-3).any()
    ind = independent_information(model.grid, sensor, (pi[:, None] * maps).sum(0), cr, bin_width=w)
    assert ind.shape == got.shape and torch.isfinite(ind).all() and (ind >= 0).all()


def test_own_sensor_scan_information_agrees_with_the_beams(problem):
    """One beam per candidate: the binned whole-scan estimate is an unbiased estimate of the beam's MI."""
    model, maps, pi, _ = problem
    sensor = LaplaceRange(0.6)
    for angle in (0.0, math.pi / 4):
        cr = candidate_rays(model.grid, POSES, [angle], 3.0)
        beam = beam_information(model.grid, sensor, maps.to(torch.uint8), cr, weights=pi, bin_width=0.5)[:, 0]
        g = torch.Generator().manual_seed(3)
        scan = scan_information(model.grid, sensor, maps.to(torch.uint8), cr, 3000, g, weights=pi, bin_width=0.5)
        assert ((scan.mean - beam).abs() <= 4.5 * scan.stderr + 1e-9).all(), (scan.mean, scan.stderr, beam)
        dens = scan_information(model.grid, sensor, maps.to(torch.uint8), cr, 200, g, weights=pi)
        assert torch.isfinite(dens.mean).all() and (dens.mean <= math.log2(len(maps)) + 1e-9).all()


def test_a_sensor_without_a_compiled_face_does_not_explore(problem):
    model, maps, _, cr = problem

    class Plain(LaplaceRange):
        def compiled(self, bin_width=None):
            return None

    class Unregistered(NamedTuple):
        scale: float

    class Foreign(LaplaceRange):
        def compiled(self, bin_width=None):
            return Unregistered(self.scale)

    samples = maps.to(torch.uint8)
    with pytest.raises(TypeError, match=r"no compiled reading model for Plain: .*compiled\(bin_width\)"):
        beam_information(model.grid, Plain(0.5), samples, cr)
    with pytest.raises(TypeError, match="no compiled reading kind is registered for Unregistered"):
        scan_information(model.grid, Foreign(0.5), samples, cr, 4)
    with pytest.raises(TypeError, match=r"SensorModel\.compiled"):
        independent_information(model.grid, SensorModel(), torch.full((model.grid.num_cells,), 0.5), cr)


def test_a_reading_kind_of_ones_own_stays_out_of_the_disk_cache(problem):
    """Numba's on-disk cache index pickles the type of every specialisation: a bundle class of a test module or a
    notebook in it made every process that cannot import that module fail to load the kernel (a notebook run after
    this file failed with "No module named 'tests'"). The kernels compile a kind of one's own per process only."""
    from ogm_ppl._numba_cache import cache_index
    from ogm_ppl.exploration.beam_mi import beam_mi_kernel
    from ogm_ppl.exploration.scan_mi import scan_mi_kernel

    model, maps, pi, cr = problem
    sensor = LaplaceRange(0.6)
    beam_information(model.grid, sensor, maps.to(torch.uint8), cr, weights=pi, bin_width=0.5)
    scan_information(model.grid, sensor, maps.to(torch.uint8), cr, 20, torch.Generator().manual_seed(0), weights=pi)
    beam_information(model.grid, GaussianRange(0.6), maps.to(torch.uint8), cr, weights=pi)
    for kernel in (beam_mi_kernel, scan_mi_kernel):
        assert any("LaplaceReading" in str(sig) for sig in kernel.signatures), kernel.signatures  # compiled here
        index = cache_index(kernel)
        assert b"LaplaceReading" not in index and __name__.encode() not in index
    assert b"GaussianReading" in cache_index(beam_mi_kernel)
