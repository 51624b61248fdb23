"""Contract checks every input kind must pass (:mod:`ogm_ppl.inputs`), as a pytest mixin::

    class TestCsvScans(InputKindContract):
        kind = "csv"                                  # its registered name

        def make_input(self, folder):                 # a small input of the kind under ``folder``
            path = folder / "scans.csv"
            path.write_text("0,0,0,1.0,2.0,1.5,3.0\\n0.5,0,0,1.2,2.1,1.4,2.9\\n")
            return path, {"max_range": 5.0}           # the path (None for a kind that reads no file), options

and gets:

* **registration**: the name resolves to its :class:`~ogm_ppl.inputs.InputKind`; every option is a
  :func:`~ogm_ppl.options.param` field with a kind and a doc, and :meth:`~ogm_ppl.inputs.InputKind.describe`
  lists them; an unknown key is refused naming it, and so is a value of the wrong type for *every* option
  (:class:`~ogm_ppl.options.ParamError` when the options are read, never a ``TypeError`` in the reader later);
* **told apart**: a kind that reads a file and declares ``detect`` claims the input, and
  :func:`~ogm_ppl.inputs.detect_input_kind` names the kind for it;
* **read**: :func:`~ogm_ppl.inputs.read_input` returns :class:`~ogm_ppl.inputs.InputData` of the kind: scans
  (at least one, with a valid reading), a grid or ``None``, a truth of the grid's shape (bool) or ``None``,
  JSON-able settings, and a JSON-able resume key naming the kind and every option;
* **reproducible**: reading twice gives the same scans, bit for bit, and the same resume key;
* **resume key**: it changes when an option changes (:attr:`InputKindContract.other_options`) and, for a kind
  that reads a file, when the file changes (its modification time).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

__all__ = ["InputKindContract"]


class InputKindContract:
    """Pytest mixin: an input kind's contract (module docstring). Set :attr:`kind` and write
    :meth:`make_input`; optionally :attr:`other_options`."""

    #: the registered name
    kind: str = ""
    #: option values over :meth:`make_input`'s that read the same input another way (the resume key must
    #: differ); ``None``: not checked
    other_options: ClassVar[dict[str, Any] | None] = None

    def make_input(self, folder: Path) -> tuple[Path | None, dict[str, Any]]:
        """A small input of the kind under ``folder``: its path (``None`` for a kind that reads no file) and
        the option values to read it with."""
        raise NotImplementedError("write make_input(folder) -> (path or None, options)")

    def _kind(self):
        from ogm_ppl.inputs import get_input_kind

        return get_input_kind(self.kind)

    def test_registration_and_options(self):
        from ogm_ppl.inputs import InputKind
        from ogm_ppl.options import Kind, ParamError, param_fields

        k = self._kind()
        assert isinstance(k, InputKind) and k.name == self.kind and k.doc and k.noun
        fields = param_fields(k.options)
        lines = k.describe()
        for name, kind, _, doc in fields:
            assert isinstance(kind, Kind) and doc, f"{self.kind}.{name}: give a kind and a doc"
            assert any(line.strip().startswith(f"{name} = ") for line in lines[1:]), name
        try:
            k.parse({"no_such_option_": 1})
        except ParamError as e:
            assert e.key == "no_such_option_" and "unknown key" in e.message
        else:
            raise AssertionError("an unknown option was accepted")
        for name, *_ in fields:
            try:
                k.parse({name: object()})
            except ParamError as e:
                assert e.key == name, f"{name}: the error names {e.key!r}"
            else:
                raise AssertionError(f"option {name!r} accepted a value of no type it takes")

    def test_told_apart(self, tmp_path):
        from ogm_ppl.inputs import detect_input_kind

        k = self._kind()
        path, _ = self._make(tmp_path)
        assert (path is None) == (not k.reads_file), "a kind that reads a file makes a path, and only it"
        if path is None or k.detect is None:
            return
        head = b"" if Path(path).is_dir() else Path(path).read_bytes()[:16]
        assert k.detect(Path(path), head), f"{self.kind}'s detect does not claim its own input"
        assert detect_input_kind(path) == self.kind

    def _make(self, folder: Path) -> tuple[Path | None, dict[str, Any]]:
        folder.mkdir(parents=True, exist_ok=True)
        return self.make_input(folder)

    def test_read(self, tmp_path):
        from ogm_ppl.grid import Grid
        from ogm_ppl.inputs import InputData, read_input
        from ogm_ppl.options import param_fields
        from ogm_ppl.scans import Scans

        path, options = self._make(tmp_path)
        data = read_input(self.kind, path, options)
        assert isinstance(data, InputData) and data.kind == self.kind
        assert data.path == (None if path is None else Path(path))
        assert isinstance(data.scans, Scans) and data.scans.num_scans >= 1 and data.scans.num_valid >= 1
        assert data.grid is None or isinstance(data.grid, Grid)
        if data.truth is not None:
            assert data.grid is not None and data.truth.shape == data.grid.shape and data.truth.dtype == bool
        json.dumps(data.settings)
        key = data.resume_key
        assert json.loads(json.dumps(key)) == key, "the resume key must be JSON"
        assert key["kind"] == self.kind
        assert set(key["options"]) == {name for name, *_ in param_fields(self._kind().options)}

    def test_reproducible(self, tmp_path):
        from ogm_ppl.inputs import read_input

        path, options = self._make(tmp_path)
        a, b = read_input(self.kind, path, options), read_input(self.kind, path, options)
        for field in ("poses", "angles", "ranges", "valid", "is_max"):
            np.testing.assert_array_equal(getattr(a.scans, field), getattr(b.scans, field), err_msg=field)
        assert a.resume_key == b.resume_key

    def test_resume_key_follows_the_input(self, tmp_path):
        from ogm_ppl.inputs import read_input

        path, options = self._make(tmp_path)
        key = read_input(self.kind, path, options).resume_key
        if self.other_options is not None:
            other = read_input(self.kind, path, {**options, **self.other_options}).resume_key
            assert other != key, "options that read the input otherwise keep its resume key"
        if path is not None:
            files = [Path(path)] if Path(path).is_file() else [p for p in Path(path).rglob("*") if p.is_file()]
            for f in files:
                st = f.stat()
                os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
            assert read_input(self.kind, path, options).resume_key != key, "a changed file keeps its resume key"
