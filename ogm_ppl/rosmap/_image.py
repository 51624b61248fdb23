"""Map images: binary and ASCII PGM read by a strict reader of their own (any ``maxval``, 16 bits included,
scaled to 8 bits), every other format through Pillow; written as map_saver writes them (binary PGM with its
comment line) or as PNG."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ogm_ppl.rosmap._errors import RosMapError

_MAX_PIXELS = 1 << 28


def _extra_data(n: int, what: str, w: int, h: int) -> str:
    return (
        f"PGM has {n} pixel {what} after the {w} x {h} its header states: the header's size is wrong, or the "
        "file holds several images (a map is one)"
    )


def _read_pnm(data: bytes, path: Path) -> np.ndarray:
    magic = data[:2]
    pos, n = 2, len(data)
    tokens: list[int] = []
    if n < 3 or not (data[2:3].isspace() or data[2] == ord("#")):
        raise RosMapError(path, "PGM bad header (magic number must be followed by whitespace)")
    while len(tokens) < 3:
        while pos < n and (data[pos : pos + 1].isspace() or data[pos] == ord("#")):
            if data[pos] == ord("#"):
                while pos < n and data[pos] not in (10, 13):
                    pos += 1
            else:
                pos += 1
        start = pos
        while pos < n and 48 <= data[pos] <= 57:
            pos += 1
        if pos == start:
            what = "truncated header" if pos >= n else f"bad header byte {data[pos : pos + 1]!r}"
            raise RosMapError(path, f"PGM {what} (expected width, height, maxval)")
        tokens.append(int(data[start:pos]))
        last = len(tokens) == 3
        if pos < n and not data[pos : pos + 1].isspace() and (last or data[pos] != ord("#")):
            raise RosMapError(path, f"PGM bad header byte {data[pos : pos + 1]!r}")
    w, h, maxval = tokens
    if w < 1 or h < 1 or w * h > _MAX_PIXELS:
        raise RosMapError(path, f"PGM size {w} x {h} is not a usable image size")
    if not 1 <= maxval <= 65535:
        raise RosMapError(path, f"PGM maxval {maxval} unsupported (need 1..65535)")
    px: np.ndarray
    if magic == b"P5":
        if pos >= n:
            raise RosMapError(path, "PGM truncated: no pixel data")
        size = w * h * (1 if maxval <= 255 else 2)  # 16-bit samples: two bytes each, most significant first
        raw = data[pos + 1 : pos + 1 + size]
        if len(raw) < size:
            raise RosMapError(path, f"PGM truncated: {len(raw)} of {size} pixel bytes")
        extra = data[pos + 1 + size :]
        if extra.strip():
            raise RosMapError(path, _extra_data(len(extra), "bytes", w, h))
        px = np.frombuffer(raw, dtype=np.uint8 if maxval <= 255 else ">u2").reshape(h, w).astype(np.int64)
    else:  # P2, ASCII
        body = data[pos:].split()
        if len(body) < w * h:
            raise RosMapError(path, f"PGM truncated: {len(body)} of {w * h} pixel values")
        if len(body) > w * h:
            raise RosMapError(path, _extra_data(len(body) - w * h, "values", w, h))
        try:
            px = np.array([int(t) for t in body[: w * h]], dtype=np.int64).reshape(h, w)
        except ValueError:
            raise RosMapError(path, "PGM pixel data are not integers") from None
    if px.max(initial=0) > maxval or px.min(initial=0) < 0:
        raise RosMapError(path, f"PGM pixel value above maxval {maxval}")
    if maxval != 255:
        px = (px.astype(np.int64) * 255 + maxval // 2) // maxval
    return px.astype(np.uint8)


def _read_image(path: Path) -> tuple[np.ndarray, bytes]:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise RosMapError(path, "image file not found") from None
    except OSError as e:
        raise RosMapError(path, f"cannot read image file ({e.strerror or e})") from None
    if data[:2] in (b"P5", b"P2"):
        return _read_pnm(data, path), data
    if data[:1] == b"P" and data[1:2] in b"1346":
        raise RosMapError(path, f"PNM type {data[:2].decode()} unsupported (use P5 / P2 greyscale)")
    try:
        from PIL import Image

        im: Image.Image  # convert() below returns a plain Image
        with Image.open(io.BytesIO(data)) as im:
            if im.size[0] * im.size[1] > _MAX_PIXELS:
                raise RosMapError(path, f"image size {im.size} too large")
            im.load()
            if im.mode == "P":
                im = im.convert("RGBA" if "transparency" in im.info else "RGB")
            elif im.mode == "1":
                im = im.convert("L")
            if im.mode not in ("L", "LA", "RGB", "RGBA"):
                raise RosMapError(path, f"image mode {im.mode} unsupported (8-bit grey or colour)")
            px = np.asarray(im, dtype=np.uint8).copy()
    except RosMapError:
        raise
    except Exception as e:  # Pillow raises many types on corrupt files
        why = "unrecognised format" if type(e).__name__ == "UnidentifiedImageError" else f"{type(e).__name__}: {e}"
        raise RosMapError(path, f"not a readable image ({why})") from None
    return px, data


def _encode_image(img: np.ndarray, image_format: str, resolution: float, alpha: np.ndarray | None = None) -> bytes:
    """The file bytes of a map image ``img`` (``H x W`` uint8, row 0 at the top): a binary 8-bit PGM with
    map_saver's comment line (``"pgm"``), or a PNG (``"png"``: grey, or grey + ``alpha`` when given)."""
    if image_format == "pgm":
        h, w = img.shape
        header = f"P5\n# CREATOR: ogm_ppl.rosmap {resolution:.3f} m/pix\n{w} {h}\n255\n"
        return header.encode("ascii") + np.ascontiguousarray(img).tobytes()
    from PIL import Image

    buf = io.BytesIO()
    if alpha is not None:
        Image.fromarray(np.ascontiguousarray(np.stack([img, alpha], -1))).save(buf, "PNG")  # LA
    else:
        Image.fromarray(np.ascontiguousarray(img)).save(buf, "PNG")  # L
    return buf.getvalue()
