r"""Guide artefacts: the file format of a saved amortised guide, its writer, and the validating reader
of untrusted files.

An artefact is a plain ``.npz`` (no pickle): the fields ``kind``, ``format``, ``feature_version`` (of
:func:`~ogm_ppl.inference.variational.amortised_features.evidence_features`), the architecture
(``channels``, ``dilations``, ``phase``, ``delta``), ``meta`` (the JSON record of what the guide was trained
for) and one float32 array ``param/<name>`` per weight of the
:class:`~ogm_ppl.inference.variational.amortised_net.GuideNet`. :func:`read_guide_file` validates every field
(types, ranges, the weight names and shapes the architecture implies, finite values) and raises
:class:`GuideFileError` naming the path and what is wrong.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from ogm_ppl.inference.variational.amortised_features import FEATURE_VERSION
from ogm_ppl.inference.variational.amortised_net import GuideArchitecture, GuideNet, _architecture_problems
from ogm_ppl.io import atomic_write, read_npz

__all__ = ["FORMAT", "GuideFileError", "read_guide_file", "write_guide_file"]

#: artefact format (bumped when the file layout changes)
FORMAT = 1
_KIND = "ogm_ppl.amortised_guide"


class GuideFileError(ValueError):
    """A guide artefact that cannot be loaded (the message names the path and what is wrong), or a corpus
    with no shipped guide (:func:`~ogm_ppl.inference.variational.corpus_guides.corpus_guide`)."""


def write_guide_file(path: Path, arch: GuideArchitecture, weights: dict[str, torch.Tensor], meta: dict) -> Path:
    """Write an artefact: the architecture, ``meta`` (JSON-able) as text and the network's ``weights`` (its
    ``state_dict``) as float32 arrays, to ``path`` (``.npz``, no pickle). Atomic."""
    if path.suffix != ".npz":
        raise ValueError(f"{path}: a guide artefact is an .npz file")
    a = arch
    payload = {
        "kind": np.array(_KIND),
        "format": np.array(FORMAT, dtype=np.int64),
        "feature_version": np.array(FEATURE_VERSION, dtype=np.int64),
        "channels": np.array(a.channels, dtype=np.int64),
        "dilations": np.array(a.dilations, dtype=np.int64),
        "phase": np.array(a.phase, dtype=np.int64),
        "delta": np.array(a.delta),
        "meta": np.array(json.dumps(meta, sort_keys=True)),
    }
    for k, v in weights.items():
        payload[f"param/{k}"] = v.detach().cpu().to(torch.float32).numpy()
    with atomic_write(path) as f:
        np.savez_compressed(f, **payload)  # type: ignore[arg-type]  # numpy stub: **arrays could fill allow_pickle
    return path


def read_guide_file(path: Path) -> tuple[GuideArchitecture, dict[str, torch.Tensor], dict]:
    """The architecture, weights and ``meta`` record of an artefact written by :func:`write_guide_file`
    (validated; :class:`GuideFileError` names the path and the problem)."""
    what = "a guide written by AmortisedGuide.save (ogm_ppl.learn.train_prior_guide, ogm-ppl train-guide)"
    hint = f"expected {what}"
    arrays = read_npz(path, what, GuideFileError)
    fields = ("kind", "format", "feature_version", "channels", "dilations", "phase", "delta", "meta")
    missing = [k for k in fields if k not in arrays]
    if missing:
        raise GuideFileError(f"{path}: missing {', '.join(missing)}; {hint}")

    def text(key: str) -> str:
        a = arrays[key]
        if a.dtype.kind != "U" or a.ndim != 0:
            raise GuideFileError(f"{path}: field {key!r} must be a text scalar, got {a.dtype} of shape {a.shape}")
        return str(a)

    def ints(key: str, ndim: int) -> np.ndarray:
        a = arrays[key]
        if a.dtype.kind not in "iu" or a.ndim != ndim:
            raise GuideFileError(
                f"{path}: field {key!r} must be an integer array of {ndim} dimensions, got {a.dtype} of shape {a.shape}"
            )
        return a

    if text("kind") != _KIND:
        raise GuideFileError(f"{path}: kind {text('kind')!r}, not {_KIND!r}; {hint}")
    if int(ints("format", 0)) != FORMAT:
        raise GuideFileError(f"{path}: artefact format {int(arrays['format'])}, this version reads {FORMAT}")
    if int(ints("feature_version", 0)) != FEATURE_VERSION:
        raise GuideFileError(
            f"{path}: feature set version {int(arrays['feature_version'])}, this version "
            f"computes {FEATURE_VERSION}: the weights would read other inputs"
        )
    channels = int(ints("channels", 0))
    dilations = tuple(int(d) for d in ints("dilations", 1))
    ph = ints("phase", 1)
    if ph.shape != (2,):
        raise GuideFileError(f"{path}: field 'phase' must hold 2 integers, got {ph.shape[0]}")
    phase = (int(ph[0]), int(ph[1]))
    delta = text("delta")
    problems = _architecture_problems(channels, dilations, phase, delta)
    if problems:
        raise GuideFileError(f"{path}: {problems}")
    arch = GuideArchitecture(channels, dilations, phase, delta)
    try:
        meta = json.loads(text("meta"))
    except json.JSONDecodeError as e:
        raise GuideFileError(f"{path}: field 'meta' is not JSON ({e.msg})") from None
    if not isinstance(meta, dict):
        raise GuideFileError(f"{path}: field 'meta' must be a JSON object")
    expected = {k: tuple(v.shape) for k, v in GuideNet(arch).state_dict().items()}
    got = {k[len("param/") :]: a for k, a in arrays.items() if k.startswith("param/")}
    extra = sorted(set(arrays) - set(fields) - {f"param/{k}" for k in expected})
    if extra:
        raise GuideFileError(f"{path}: unexpected entries {extra} for this architecture")
    absent = sorted(set(expected) - set(got))
    if absent:
        raise GuideFileError(f"{path}: weights {absent} missing for this architecture")
    state = {}
    for k, shape in expected.items():
        a = got[k]
        if a.dtype != np.float32:
            raise GuideFileError(f"{path}: weight {k!r} must be float32, got {a.dtype}")
        if tuple(a.shape) != shape:
            raise GuideFileError(f"{path}: weight {k!r} has shape {tuple(a.shape)}, the architecture needs {shape}")
        if not np.isfinite(a).all():
            raise GuideFileError(f"{path}: weight {k!r} holds a non-finite value")
        state[k] = torch.from_numpy(a.copy())
    return arch, state, meta
