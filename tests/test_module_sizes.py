"""Every module of the library and of its tools, benchmarks, experiments and docs extension is small: at most
:data:`MAX_LINES` lines, so that each keeps one clear job (a longer one is split by job, as ``tools/mutate*.py``
and ``tools/docs_tables_*.py`` are)."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MAX_LINES = 700
FOLDERS = ("ogm_ppl", "tools", "benchmarks", "experiments", "docs/_ext")


def _lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def oversized(root: Path = ROOT, folders: tuple[str, ...] = FOLDERS, limit: int = MAX_LINES) -> dict[str, int]:
    """``{path relative to root: lines}`` of the ``.py`` files under ``folders`` longer than ``limit`` lines."""
    out = {}
    for folder in folders:
        for p in sorted((root / folder).rglob("*.py")):
            if ".venv" not in p.parts and (n := _lines(p)) > limit:
                out[str(p.relative_to(root))] = n
    return out


def test_no_module_is_over_the_limit():
    assert oversized() == {}


@pytest.mark.parametrize("extra, expected", [(MAX_LINES, {}), (MAX_LINES + 1, {"pkg/big.py": MAX_LINES + 1})])
def test_the_check_finds_a_long_module(tmp_path, extra, expected):
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "big.py").write_text("x = 1\n" * extra)
    (tmp_path / "pkg" / "small.py").write_text("x = 1\n")
    assert oversized(tmp_path, ("pkg",)) == expected
