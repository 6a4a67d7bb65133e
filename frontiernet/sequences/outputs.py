"""What ``frontiernet sequence`` writes: ``frontiers.json``, ``map.ply`` + ``frontiers.ply``,
``poses.json`` and the per-frame video pictures.

All 3D outputs are in the run's world frame: gravity-aligned (+z up), metres, the first camera
at the origin (``frontiers.json`` records the transform from the input's frame).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..geometry import back_projected_points
from ..io import atomic_path, check_output_files, write_json
from ..model.overlay import frontier_overlay

RUN_OUTPUTS = ("frontiers.json", "poses.json", "map.ply", "frontiers.ply", "occupancy.npz", "summary.json")
"""The files every ``frontiernet sequence`` run writes in its folder (:func:`check_run_outputs`)."""
VIDEO = "overlay.mp4"
"""The video a run writes, unless ``--no-video`` (through :class:`~frontiernet.exploration.outputs.VideoWriter`)."""


def check_run_outputs(out: str | Path, *, video: bool = True, mcap: bool = True, rosbag2: bool = False,
                      inputs=()) -> None:
    """Before the first frame: InputError naming the first path a run writes in `out` where something of
    the wrong kind stands (a folder at ``overlay.mp4``, a file at ``rosbag2``, a pipe at ``map.ply``: each was
    refused, or an internal error, only after the whole run, its scratch left behind):
    :data:`RUN_OUTPUTS`, the :data:`VIDEO` (with `video`), ``frontiers.mcap`` (with `mcap`), ``rosbag2/`` (with
    `rosbag2`) and their scratch (:func:`~frontiernet.io.check_output_files`,
    :func:`~.ros_out.check_ros_outputs`); or where one of the run's `inputs` ((path, what) pairs) is."""
    from ..exploration.outputs import VideoWriter
    from .ros_out import check_ros_outputs

    check_output_files(out, (*RUN_OUTPUTS, *((VIDEO, VideoWriter.scratch(Path(VIDEO)).name) if video else ())),
                       inputs)
    check_ros_outputs(Path(out), mcap=mcap, rosbag2=rosbag2)


def frontier_records(tracked, names: list[str]) -> tuple[list[dict], list[dict]]:
    """(alive, removed) frontier records with first/last frame names in place of step numbers."""
    def record(entry: dict) -> dict:
        entry = dict(entry)
        entry["first_frame"], entry["last_frame"] = names[entry.pop("first_step")], names[entry.pop("last_step")]
        entry["parent_frame"] = names[entry.pop("parent_pose")]
        if "removed_frame" in entry:
            entry["removed_frame"] = names[entry["removed_frame"]]
        return entry

    return ([record(frontier) for frontier in tracked.tracker.as_list()],
            [record(frontier) for frontier in tracked.tracker.removed_log])


def write_frontiers(path: Path, tracked, names: list[str], info: dict) -> Path:
    """``frontiers.json``: ``frontiers`` (alive after the last frame), ``removed`` (with
    ``reason`` and ``removed_frame``) and `info` (frame, transform, scale, counts)."""
    alive, removed = frontier_records(tracked, names)
    return write_json(path, {**info, "frontiers": alive, "removed": removed, "per_frame": tracked.per_frame})


