"""The amortised guide against Gibbs with the same prior and against p21 OGM.

A thin front of :func:`ogm_ppl.studies.amortised_guide_eval.guide_eval` (the held-out maps, the reference and
the convergence measures are described in :mod:`ogm_ppl.studies.amortised_guide_eval`).

    python experiments/amortised_guide_eval.py            # ~8 min on 2 cores; writes out/amortised/
    python experiments/amortised_guide_eval.py --maps-a 1 --maps-b 1 --ref-sweeps 300 --chains 2 --sweeps 30
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import fields
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.io import atomic_write_text
from ogm_ppl.studies.amortised_guide_eval import (
    GuideEvalSettings,
    GuideEvalSettingsError,
    guide_eval,
    markdown,
)


def main(argv=None) -> None:
    d = GuideEvalSettings()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for f in fields(GuideEvalSettings):  # one option per setting, with its default
        flag, default = "--" + f.name.replace("_", "-"), getattr(d, f.name)
        if f.name == "block":
            ap.add_argument(flag, type=int, nargs=2, default=default)
        else:
            ap.add_argument(flag, type=type(default), default=default)
    ap.add_argument("--out", default="out/amortised")
    args = ap.parse_args(argv)
    try:
        settings = GuideEvalSettings(**{f.name: getattr(args, f.name) for f in fields(GuideEvalSettings)})
    except GuideEvalSettingsError as e:
        ap.error(f"--{e.option.replace('_', '-')}: {e.reason}")
    torch.set_num_threads(1)
    r = guide_eval(settings)
    out = Path(args.out)
    record = {"settings": vars(args), "trained_for": r.trained_for, "summary": r.summary, "per_map": r.per_map}
    atomic_write_text(out / "results.json", json.dumps({**record, "seconds": r.seconds}, indent=1) + "\n")
    md = markdown(r.summary, settings, r.trained_for)
    atomic_write_text(out / "results.md", md)
    print(md)
    print(f"{r.seconds:.0f} s; wrote {out}/results.json and results.md")


if __name__ == "__main__":
    main()
