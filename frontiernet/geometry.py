"""Poses and rotations.

Conventions (docs/design.md): world frame Z-up, metres, radians; camera frame OpenCV
(x right, y down, z forward). ``T_world_cam`` (4, 4) float64 maps camera
coordinates into the world: ``p_world = T_world_cam[:3, :3] @ p_cam + T_world_cam[:3, 3]``.

A *heading pose* ``(x, y, z, yaw, pitch)`` places the camera at ``(x, y, z)`` looking
along yaw (radians, counter-clockwise about +z from +x) and pitch (radians, positive
looks up), with no roll.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import InputError

# Y-up (glTF, HM3D, habitat) to Z-up (ours): a +90 degree rotation about x maps
# +y to +z and +z to -y.
T_ZUP_YUP = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)


def rotation_from_yaw_pitch(yaw: float | np.ndarray, pitch: float | np.ndarray = 0.0) -> np.ndarray:
    """Camera-to-world rotation(s) for a camera with the given yaw and pitch (radians).

    Args:
        yaw: scalar or (N,) heading about world +z, 0 = looking along +x.
        pitch: scalar or (N,), positive tilts the optical axis up.
    Returns:
        (3, 3) or (N, 3, 3) float64 ``R_world_cam`` whose columns are the camera's
        x (right), y (down) and z (forward) axes in world coordinates.
    """
    yaw = np.asarray(yaw, dtype=np.float64)
    pitch = np.broadcast_to(np.asarray(pitch, dtype=np.float64), yaw.shape)
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    forward = np.stack([cp * cy, cp * sy, sp], axis=-1)
    right = np.stack([sy, -cy, np.zeros_like(yaw)], axis=-1)
    down = np.cross(forward, right)
    return np.stack([right, down, forward], axis=-1)


_MATH_ATAN2 = np.frompyfunc(math.atan2, 2, 1)


def atan2(y, x):
    """arctan2(y, x) in radians, rounded the same on every CPU: a float for scalars, else a float64
    array (broadcast).

    numpy runs its float64 arctan2 in SIMD loops chosen for the CPU when it is imported, and its
    AVX-512 loops round otherwise than the others in the last bit. A heading read from a pose so
    differed between machines, and an image method's run from the same start drifted apart
    (docs/benchmark.md, "Both depth regimes"). The C library's atan2 (Python's ``math.atan2``)
    does not depend on the SIMD level; elementwise it costs ~0.1 us a value.
    """
    if np.ndim(y) == 0 and np.ndim(x) == 0:
        return math.atan2(float(y), float(x))
    return _MATH_ATAN2(np.asarray(y, np.float64), np.asarray(x, np.float64)).astype(np.float64)


def pose_from_heading(x: float, y: float, z: float, yaw: float, pitch: float = 0.0) -> np.ndarray:
    """(4, 4) float64 ``T_world_cam`` for a camera at (x, y, z) metres with yaw/pitch radians."""
    T = np.eye(4)
    T[:3, :3] = rotation_from_yaw_pitch(yaw, pitch)
    T[:3, 3] = (x, y, z)
    return T


def poses_from_headings(positions: np.ndarray, yaws: np.ndarray, pitches: np.ndarray | float = 0.0) -> np.ndarray:
    """Batched :func:`pose_from_heading`: (N, 3) positions, (N,) yaws -> (N, 4, 4) ``T_world_cam``."""
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    T = np.tile(np.eye(4), (len(positions), 1, 1))
    T[:, :3, :3] = rotation_from_yaw_pitch(np.asarray(yaws, dtype=np.float64).reshape(-1), pitches)
    T[:, :3, 3] = positions
    return T


MAX_COORDINATE_M = 1e5
"""The farthest a typed position may be from the world origin, per axis (metres): the camera's rays are
float32, whose spacing is ~8 mm at 1e5 m (a tenth of a 0.1 m voxel) and grows with the distance; 1e300
overflowed to inf (RuntimeWarnings, a view with no depth). A building is far smaller."""


def parse_pose_text(text: str, option: str = "--pose", pitch: bool = True) -> tuple[float, ...]:
    """``"x,y,z,yaw[,pitch]"`` as typed on a command line -> (x, y, z, yaw, pitch) floats, with
    angles in radians (pitch 0 when not given), or (x, y, z, yaw) when `pitch` is False.

    Positions are metres in the world frame (Z up). Angles are degrees (``90``, ``90deg``) or
    radians with a ``rad`` suffix (``1.5708rad``); yaw 0 looks along +x and lies within -360 and
    360 degrees, pitch > 0 looks up and must lie strictly between -90 and 90 degrees; a position within
    :data:`MAX_COORDINATE_M` of the origin. Raises :class:`InputError` naming `option` and the bad part.
    """
    form = "x,y,z,yaw[,pitch]" if pitch else "x,y,z,yaw"
    parts = [part.strip() for part in str(text).split(",")]
    if len(parts) not in ((4, 5) if pitch else (4,)):
        raise InputError(f"{option} '{text}': expected {form} (metres; angles in degrees, or radians with 'rad')")
    values = []
    for index, part in enumerate(parts):
        unit = part[-3:].lower() if index >= 3 and part[-3:].lower() in ("deg", "rad") else ""
        try:
            value = float(part[:-3] if unit else part)
        except ValueError:
            raise InputError(f"{option} '{text}': '{part}' is not a number") from None
        if not np.isfinite(value):
            raise InputError(f"{option} '{text}': '{part}' is not finite")
        if index < 3 and abs(value) > MAX_COORDINATE_M:
            raise InputError(f"{option} '{text}': '{part}' m is farther from the world origin than any scene "
                             f"({MAX_COORDINATE_M:.0e} m at most: rays are computed in float32, which keeps about a "
                             "centimetre there)")
        values.append(value if index < 3 or unit == "rad" else float(np.radians(value)))
    if abs(values[3]) > 2 * np.pi + 1e-9:  # (1e30 degrees is a number, but no heading: cos loses every digit)
        raise InputError(f"{option} '{text}': yaw must lie between -360 and 360 degrees")
    if pitch and len(values) == 4:
        values.append(0.0)
    if pitch and abs(values[4]) >= np.pi / 2:
        raise InputError(f"{option} '{text}': pitch must lie strictly between -90 and 90 degrees")
    return tuple(values)


def arc_lengths(points: np.ndarray) -> np.ndarray:
    """(N,) cumulative arc length (metres) along an (N, D) polyline, starting at 0."""
    points = np.asarray(points, np.float64)
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def points_at_arc(points: np.ndarray, arc: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(K, D) points of the (N, D) polyline `points` at arc lengths `s` (K,), given its
    :func:`arc_lengths` `arc` (N,); linear between vertices, clamped at the ends."""
    points = np.asarray(points, np.float64)
    return np.stack([np.interp(s, arc, points[:, i]) for i in range(points.shape[1])], axis=1)


