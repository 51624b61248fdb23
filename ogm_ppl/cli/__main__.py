"""``python -m ogm_ppl.cli``: the ``ogm-ppl`` command, as ``python -m ogm_ppl``."""

from ogm_ppl.cli import main

raise SystemExit(main())
