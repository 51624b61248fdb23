r"""The input of a mapping run, one way in: a table of input kinds, each with its options declared once.

The command line (``ogm-ppl map``, ``convert``, ``info``) and experiment specs (``[[datasets]] kind = ...``) read
their inputs here, and nothing else decides how an input is told apart, which options it takes, how they are
checked, how it is read and what identifies it. The library ships four kinds (:data:`SHIPPED_INPUT_KINDS`):

=============  ======================================================================  ==============================
kind           reads                                                                   told apart by
=============  ======================================================================  ==============================
``log``        a CARMEN log, plain or gzip (:func:`~ogm_ppl.datasets.read_carmen`)     anything no other kind claims
``bag``        a ROS 1 bag, a ROS 2 bag folder or its ``.db3`` / ``.mcap``             magic bytes (``bag_kind``)
               (:func:`~ogm_ppl.datasets.read_bag`): a LaserScan topic and its
               poses from a pose topic or ``/tf``
``npz``        an ogm_ppl dataset file (:func:`~ogm_ppl.datasets.load_dataset`):       a zip archive's magic bytes
               scans, and its grid and truth
``simulated``  no file: a stop-and-scan dataset on a generated map or a floor          (named only)
               plan of one's own (:mod:`~ogm_ppl.inputs.simulated`)
=============  ======================================================================  ==============================

**Options.** A kind's options are a frozen dataclass of :func:`ogm_ppl.options.param` fields (name, kind,
default, doc), the same option system as a map method's parameters, and one check serves every surface: a
spec's ``reader = {messages = 5}`` fails when the spec is read, naming ``reader.messages`` and what it takes,
and the command line's flags are checked by the same fields. ``ogm-ppl methods``-style lines of a kind's
options: :meth:`InputKind.describe`.

**Reading.** :func:`read_input` (``kind`` or ``None`` to tell it apart with :func:`detect_input_kind`, the
path, the options) returns :class:`InputData`: the scans, the input's own grid and truth where it has them,
the reader's settings and record, and its :func:`resume_key`: the kind, what identifies the file as it is now
(:func:`file_identity`: path, size, modification time; a plan's SHA-256 for a simulated scene) and every
option's value. ``ogm-ppl map`` keys its chains' checkpoints with it, an experiment its base tasks: a result
is reused only for the same input read the same way.

>>> from ogm_ppl.inputs import get_input_kind, read_input
>>> get_input_kind("log").parse({"max_usable_range": 20}).max_usable_range
20.0
>>> get_input_kind("log").parse({"messages": 5})  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
ogm_ppl.options.ParamError: messages: must be 'auto', a laser message type (FLASER, ROBOTLASER1) or a ..., got 5

**An input kind of one's own** is an :class:`InputKind` given to :func:`register_input_kind`: its name, its
options dataclass, ``read(path, options) -> InputData``, a one-line doc, the noun messages call one input of
it, and optionally ``detect(path, head) -> bool`` so that the command line tells its files apart by their
first bytes (kinds of one's own are asked before the shipped ones)::

    from dataclasses import dataclass
    import numpy as np
    from ogm_ppl.inputs import InputData, InputKind, register_input_kind
    from ogm_ppl.options import Float, param
    from ogm_ppl.scans import Scans

    @dataclass(frozen=True)
    class CsvOptions:
        max_range: float = param(30.0, Float(0, lo_open=True), "the sensor's maximum range (metres)")

    def read_csv_scans(path, options):
        '''One scan a line: x, y, yaw, then the ranges of beams evenly spread over 360 degrees.'''
        rows = np.loadtxt(path, delimiter=",", ndmin=2)
        angles = np.linspace(-np.pi, np.pi, rows.shape[1] - 3, endpoint=False)
        return InputData("csv", path, Scans(rows[:, :3], angles, rows[:, 3:], options.max_range))

    register_input_kind(InputKind("csv", CsvOptions, read_csv_scans, "scans as CSV lines", noun="CSV scan file",
                                  detect=lambda path, head: path.suffix == ".csv"))

A spec then names it (``kind = "csv"``, its options as the entry's keys and, for options of
``group="reader"``, in its ``reader`` table), and ``ogm-ppl map scans.csv`` reads it with its defaults. As for
the other roles, name the module in ``$OGM_PPL_METHODS`` (or an entry point of the group ``ogm_ppl.methods``)
so that the command line and dask workers find the kind, and test it with
:class:`~ogm_ppl.testing.InputKindContract`.
"""

from ogm_ppl.inputs.files import BagOptions, DatasetFileOptions, LogOptions  # registers log, bag, npz
from ogm_ppl.inputs.kinds import (
    SHIPPED_INPUT_KINDS,
    InputData,
    InputError,
    InputKind,
    check_readable,
    detect_input_kind,
    file_identity,
    get_input_kind,
    image_kind,
    input_kinds,
    read_input,
    register_input_kind,
    resume_key,
    unregister_input_kind,
)
from ogm_ppl.inputs.simulated import SimulatedOptions  # registers simulated

__all__ = [
    "SHIPPED_INPUT_KINDS",
    "BagOptions",
    "DatasetFileOptions",
    "InputData",
    "InputError",
    "InputKind",
    "LogOptions",
    "SimulatedOptions",
    "check_readable",
    "detect_input_kind",
    "file_identity",
    "get_input_kind",
    "image_kind",
    "input_kinds",
    "read_input",
    "register_input_kind",
    "resume_key",
    "unregister_input_kind",
]
