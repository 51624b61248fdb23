"""``python -m ogm_ppl``: the ``ogm-ppl`` command (:mod:`ogm_ppl.cli`)."""

from ogm_ppl.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
