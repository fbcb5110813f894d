"""The explorer's state as ROS 2 messages (frames and units: ``docs/robot.md``).

Fields over the grid arrive flat in the scenario's cell order (row-major over (ix, iy(, iz))),
with NaN where a value is unknown. On a surface of cells they become ``nav_msgs/OccupancyGrid``
(``data[iy * width + ix]``, 0..100, -1 unknown, the grid's corner at the frame's origin); in a
volume, ``sensor_msgs/PointCloud2`` of the cells whose value is known (x, y, z at the cells'
centres, ``intensity`` on the same 0..100 scale).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, PointStamped, PoseStamped
from nav_msgs.msg import OccupancyGrid, Path
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray


def header(frame: str, stamp: Time) -> Header:
    return Header(frame_id=frame, stamp=stamp)


def percent(values: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """``values`` [cells] in [0, scale] as integer percent 0..100 (rounded), -1 where NaN."""
    values = np.asarray(values, float)
    known = np.isfinite(values)
    out = np.full(values.shape, -1, dtype=np.int8)
    if scale > 0:
        out[known] = np.clip(np.rint(values[known] / scale * 100), 0, 100).astype(np.int8)
    else:
        out[known] = 0
    return out


def occupancy_grid(values: np.ndarray, shape: Sequence[int], cell: float, head: Header
                   ) -> OccupancyGrid:
    """A field ``values`` [nx * ny] (0..100 or -1, flat over (ix, iy)) as an occupancy grid."""
    nx, ny = shape
    msg = OccupancyGrid(header=head)
    msg.info.map_load_time = head.stamp
    msg.info.resolution = float(cell)
    msg.info.width, msg.info.height = int(nx), int(ny)
    msg.info.origin.orientation.w = 1.0
    # (ix, iy) row-major -> row iy, column ix
    msg.data = np.asarray(values, np.int8).reshape(nx, ny).T.ravel()
    return msg


def point_cloud(values: np.ndarray, centres: np.ndarray, head: Header) -> PointCloud2:
    """A field ``values`` [cells] (0..100, -1 unknown) at ``centres`` [cells, 3] (metres) as a
    cloud of its known cells (x, y, z, intensity, float32)."""
    known = np.asarray(values) >= 0
    points = np.empty((int(known.sum()), 4), np.float32)
    points[:, :3] = centres[known]
    points[:, 3] = np.asarray(values)[known]
    fields = [PointField(name=name, offset=4 * i, datatype=PointField.FLOAT32, count=1)
              for i, name in enumerate(("x", "y", "z", "intensity"))]
    return PointCloud2(header=head, height=1, width=len(points), fields=fields,
                       is_bigendian=False, point_step=16, row_step=16 * len(points),
                       data=points.tobytes(), is_dense=True)


def field(values: np.ndarray, shape: Sequence[int], cell: float, centres: np.ndarray,
          head: Header) -> OccupancyGrid | PointCloud2:
    """A field (0..100, -1 unknown) as a grid on a surface of cells, a cloud in a volume."""
    if len(shape) == 2:
        return occupancy_grid(values, shape, cell, head)
    return point_cloud(values, centres, head)


def point(centre: np.ndarray) -> Point:
    c = [float(x) for x in centre] + [0.0] * (3 - len(centre))
    return Point(x=c[0], y=c[1], z=c[2])


def point_stamped(centre: np.ndarray, head: Header) -> PointStamped:
    return PointStamped(header=head, point=point(centre))


def pose(centre: np.ndarray, head: Header) -> PoseStamped:
    msg = PoseStamped(header=head)
    msg.pose.position = point(centre)
    msg.pose.orientation.w = 1.0
    return msg


class GrowingPath:
    """A path that grows by one pose per step, kept serialized (CDR) so that publishing it
    costs the same at the thousandth step as at the first: rclpy converts a message's poses
    one by one at every publication (2 ms for 1,000 poses), while each pose's bytes here are
    made once, when it is added.

    The bytes are those rclpy makes of the whole message: poses follow the header and the
    sequence's length, each beginning where the one before ends (8-aligned, after its
    doubles); only the first one's alignment depends on the header, so it is cut from a
    one-pose path serialized whole.
    """

    def __init__(self) -> None:
        self.poses: list[bytes] = []

    def __len__(self) -> int:
        return len(self.poses)

    def clear(self) -> None:
        self.poses.clear()

    def append(self, centre: np.ndarray, head: Header) -> None:
        from rclpy.serialization import serialize_message

        if self.poses:
            self.poses.append(serialize_message(pose(centre, head))[4:])  # after its encoding
        else:
            whole = serialize_message(Path(header=head, poses=[pose(centre, head)]))
            self.poses.append(whole[len(serialize_message(Path(header=head))):])

    def serialized(self, head: Header) -> bytes:
        """The whole path, stamped ``head``, as the bytes of a ``nav_msgs/Path``."""
        from rclpy.serialization import serialize_message

        empty = serialize_message(Path(header=head))  # ... its last four bytes: the length 0
        return empty[:-4] + len(self.poses).to_bytes(4, "little") + b"".join(self.poses)


def clear_markers(head: Header) -> MarkerArray:
    return MarkerArray(markers=[Marker(header=head, action=Marker.DELETEALL)])


def shape_markers(points: np.ndarray, name: str, probability: float, cell: float,
                  head: Header, closed: bool) -> MarkerArray:
    """The registered template ``points`` [V, dims] (metres): its outline as a line strip
    (``closed``: back to its first vertex) on a surface, its surface points in a volume; and
    its name and probability as a label above its first point."""
    colour = ColorRGBA(r=0.1, g=0.8, b=1.0, a=1.0)
    if closed:
        outline = Marker(header=head, ns="shape", id=0, type=Marker.LINE_STRIP,
                         action=Marker.ADD, color=colour)
        outline.points = [point(p) for p in np.vstack([points, points[:1]])]
        outline.scale.x = cell / 4  # the line's width
    else:
        outline = Marker(header=head, ns="shape", id=0, type=Marker.POINTS, action=Marker.ADD,
                         color=colour)
        outline.points = [point(p) for p in points]
        outline.scale.x = outline.scale.y = cell / 4
    outline.pose.orientation.w = 1.0
    label = Marker(header=head, ns="shape", id=1, type=Marker.TEXT_VIEW_FACING,
                   action=Marker.ADD, color=colour, text=f"{name} {probability:.2f}")
    label.pose.position = point(points[0])
    label.pose.position.z += cell
    label.pose.orientation.w = 1.0
    label.scale.z = 2 * cell  # the text's height
    return MarkerArray(markers=[outline, label])