def rotation_angle(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Geodesic angle (radians) between two rotations (3, 3)."""
    cos = (np.trace(np.asarray(R_a).T @ np.asarray(R_b)) - 1.0) / 2.0
    return float(np.arccos(np.clip(cos, -1.0, 1.0)))


def intrinsics_matrix(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """(3, 3) float64 pinhole K from focal lengths and principal point, pixels (OpenCV convention)."""
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], np.float64)


def image_corner_rays(K: np.ndarray, image_shape: tuple[int, int]) -> np.ndarray:
    """(4, 3) float64 camera-frame directions (unit z) through the corner pixel centres of an (H, W)
    image with (3, 3) intrinsics `K`."""
    H, W = image_shape
    u = np.array([0.0, W - 1, 0.0, W - 1])
    v = np.array([0.0, 0.0, H - 1, H - 1])
    return np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones(4)], axis=1)


def quaternion_rotations(quaternions, what: str):
    """scipy ``Rotation`` of (N, 4) or (4,) quaternions (x, y, z, w) of any length; InputError naming `what` for
    one that is not finite or has zero length. Each is scaled by its largest component first: a quaternion of
    1e200 squared overflows to inf, and scipy then finds it of zero length."""
    from scipy.spatial.transform import Rotation

    q = np.asarray(quaternions, np.float64)
    if not np.all(np.isfinite(q)):
        raise InputError(f"{what}: a quaternion is not finite")
    scale = np.abs(q).max(axis=-1, keepdims=True)
    unit = np.divide(q, scale, out=np.zeros_like(q), where=scale > 0)
    if not np.all(np.linalg.norm(unit, axis=-1) * scale[..., 0] > 1e-6):
        raise InputError(f"{what}: a quaternion has zero length")
    return Rotation.from_quat(unit)


def parse_intrinsics_text(text: str) -> tuple[float, float, float, float]:
    """``"fx,fy,cx,cy"`` as typed after ``--intrinsics`` -> four finite floats, pixels (focal
    lengths positive), or :class:`InputError` quoting `text`."""
    try:
        values = tuple(float(value) for value in text.split(","))
    except ValueError:
        raise InputError(f"--intrinsics must be fx,fy,cx,cy in pixels, got '{text}'") from None
    if len(values) != 4 or not all(np.isfinite(value) for value in values) or values[0] <= 0 or values[1] <= 0:
        raise InputError(f"--intrinsics must be fx,fy,cx,cy: finite pixels, positive focal lengths, got '{text}'")
    return values


MAX_FOCAL_PER_IMAGE_SIDE = 100.0
"""Focal lengths above this many times an image's larger side are refused: a field of view under 0.6 degrees
is a telescope's, not a robot's camera (the paper's: 77 degrees, f = 0.62 x 480 px)."""
MIN_FOCAL_PER_IMAGE_SIDE = 0.04
"""Focal lengths below this many times an image's larger side are refused: a field of view over 170 degrees
is no pinhole camera (its rays' frustum, and the map sized to it, grow without bound)."""


def check_intrinsics_fit(fx: float, fy: float, cx: float, cy: float, width: int, height: int,
                         what: str = "--intrinsics") -> None:
    """InputError naming `what` when pixels intrinsics do not fit a `width` x `height` image, as given before any
    scaling: a number that is not finite, a principal point (`cx`, `cy`) outside it (the intrinsics of another image
    size, or typed wrong), or a focal length above :data:`MAX_FOCAL_PER_IMAGE_SIDE` or below
    :data:`MIN_FOCAL_PER_IMAGE_SIDE` times its larger side. Typed ``--intrinsics`` and those read from files
    (:meth:`~frontiernet.sequences.Camera.checked`) alike."""
    if not np.all(np.isfinite([fx, fy, cx, cy])):
        raise InputError(f"{what}: intrinsics must be finite numbers, got fx={fx:g}, fy={fy:g}, cx={cx:g}, cy={cy:g}")
    if not (0.0 <= cx <= width - 1 and 0.0 <= cy <= height - 1):  # the pixel centres, as pinhole_intrinsics
        raise InputError(f"{what}: the principal point ({cx:g}, {cy:g}) lies outside the {width} x {height} image "
                         f"(intrinsics of another image size?)")
    if max(fx, fy) > MAX_FOCAL_PER_IMAGE_SIDE * max(width, height):
        raise InputError(f"{what}: a focal length of {max(fx, fy):g} px is over {MAX_FOCAL_PER_IMAGE_SIDE:g} x the "
                         f"{width} x {height} image's side (a field of view under 0.6 degrees); focal lengths are pixels")
    if min(fx, fy) < MIN_FOCAL_PER_IMAGE_SIDE * max(width, height):
        raise InputError(f"{what}: a focal length of {min(fx, fy):g} px is under {MIN_FOCAL_PER_IMAGE_SIDE:g} x the "
                         f"{width} x {height} image's side (a field of view over 170 degrees: no pinhole camera); "
                         "focal lengths are pixels")


def back_projected_points(depth: np.ndarray, rgb: np.ndarray | None, K: np.ndarray, T_world_cam: np.ndarray,
                          max_depth_m: float, stride: int) -> tuple[np.ndarray, np.ndarray | None]:
    """(N, 3) float64 world points and (N, 3) uint8 colours (None without `rgb`) of every
    `stride`-th pixel with a valid depth up to `max_depth_m` (`depth` (H, W) metres NaN invalid,
    `rgb` (H, W, 3) the same size)."""
    v, u = np.mgrid[0:depth.shape[0]:stride, 0:depth.shape[1]:stride]
    z = depth[v, u]
    valid = np.isfinite(z) & (z > 0) & (z <= max_depth_m)
    u, v, z = u[valid], v[valid], z[valid].astype(np.float64)
    camera = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], 1)
    return camera @ T_world_cam[:3, :3].T + T_world_cam[:3, 3], None if rgb is None else rgb[v, u]


