"""The results of ``tools/mutate.py``: the equivalent mutants listed with their reasons, each planned
mutant's latest result, and ``report.md`` / ``summary.json`` / ``survivors/*.diff``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from mutate_common import (
    ANNOTATION,
    ANNOTATION_REASON,
    ERROR,
    INCOMPETENT,
    KILLED,
    ROOT,
    SURVIVED,
    TIMEOUT,
    atomic_write_text,
)


def load_equivalents() -> list[dict]:
    p = ROOT / "tools" / "mutate_equivalents.toml"
    if not p.exists():
        return []
    return tomllib.loads(p.read_text()).get("equivalent", [])


def equivalent_reason(r: dict, equivalents: list[dict]) -> str | None:
    for e in equivalents:
        if e["module"] == r["module"] and e["line"] == r["original"] and e["mutant"] == r["mutated"]:
            return e["reason"]
    return None


def current_results(results: dict[str, dict], plan) -> dict[str, dict]:
    """For each planned mutant its latest result (a survivor retested under new tests supersedes the
    old result)."""
    cur = {}
    for _name, _m, _src, _tests, _fp, muts, _n in plan:
        for mu in muts:
            cands = [r for r in results.values() if r["id"].startswith(mu.key + ":")]
            if cands:
                cur[mu.key] = cands[-1]
    return cur


def write_report(out: Path, results: dict[str, dict], equivalents: list[dict], plan) -> None:
    """``report.md``, ``summary.json`` and ``survivors/*.diff`` for the planned mutants' results."""
    surv_dir = out / "survivors"
    if surv_dir.exists():
        shutil.rmtree(surv_dir)
    surv_dir.mkdir(parents=True)
    summary: dict[str, dict] = {}
    rows, surv_md, eq_md = [], [], []
    counted = (KILLED, TIMEOUT, ERROR, SURVIVED, "equivalent")
    for name, m, _src, tests, _fp, muts, n_all in plan:
        rs = sorted((r for r in results.values() if r["module"] == name), key=lambda r: (r["line"], r["operator"]))
        if not rs:
            continue
        c = {k: 0 for k in (*counted, INCOMPETENT)}
        for i, r in enumerate(rs):
            outcome = r["outcome"]
            reason = equivalent_reason(r, equivalents) if outcome == SURVIVED else None
            if outcome == ANNOTATION:
                reason = ANNOTATION_REASON
            if reason:
                outcome = "equivalent"
            c[outcome] += 1
            if r["outcome"] not in (SURVIVED, ANNOTATION):
                continue
            fn = f"{name}-L{r['line']}-{r['operator'].split('/')[-1]}-{i}.diff"
            atomic_write_text(surv_dir / fn, r.get("diff", ""))
            item = (
                f"* `{name}` line {r['line']}, {r['operator'].split('/')[-1]}: "
                f"`{r['original']}` -> `{r['mutated']}` ([diff](survivors/{fn}))"
            )
            (eq_md.append(f"{item}\n  {reason}") if reason else surv_md.append(item))
        det = c[KILLED] + c[TIMEOUT] + c[ERROR]
        denom = det + c[SURVIVED]
        summary[name] = {
            "path": m.path,
            "population": n_all,
            "sampled": len(muts),
            "run": len(rs),
            **c,
            "kill_ratio": round(det / denom, 4) if denom else None,
            "tests": tests,
        }
        ratio = f"{det / denom:.0%}" if denom else "-"
        rows.append(
            f"| {name} | {n_all} | {len(rs)} | {c[KILLED]} | {c[TIMEOUT]} | {c[ERROR]} | "
            f"{c[SURVIVED]} | {c['equivalent']} | {c[INCOMPETENT]} | {ratio} |"
        )
    tot = {k: sum(v[k] for v in summary.values()) for k in ("population", "run", *counted, INCOMPETENT)}
    det = tot[KILLED] + tot[TIMEOUT] + tot[ERROR]
    denom = det + tot[SURVIVED]
    summary["total"] = {**tot, "kill_ratio": round(det / denom, 4) if denom else None}
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    md = [
        "# Mutation testing (`make mutate`, tools/mutate.py)",
        "",
        "cosmic-ray mutants of the core modules, a random sample of code sites per module (one "
        "operator variant each), each run against the tests that cover its module. *Detected* = killed "
        "(a test failed) + timeout + error (the mutant breaks import or collection). *Equivalent*: a "
        "survivor listed with its reason in `tools/mutate_equivalents.toml`. *Incompetent*: not valid "
        "Python, not run. Kill ratio = detected / (detected + survived).",
        "",
        "| module | population | run | killed | timeout | error | survived | equivalent | incompetent | kill ratio |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *rows,
        f"| **total** | {tot['population']} | {tot['run']} | {tot[KILLED]} | {tot[TIMEOUT]} | "
        f"{tot[ERROR]} | {tot[SURVIVED]} | {tot['equivalent']} | {tot[INCOMPETENT]} | "
        f"{f'{det / denom:.0%}' if denom else '-'} |",
        "",
        "## Survivors",
        "",
        *(surv_md or ["none"]),
        "",
        "## Equivalent survivors",
        "",
        *(eq_md or ["none"]),
        "",
    ]
    atomic_write_text(out / "report.md", "\n".join(md))
