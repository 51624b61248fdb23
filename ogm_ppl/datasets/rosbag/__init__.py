r"""Read laser scans and poses from ROS bags (ROS 1 ``.bag``, ROS 2 sqlite3 and MCAP) into
:class:`~ogm_ppl.scans.Scans`, with the conventions of :func:`~ogm_ppl.datasets.carmen.read_carmen`.

The bags are read with the pure-Python ``rosbags`` library (no ROS install). One
``sensor_msgs/LaserScan`` topic gives the scans; the laser's pose at each scan comes from a pose topic
(``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped`` or ``geometry_msgs/PoseWithCovarianceStamped``)
or from the transform tree of ``/tf`` and ``/tf_static``.

**Beams.** Beam ``i`` of a scan of ``n`` beams points at ``angle_min + i * angle_increment`` relative
to the laser's heading (the formula of :func:`~ogm_ppl.datasets.carmen.flaser_angles`). LaserScan
stores its fields as float32; a float32 ``angle_min`` / ``angle_increment`` that is the float32 rounding
of ``p * pi / q`` (``q <= 1440``: 1, 0.5, 0.25, 360/1024 degrees, ...) is read as that float64 value, the
laser's own geometry, and other float32 values (ranges, range limits, other angles) are widened through
their shortest decimal representation (``widen="decimal"``: a driver that wrote 1.23 m stored
float32(1.23), and 1.23 is read back; ``widen="binary"`` keeps the float32 value itself). A log written
with decimals therefore reads back bit for bit.

**No return and out of range** (REP 117 and the CARMEN rule together). A beam is *no-return* when its
range is NaN (invalid measurement), +Inf (nothing within range) or ``>= range_max`` of its message (the
ROBOTLASER1 rule of the CARMEN reader: drivers report misses at or above ``range_max``), or ``>=
no_return_threshold`` when that is given. ``no_return="drop"`` (default, thesis Section 6.2) marks such
beams invalid; ``"max"`` makes them max-range readings. -Inf and ranges below the message's
``range_min`` (or the ``min_range`` option) are *below minimum* and invalid. ``max_usable_range`` drops
or clips every other reading at or beyond it. The ``max_range`` given to :class:`Scans` is
``max_range`` if given, else ``max_usable_range``, else the largest ``range_max`` of the scans.

**Poses.** Stamps are the messages' ``header.stamp`` (nanoseconds). The pose of each scan is interpolated
between the last pose sample at or before its stamp and the first at or after it: linear in position
and along the shortest arc in yaw (for a transform tree, each dynamic link is interpolated, its rotation
by slerp, and the links composed in 3D, as tf2 does; the 2D pose is the laser origin's ``x, y`` in the
map frame and the yaw of its rotation). A scan whose stamp is more than ``pose_tolerance`` seconds from
either bracketing sample (or that lies outside the samples) has no pose; it is dropped and counted
(``counts["no_pose"]``). A pose topic gives the robot's pose; ``laser_offset = (x, y, yaw)`` moves it to
the laser (in the robot frame). With ``tf=True`` the chain ``map_frame -> ... -> laser frame`` (the
scans' ``header.frame_id``) is followed through every link, the static laser mounting included; a laser
mounted upside down (its z axis pointing down) has its beam angles negated.

**Errors.** With ``strict=True`` (default) the first malformed message raises :class:`BagFormatError`
naming the file, the topic, the 0-based message index on that topic and the field. With ``strict=False``
a malformed message is skipped and listed in ``bad_messages``; when the storage itself fails part way
(a truncated or corrupted file), every message read before is kept and ``bad_messages`` says where
reading stopped. A ROS 1 bag without a usable index (a recording cut short, ``.bag.active``) or an MCAP
file without its summary is read record by record in lenient mode, keeping every message before the cut;
strict mode refuses it. Other files that cannot be opened (not a bag, a damaged sqlite3 database,
unreadable metadata) raise in both modes.
"""

from ogm_ppl.datasets.rosbag._errors import BagFormatError
from ogm_ppl.datasets.rosbag._info import bag_info
from ogm_ppl.datasets.rosbag._messages import (
    LASER_SCAN,
    ODOMETRY,
    POSE_COV_STAMPED,
    POSE_STAMPED,
    POSE_TYPES,
    TF_MESSAGE,
)
from ogm_ppl.datasets.rosbag._open import bag_kind, bag_topics
from ogm_ppl.datasets.rosbag._read import BagLog, read_bag
from ogm_ppl.datasets.rosbag._write import STORAGES, typestore, write_bag

__all__ = ["BagFormatError", "BagLog", "bag_info", "bag_kind", "bag_topics", "read_bag", "typestore", "write_bag"]
__all__ += ["LASER_SCAN", "ODOMETRY", "POSE_COV_STAMPED", "POSE_STAMPED", "POSE_TYPES", "STORAGES", "TF_MESSAGE"]