def pinhole_intrinsics(K, image_shape: tuple[int, int]) -> np.ndarray:
    """(3, 3) float64 pinhole K that fits an (H, W) image, or InputError naming `K`."""
    K = np.asarray(K, np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or not (K[0, 0] > 0 and K[1, 1] > 0):
        raise InputError(f"K must be a finite (3, 3) pinhole matrix with positive focal lengths, got {K.tolist()}")
    H, W = image_shape
    if not (0.0 <= K[0, 2] <= W - 1 and 0.0 <= K[1, 2] <= H - 1):
        raise InputError(f"K's principal point ({K[0, 2]}, {K[1, 2]}) lies outside the {W} x {H} depth image: "
                         "K and depth do not belong together")
    return K


def rigid_pose(T_world_cam, what: str = "T_world_cam") -> np.ndarray:
    """(4, 4) float64 rigid transform, or InputError naming `what` (a pose read from a file: its file, line
    and frame, e.g. ``"rw/trajectory.log:2: the matrix of frame 0"``)."""
    T = np.asarray(T_world_cam, np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InputError(f"{what} must be a finite (4, 4) matrix, got {T.tolist() if T.size <= 16 else T.shape}")
    R = T[:3, :3]
    if not np.allclose(T[3], [0, 0, 0, 1]) or not np.allclose(R.T @ R, np.eye(3), atol=1e-4) \
            or np.linalg.det(R) < 0:
        raise InputError(f"{what} must be a rigid transform (rotation + translation), got {T.tolist()}")
    return T


def grid_cells(xy: np.ndarray, origin_xy: np.ndarray, cell_m: float) -> np.ndarray:
    """(N, 2) int64 indices of the 2D grid cells under (N, 2) (or (2,)) world points `xy`, metres
    (cell ``[i, j]`` spans ``origin + [i, i + 1) x [j, j + 1)`` cells; indices may lie off the grid)."""
    return np.floor((np.asarray(xy, np.float64).reshape(-1, 2) - origin_xy) / cell_m).astype(np.int64)


def cells_inside(cells: np.ndarray, shape: tuple) -> np.ndarray:
    """(...,) bool: whether each cell index (..., 2) lies on a grid of `shape` (X, Y, ...)."""
    return (cells >= 0).all(-1) & (cells[..., 0] < shape[0]) & (cells[..., 1] < shape[1])


def grid_values(field: np.ndarray, origin_xy: np.ndarray, cell_m: float, xy: np.ndarray,
                outside: float = np.inf) -> np.ndarray:
    """(N,) float64 values of an (X, Y) `field` at (N, 2) world points (`outside` off the grid)."""
    cells = grid_cells(xy, origin_xy, cell_m)
    ok = cells_inside(cells, field.shape)
    values = np.full(len(cells), outside, np.float64)
    values[ok] = field[cells[ok, 0], cells[ok, 1]]
    return values


def disks_touch_cells(mask: np.ndarray, origin_xy: np.ndarray, cell_m: float, xy: np.ndarray,
                      radius_m: float) -> np.ndarray:
    """Whether a disk of `radius_m` around each world point overlaps a set cell of a 2D grid.

    Args:
        mask: (X, Y) bool, cell ``[i, j]`` is the square ``origin + [i, i + 1) x [j, j + 1)`` cells.
        origin_xy: (2,) world corner of cell (0, 0), metres; cell_m: cell size, metres.
        xy: (N, 2) world points, metres.
        radius_m: disk radius, metres (an exact disk-square test; cells off the grid are unset).

    Returns:
        (N,) bool.
    """
    cells, near = cells_near(xy, origin_xy, cell_m, radius_m)
    inside = cells_inside(cells, mask.shape)
    hit = np.zeros(inside.shape, bool)
    hit[inside] = mask[cells[inside][:, 0], cells[inside][:, 1]]
    return (hit & near).any(axis=1)


def cells_near(xy: np.ndarray, origin_xy: np.ndarray, cell_m: float, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The cells of a 2D grid (as in :func:`disks_touch_cells`) around each of the (N, 2) world points `xy`
    (metres), within reach of a disk of `radius_m` metres: (N, K, 2) int64 cells (the square block of K
    cells around each point's own; they may lie off the grid) and (N, K) bool, whether the cell's square
    comes within `radius_m` of the point (an exact disk-square test)."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    reach = int(np.ceil(radius_m / cell_m))
    steps = np.arange(-reach, reach + 1)
    offsets = np.stack(np.meshgrid(steps, steps, indexing="ij"), -1).reshape(-1, 2)
    cells = grid_cells(xy, origin_xy, cell_m)[:, None, :] + offsets[None]  # (N, K, 2)
    return cells, squared_distance_to_cells(cells, origin_xy, cell_m, xy[:, None, :]) < radius_m ** 2


def squared_distance_to_cells(cells: np.ndarray, origin_xy: np.ndarray, cell_m: float, xy: np.ndarray) -> np.ndarray:
    """Squared distance (metres^2) from world points `xy` (..., 2) to the squares of 2D grid cells
    `cells` (..., 2) int (cell ``[i, j]`` spans ``origin + [i, i + 1) x [j, j + 1)`` cells, as in
    :func:`disks_touch_cells`); 0 inside a square. The two broadcast against each other."""
    gaps = np.maximum(np.abs(origin_xy + (cells + 0.5) * cell_m - xy) - cell_m / 2, 0.0)  # to each square
    return (gaps ** 2).sum(-1)


def distance_to_false(mask: np.ndarray) -> np.ndarray:
    """(H, W) float64: each cell's Euclidean distance, in cells, to the nearest False cell of the (H, W)
    bool `mask` (0 on False cells): ``scipy.ndimage.distance_transform_edt(mask)``, bit for bit, from
    OpenCV's exact transform (Felzenszwalb and Huttenlocher's, ``DIST_MASK_PRECISE``), ~3x faster on a
    planning grid. OpenCV gives float32 distances; their squares round to the exact integer squared
    distances, whose float64 roots are scipy's values. A mask with no False cell, not 2D or with a diagonal of
    2,000 cells or more (200 m at 0.1 m: near 2,700 the float32 squares no longer round back) goes to scipy.
    """
    import cv2

    mask = np.asarray(mask, bool)
    if mask.ndim != 2 or mask.all() or math.hypot(*mask.shape) >= 2000.0:
        from scipy import ndimage

        return ndimage.distance_transform_edt(mask)
    distance = cv2.distanceTransform(np.ascontiguousarray(mask).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    np.square(distance, out=distance)
    np.rint(distance, out=distance)  # the integer squared distance
    return np.sqrt(distance.astype(np.float64))
