"""The error of the map_server readers: :class:`RosMapError`, naming the file."""

from __future__ import annotations

import os


class RosMapError(ValueError):
    """A map file (YAML, image or sidecar) is missing, malformed or inconsistent; names the path."""

    def __init__(self, path: str | os.PathLike, problem: str):
        self.path, self.problem = str(path), problem
        super().__init__(f"{path}: {problem}")
