"""A prior in one file, as a user would write it: a checkerboard stencil registered by name on import
(tests import it; ``OGM_PPL_METHODS=tests.priors.toy_checkerboard`` makes the command line import it)."""

from ogm_ppl.priors import StencilPrior, register_prior

KIND = "toy_checker"


class CheckerboardPrior(StencilPrior):
    r"""Neighbours prefer to differ: ``l(m_k | m_-k) = beta (n_0 - n_1)`` over the 4-neighbourhood (the
    MRF of Section 5.2.1 with ``log psi = -beta``), so the two checkerboards are the modes."""

    def __init__(self, shape, beta: float = 1.0) -> None:
        offsets = [(0, 1), (1, 0)] if len(getattr(shape, "shape", shape)) == 2 else [1]
        super().__init__(shape, unary=0.0, offsets=offsets, coupling=-2.0 * beta, bias=beta)


register_prior(KIND, lambda shape, tables: CheckerboardPrior(shape))
