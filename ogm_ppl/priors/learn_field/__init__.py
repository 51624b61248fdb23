r"""Learning a pattern field (:class:`~ogm_ppl.priors.PatternFieldPrior`) from training maps, in torch.

The field ``log p~(m) = sum_windows theta[code]`` (``+ sum_pooled windows theta2[code]``) is fitted in
stages (Felzenszwalb & Oberlin 2014 fit by contrastive divergence; here pseudo-likelihood starts it; the
shipped fits use stages 1, 3 and 4 below):

1. **Maximum pseudo-likelihood** (Besag):
   ``max_theta  1/N sum_k log p(m_k | m_-k; theta) - lambda_/2 |theta|^2``, the sum over every cell whose
   ``(2w - 1)^2`` neighbourhood (at two scales also its pooled parent's ``(2w - 1)^2`` pooled neighbourhood)
   lies inside the grid and in known cells. The conditional depends on the data only through that
   neighbourhood, so the objective is a weighted sum over the *distinct* neighbourhood codes
   (:class:`FieldStats`): exact, and cheap enough for LBFGS. ``theta`` is tied over the 8 symmetries (one
   parameter per orbit, :func:`~ogm_ppl.priors.pattern_field.symmetry_orbits`); the L2 penalty also fixes
   the gauge (adding a constant to every ``theta`` leaves the conditionals unchanged).
2. **Persistent contrastive divergence** (MCMC maximum likelihood, Tieleman 2008): per iteration,
   ``grad = f_data - f_model - lambda_ theta``, where ``f`` are per-window orbit frequencies (scale 2: per
   pooled window) of the training data (windows wholly in known cells) and of persistent prior-only Gibbs
   chains (``chains x size x size`` maps, ``sweeps`` compiled sweeps per iteration,
   :func:`~ogm_ppl.priors.compiled.prior_gibbs_sweeps`); Adam steps.

The chains start from crops of the training maps (:func:`data_crops`; from noise a strongly coupled field
freezes in noise-like states), and run ``burn_in`` sweeps under the PL solution first. Stopping point: every
``eval_every`` iterations the *held-out frequency gap* ``|f_val - f_model|_1`` (summed over the scales) of
the persistent chains; the iterate with the smallest gap is returned. :func:`fit_mle` is the same
stochastic approximation with a Robbins-Monro step, a Fisher-preconditioned gradient and Polyak averaging,
checked by fresh chains from both phases.

**Why the shipped fields are tempered PL fields.** Rasterised plans are nearly deterministic at the scale of
a window (validation PLL about -0.001 nats per cell): the PL field is *ordered*. The compiled sampler keeps
the all-free map free and the all-occupied one occupied (:func:`sampler_check`), and noise freezes into
stripes and specks, since with the penalty centred at 0 every pattern the plans never showed scores about
the same, so nothing pulls a map back to plan-like patterns. PCD cannot repair this: its chains never
cross between the phases, so the negative phase is a start-dependent mixture and the steps oscillate.
Two changes fix the prior:

3. **Backoff centre.** The penalty is ``lambda_/2 |theta - theta0|^2`` with ``theta0`` the
   :func:`backoff_potentials` of a ``2 x 2`` field fitted by PL first: unseen ``3 x 3`` patterns score as the
   smaller, smoother field scores them (a restoring force; noise now coarsens to plan-like textures).
4. **Tempering** (:func:`fit_tempered`): the tempered family ``beta theta`` has a sharp transition between
   a disordered phase and the two ordered ones; the chosen ``beta`` is the largest whose chains from the
   all-free and the all-occupied map agree, closest to the validation maps' window frequencies, with a
   unary bias (:func:`unary_orbits`) that gives the prior samples the training maps' occupied share.
   :func:`fit_pattern_field` is this recipe.

The parts: ``_stats`` (window and neighbourhood statistics of maps), ``_pl`` (stage 1 and the back-off
centre), ``_mcmc`` (stage 2 and :func:`fit_mle`), ``_check`` (the fitted field and the sampler check) and
``_temper`` (stage 4 and the recipe).
"""

from ogm_ppl.priors.learn_field._check import FieldFit, sampler_check
from ogm_ppl.priors.learn_field._mcmc import fit_mle, fit_pcd
from ogm_ppl.priors.learn_field._pl import backoff_potentials, fit_pl, validation_pll
from ogm_ppl.priors.learn_field._stats import FieldStats, data_crops, field_stats
from ogm_ppl.priors.learn_field._temper import fit_pattern_field, fit_tempered, unary_orbits

__all__ = [
    "FieldFit",
    "FieldStats",
    "data_crops",
    "backoff_potentials",
    "field_stats",
    "sampler_check",
    "fit_pattern_field",
    "fit_pl",
    "fit_mle",
    "fit_pcd",
    "fit_tempered",
    "unary_orbits",
    "validation_pll",
]
