"""``ogm-ppl methods [NAME]``: the registered map methods with their parameters, and the prior and sensor kinds."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ogm_ppl.methods import (
    ParamError,
    get_method,
    methods,
)

if TYPE_CHECKING:
    pass
from ogm_ppl.cli._common import (
    CLIError,
)
from ogm_ppl.cli.map import CLI_LAMBDA, CLI_SWEEPS


def add_parser(sub) -> None:
    """The ``methods`` subcommand's options."""
    ms = sub.add_parser(
        "methods",
        help="list the map methods and their parameters",
        description="List the registered map methods (ogm_ppl.methods): name, one line, and each parameter "
        "with its default, kind and meaning; then the prior and sensor kinds the parameters prior and sensor "
        "take (shipped and registered).",
    )
    ms.add_argument("name", nargs="?", metavar="NAME", help="show this method only")


def cmd_methods(args) -> str:
    """``ogm-ppl methods [NAME]``: each method's name, one line and parameters (default, kind, meaning)."""
    cli_defaults = (
        f"ogm-ppl map's own defaults, where a method has the parameter: sweeps = {CLI_SWEEPS}, burn_in = sweeps // "
        f"10, lam = {CLI_LAMBDA} (prior independent); specs and the Python API use the defaults listed"
    )
    if args.name is not None:
        try:
            m = get_method(args.name)
        except ParamError as e:
            raise CLIError(f"argument NAME: {e.message}") from None
        shared = {"sweeps", "burn_in", "lam"} & set(m.param_names())
        return "\n".join([*m.describe(), *(["", cli_defaults] if shared else [])])
    from ogm_ppl.priors import prior_kinds
    from ogm_ppl.sensors import sensor_kinds

    lines = []
    for m in methods():
        lines += [f"{m.name}: {m.doc}"] if m.alias_of else m.describe()
    lines += [
        "",
        f"prior kinds (parameter prior, KIND[:CORPUS][@BETA|@cal]): {', '.join(prior_kinds())}",
        f"sensor kinds (parameter sensor): {', '.join(sensor_kinds())}",
        cli_defaults,
    ]
    return "\n".join(lines)


def run(args) -> int:
    """``ogm-ppl methods``: the listing."""
    print(cmd_methods(args))
    return 0