class PointCloudFusion:
    """Accumulates back-projected coloured points, voxel-downsampled (Open3D) as it goes."""

    def __init__(self, voxel_m: float, max_depth_m: float, stride: int) -> None:
        import open3d as o3d

        self.cloud = o3d.geometry.PointCloud()
        self.voxel_m, self.max_depth_m, self.stride = float(voxel_m), float(max_depth_m), int(stride)

    def add(self, depth: np.ndarray, rgb: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray) -> None:
        import open3d as o3d

        points, colours = back_projected_points(depth, rgb, K, T_world_cam, self.max_depth_m, self.stride)
        frame = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        frame.colors = o3d.utility.Vector3dVector(colours.astype(np.float64) / 255.0)
        self.cloud = (self.cloud + frame).voxel_down_sample(self.voxel_m)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(points (N, 3) float64 world metres, colours (N, 3) uint8) of the cloud so far."""
        colours = np.clip(np.asarray(self.cloud.colors) * 255.0 + 0.5, 0, 255).astype(np.uint8)
        return np.asarray(self.cloud.points, np.float64), colours

    def write(self, path: Path) -> Path:
        import open3d as o3d

        with atomic_path(path) as tmp:
            _checked(o3d.io.write_point_cloud(str(tmp), self.cloud), path)
        return Path(path)


def _checked(ok: bool, path: Path) -> None:
    if not ok:
        raise OSError(f"{path}: Open3D could not write the file")


def frontier_arrows(frontiers, gain_colour, length_m: float = 0.5):
    """An Open3D TriangleMesh: one arrow per frontier, from its position along its view
    direction, coloured by ``gain_colour(gain_m3) -> (r, g, b)``."""
    import open3d as o3d

    from .gravity import rotation_between

    arrows = o3d.geometry.TriangleMesh()
    for frontier in frontiers:
        arrow = o3d.geometry.TriangleMesh.create_arrow(
            cylinder_radius=0.02 * length_m, cone_radius=0.05 * length_m,
            cylinder_height=0.7 * length_m, cone_height=0.3 * length_m)  # along +z from the origin
        direction = np.asarray(frontier.direction, np.float64)
        arrow.rotate(rotation_between(np.array([0.0, 0.0, 1.0]), direction / np.linalg.norm(direction)),
                     center=np.zeros(3))
        arrow.translate(np.asarray(frontier.position, np.float64))
        arrow.paint_uniform_color(np.asarray(gain_colour(frontier.gain_m3), np.float64) / 255.0)
        arrows += arrow
    return arrows


EMPTY_PLY = ("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
             "element face 0\nproperty list uchar int vertex_indices\nend_header\n")
"""A mesh with no vertices (Open3D refuses to write one): ``frontiers.ply`` with no live frontier."""


def write_arrows(path: Path, frontiers, gain_colour) -> Path:
    import open3d as o3d

    from ..io import write_text

    frontiers = list(frontiers)
    if not frontiers:
        return write_text(path, EMPTY_PLY)
    mesh = frontier_arrows(frontiers, gain_colour)
    mesh.compute_vertex_normals()
    with atomic_path(path) as tmp:
        _checked(o3d.io.write_triangle_mesh(str(tmp), mesh), path)
    return Path(path)


def camera_picture(arrays: dict, frontiers, T_world_cam: np.ndarray, labels: dict, threshold_px: float,
                   gain_colour) -> np.ndarray:
    """(h, w, 3) uint8: the network's input image with its frontier pixels coloured by gain class,
    and the tracked frontiers in view drawn as rings with their ids."""
    import cv2

    picture = frontier_overlay(arrays["rgb"], arrays["distance_field"].astype(np.float32), arrays["gain_class"],
                               threshold_px, int(labels["num_classes"]))
    K, height, width = arrays["K"], picture.shape[0], picture.shape[1]
    T_cam_world = np.linalg.inv(T_world_cam)
    for frontier in frontiers:
        point = T_cam_world[:3, :3] @ frontier.position + T_cam_world[:3, 3]
        if point[2] <= 0.1:
            continue
        u, v = K[0, 0] * point[0] / point[2] + K[0, 2], K[1, 1] * point[1] / point[2] + K[1, 2]
        if not (0 <= u < width and 0 <= v < height):
            continue
        centre = (int(round(u)), int(round(v)))
        cv2.circle(picture, centre, 7, gain_colour(frontier.gain_m3), 2, cv2.LINE_AA)
        cv2.putText(picture, str(frontier.id), (centre[0] + 9, centre[1] + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                    (255, 255, 255), 1, cv2.LINE_AA)
    return picture
