"""Studies: the computations behind the thesis's tables and the library's own studies, as functions.

Each module here is one study: it takes its settings as arguments, returns rows (plain dicts or dataclasses)
and writes nothing unless given an output folder. ``ogm-ppl study NAME [options]`` runs each from the command
line (its options defined in :mod:`ogm_ppl.cli._studies`; ``ogm-ppl study --help`` lists the studies), and the
scripts of the repository's ``experiments/`` call that same code, so a study runs from an installed wheel exactly
as from a checkout.
"""
