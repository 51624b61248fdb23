r"""Maps for robot stacks: ROS ``map_server`` / Nav2 ``map_server`` image + YAML files.

A map is a pair of files (the format of the ROS wiki page *"map_server - ROS Wiki"*, section 1
"Map format", and the Nav2 page *"Map Server / Saver"*): an 8-bit image and a YAML file naming it (a PGM
of another ``maxval``, 16-bit included, is read scaled to 8 bits).
:func:`save_ros_map` writes exactly these YAML fields, in this order and with these types::

    image: map.pgm                  # str: image file name, relative to the YAML file
    mode: trinary                   # str: "trinary" or "scale"
    resolution: 0.05                # float: metres per pixel
    origin: [-1.5, 2.25, 0.0]       # list of 3 floats: (x, y, yaw) of the lower-left pixel's corner
    negate: 0                       # int: 0 or 1
    occupied_thresh: 0.65           # float
    free_thresh: 0.196              # float

Floats are written with Python's shortest round-trip ``repr`` and always contain a ``.`` (``1.0e-05``,
not ``1e-05``), so YAML 1.1 readers (PyYAML) and YAML 1.2 readers (yaml-cpp, used by map_server) both
read them as floats. ``yaw`` is always 0 (an ogm_ppl :class:`~ogm_ppl.grid.Grid` is axis-aligned).

**Pixel -> probability** (what map_server computes, ``x`` the pixel's grey value, the mean of its colour
channels):

.. math::

    p = \begin{cases} (255 - x) / 255 & \text{negate} = 0 \\ x / 255 & \text{negate} = 1 \end{cases}

*trinary*: ``p > occupied_thresh -> 100``, else ``p < free_thresh -> 0``, else ``-1`` (unknown).
*scale*: the same two ends; an image with alpha marks transparent pixels ``-1``; in between the value
is linear in ``p``: Nav2 ``rint(100 r)``, ROS 1 ``int(1 + 98 r)``, with
``r = (p - free_thresh) / (occupied_thresh - free_thresh)``.

**Probability -> pixel** (what we write, before ``negate``; ``negate = 1`` writes ``255 - x``):
*trinary*, as ``map_saver`` writes: ``p > occupied_thresh -> 0`` (black), ``p < free_thresh -> 254``,
else and for unknown cells ``205`` (grey); *scale*: ``x = floor(255 (1 - p) + 1/2)`` for known cells.

Unknown cells, and two traps in the conventions:

* ``thresholds="nav2"`` (free 0.25): Nav2's own map_saver writes unknown as 205 with free_thresh 0.25, and
  205 reads back as ``p = 50/255 = 0.196 < 0.25``, i.e. **free**. By default we therefore write unknown
  cells as the grey in the middle of the unknown band whenever 205 would not read back as unknown
  (140 for ``"nav2"``; 205 for ``"ros1"``). ``unknown_value=205`` forces the map_saver byte (with a
  warning).
* *scale* mode: map_server reads ``-1`` only from an alpha channel, which PGM does not have. A PGM in
  scale mode stores unknown cells as 205 (trinary-compatible, what map_saver writes) and map_server reads
  them as nearly free (0 or 1); a warning says so. Use ``image_format="png"``: we then write grey + alpha
  with unknown cells transparent and, as in trinary, grey inside the unknown band (ROS 1 looks at alpha
  only after the thresholds), which both map_servers read as ``-1``.

The reading side follows the loaders themselves where the wiki is vague: ``map_server/src/image_loader.cpp``
(ROS 1 noetic, ``ros-planning/navigation``) and ``nav2_map_server/src/map_io.cpp`` (``ros-navigation/
navigation2``): strict inequalities, alpha averaged into the grey in trinary mode, ROS 1's ``1 + 98 r``
truncated to an integer and Nav2's ``rint(100 r)`` in scale mode.

Rows: image row 0 is the top of the map (largest ``y``); our cell ``(row, col)`` is image pixel
``(rows - 1 - row, col)`` and OccupancyGrid index ``row * cols + col`` (== our flat cell index).

Next to the two files a *sidecar* ``<stem>.npz`` (``allow_pickle=False``, format version 1) keeps the
float probabilities, the unknown mask, the grid and a SHA-256 of the image (zip-compressed), so that
:func:`load_ros_map` can return the exact probabilities (a stale sidecar is ignored with a warning).
All files are written atomically (:func:`ogm_ppl.io.atomic_write_bytes`); the YAML is written last.

>>> import numpy as np, tempfile, pathlib
>>> from ogm_ppl.grid import Grid
>>> g = Grid((2, 3), resolution=0.5, origin=(-1.0, 2.0))
>>> p = np.array([0.9, 0.1, 0.5, 0.1, 0.1, 0.1])
>>> with tempfile.TemporaryDirectory() as d:
...     files = save_ros_map(pathlib.Path(d) / "map.yaml", p, g)
...     m = load_ros_map(files.yaml)
>>> m.occupancy.tolist()
[100, 0, -1, 0, 0, 0]
>>> m.grid == g
True
"""

from ogm_ppl.rosmap._errors import RosMapError
from ogm_ppl.rosmap._files import RosMap, RosMapFiles, load_ros_map, save_ros_map
from ogm_ppl.rosmap._occupancy import THRESHOLDS, from_occupancy_grid, to_occupancy_grid
from ogm_ppl.rosmap._sidecar import FORMAT_VERSION as FORMAT_VERSION
from ogm_ppl.rosmap._yaml import RosMapSettings, read_ros_map_yaml

__all__ = [
    "RosMapError",
    "RosMapSettings",
    "RosMapFiles",
    "RosMap",
    "THRESHOLDS",
    "save_ros_map",
    "load_ros_map",
    "read_ros_map_yaml",
    "to_occupancy_grid",
    "from_occupancy_grid",
]
