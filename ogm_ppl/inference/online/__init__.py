r"""Online correlated mapping: scans added to a model and to a running single-cell Gibbs chain without a
rebuild (the online version asked for in the thesis's future work, Section 7.2: "focusing the map updates
to areas with new measurements"; the sampler is the single-cell Gibbs of Section 4.1, Eq. 4.2).

**What grows, and what it costs.** :meth:`OnlineMap.add_scans` ray-casts only the new scans, computes the
likelihood rows ``log p(z_r | f)`` of the new rays only (the code of
:class:`~ogm_ppl.models.occupancy.OccupancyModel` on the new rays alone: the rows agree with those of a model
built from scratch to within 2 ulp, as torch's vectorised and scalar loops may round the last bit apart),
appends them to a ray index held with spare capacity (:mod:`~ogm_ppl.inference._kernels.online`: rays in
CSR form, a ragged likelihood table of ``nnz + R`` floats, the transposed cell -> (ray, kappa) index in a
pool of per-cell blocks), and updates the chain's state for the new rays only: their first and second hits
``f_r, s_r`` at the current map, and their terms in the kept sums ``d_k`` of the cells they reach. The
ray-side arrays double when full (amortised ``O(1)`` a ray-cell entry); the cell pool doubles and compacts.
**Memory bound:** with ``nnz`` ray-cell entries, ``R`` rays and ``K`` cells, the ray side holds at most
``2 nnz`` cells (int64), ``2 (nnz + R)`` table entries (float64) and ``2 R`` offsets and hit records, and
the cell pool at most ``2 (2 nnz + 4 K)`` (ray, kappa) pairs of int32, so the online arrays take at most
``64 nnz + 64 R + 105 K`` bytes (:meth:`OnlineMap.stats` reports them). The offline model of the same
scans holds its CSR and transposed index (``24 nnz``) and a dense table of ``8 R (max len + 1)`` bytes.

**Fixed-point scale.** The kept sums are integers in units of ``2^-S``
(:mod:`~ogm_ppl.inference._kernels.cell_sweep`). Offline, ``S`` comes from the largest ``|log p|`` and the
most rays through a cell (:func:`~ogm_ppl.inference._kernels.cell_sweep.fixed_point_bits`); online both grow.
``OnlineMap`` keeps *caps* ``n_cap >= max_k n_k`` (starting at ``initial_rays_per_cell``) and ``b_cap >=
max |ll|`` (starting at twice the first scans' largest entry), and uses ``S = min(60, floor(62 -
log2(n_cap (2 b_cap + 1) + 1)))``, the offline rule at the caps, so no sum can overflow while the caps
hold. When new rays exceed a cap it is doubled; if ``S`` then drops, every ``d_k`` is recomputed from the
hits at the new ``S`` (exact, ``O(nnz)``; at most ``log2`` of the growth of the caps times over a run).
The state then equals, bit for bit, the from-scratch state (:func:`~ogm_ppl.inference._kernels.cell_sweep.cell_state`)
of the same map, rays and table at ``bits = OnlineMap.bits``; against the table of a model rebuilt from
scratch the sums were equal too in every test (a last-bit difference of an entry changes its fixed-point
value only if it lies within an ulp of a rounding boundary).

**Focused sweeps and the schedule.** After adding scans, ``sweeps`` (default ``sweeps_per_scan``) sweeps
run; sweep number ``t`` (counted from 1 over the chain's life) is a *full* sweep over every latent cell of
the grid when ``full_every > 0`` and ``t % full_every == 0``, and otherwise a *focused* sweep over the
latent cells of the focus region: the cells where the rays of the latest ``add_scans`` end (their
readings' cells in the grid) and the new rays' current first and second hits (an occupied cell in front of
a reading is what the reading contradicts; for a ray without a hit, its last cell), dilated by ``margin``
cells (Chebyshev). The free cells along the new rays between the sensor and the reading get strong
free evidence and are left to the full sweeps. Every cell is thus visited at least once every
``full_every`` sweeps. Each sweep is a systematic pass of heat-bath (or metropolised)
single-cell updates of the posterior given *all* scans so far, so each leaves that posterior invariant
(a focused sweep is the ``region=`` kernel of :class:`~ogm_ppl.inference.mcmc.CellGibbs` on the focus
cells); the full sweeps make the chain irreducible over the whole map. Cells whose pose the new scans
hold become pinned free (as ``known_free="sensor"`` of the offline model) and are set to 0 with the state
kept in step.

Random numbers: sweep ``t`` draws its uniforms from the SplitMix64 stream seeded by a hash of ``(seed,
t)`` (:func:`~ogm_ppl.inference._kernels.cell_sweep.draws`), so a chain is reproducible from its seed.
Priors: any prior with a compiled face (``prior.compiled()``: independent cells, MRF / stencil priors,
pattern fields), through the compiled single-cell sweep. A tile-table prior is accepted with a
:class:`TilePriorWarning`: single-cell moves under it are exact but leave the chain all but frozen, and such
priors are mapped with patch Gibbs instead (:class:`~ogm_ppl.exploration.active.RebuildMapper`).

The online *predictive* map, :class:`OnlineGuideMap` (``_guide``), keeps the amortised guide's map instead of a
chain: each scan adds its terms to the guide's per-cell sums and recomputes only the cells whose receptive field
its changed cells reach, equal to the guide's map of every scan so far to float32 rounding
(:func:`replay_guide` replays a log into one).

The parts: ``_map`` (the map and its chain), ``_store`` (the growing ray store and the fixed-point caps),
``_checks`` (the options and scans a map refuses), ``_replay`` (a log replayed scan by scan) and ``_guide``
(the online guide map).
"""

from ogm_ppl.inference.online._checks import TilePriorWarning
from ogm_ppl.inference.online._guide import GuideReplay, OnlineGuideMap, replay_guide
from ogm_ppl.inference.online._map import OnlineMap, OnlineStats
from ogm_ppl.inference.online._replay import Replay, replay

__all__ = [
    "GuideReplay",
    "OnlineGuideMap",
    "OnlineMap",
    "OnlineStats",
    "Replay",
    "TilePriorWarning",
    "replay",
    "replay_guide",
]
