"""Studies: the computations behind the thesis's tables and the library's own studies, as functions.

Each module here is one study: it takes its settings as arguments, returns rows (plain dicts or dataclasses)
and writes nothing unless given an output folder. The scripts of ``experiments/`` are thin command lines over
these functions, so a study runs from an installed wheel exactly as from a checkout.
"""
