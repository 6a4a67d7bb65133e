"""``frontiernet explore --mcap``: a simulated exploration run as the ROS 2 messages that
``frontiernet sequence`` writes (:mod:`.ros_out`, issue 57), in ``exploration.mcap``.

Per iteration of the explorer, stamped iteration / ``run.video_fps`` s (the video's clock):
the tracked frontiers (``/frontiernet/frontiers`` markers with the tracker's ids,
``/frontiernet/frontier_poses``), the camera image with its frontier pixels and the frontiers in
view (``/frontiernet/overlay`` and its camera info), the camera's pose as tf ``map`` ->
``camera`` (``map`` is the simulator's world: Z up, metres; ``camera`` an optical frame), and
every ``outputs.ros.map_every_frames`` iterations and at the last the robot's map: the centres of
its occupied voxels (``/frontiernet/map``, grey). ``configs/sequence.yaml``'s ``outputs.ros``
section sets the map's rate and the arrows' length.

An ``on_step`` consumer of :class:`~frontiernet.exploration.explorer.Explorer`, as the video and
the Rerun recording are (:func:`frontiernet.exploration.run.main`'s ``step_outputs``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .outputs import camera_picture
from .ros_out import OutputFrames, RosMessages, RosWriter

MAP_GREY = (90, 90, 100)
"""Colour of the map's occupied voxels (the Rerun recording's)."""


class ExplorationMcap:
    """Writes the run's messages (module doc) to `path`; the file appears on :meth:`close`."""

    def __init__(self, path: str | Path) -> None:
        from ..config import load_config

        self.path = Path(path)
        conf = load_config("sequence").outputs.ros
        self.every, self.arrow_m = max(1, int(conf.map_every_frames)), float(conf.arrow_length_m)
        self.writer = self.messages = self.explorer = None  # opened at the first iteration
        self.stamp = self.iteration = 0

    def __call__(self, explorer, record, frame, seen) -> None:
        from ..exploration.drawing import gain_colour_map

        labels = seen.labels
        if self.writer is None:
            colour = gain_colour_map(labels["bin_edges"], float(labels["bin_unit_m3"]))
            self.messages = RosMessages(OutputFrames("map", "camera", np.eye(4), None, True), colour, self.arrow_m)
            self.writer = RosWriter(self.path.parent, name=self.path.name)
            threshold = explorer.conf.anchoring.frontier_threshold_px
            self.threshold = float(labels["frontier_threshold_px"] if threshold is None else threshold)
            self.period_s = 1.0 / float(explorer.conf.run.video_fps)
        self.explorer, self.iteration = explorer, int(record.iteration)
        self.stamp = round(self.iteration * self.period_s * 1e9)
        T = explorer.agent.pose
        frontiers = list(explorer.tracker)
        arrays = {"rgb": seen.rgb, "distance_field": seen.distance_field, "gain_class": seen.gain_class, "K": seen.K}
        overlay = camera_picture(arrays, frontiers, T, labels, self.threshold, self.messages.colour)
        cloud = self.map_points(explorer) if self.iteration % self.every == 0 else None
        self.writer.write(self.messages.frame(self.stamp, T, frontiers, overlay, seen.K, cloud))

    @staticmethod
    def map_points(explorer) -> tuple[np.ndarray, np.ndarray]:
        """(centres of the robot map's occupied voxels (N, 3), their colours (N, 3) uint8)."""
        occupancy = explorer.map
        points = occupancy.index_to_world(np.argwhere(occupancy.occupied_mask()))
        return points, np.tile(np.array(MAP_GREY, np.uint8), (len(points), 1))

    def close(self) -> Path | None:
        """The map at the last iteration (unless it was just written), then the file in place;
        None when no iteration ran."""
        if self.writer is None:
            return None
        if self.iteration % self.every:
            self.writer.write([self.messages.map_message(self.stamp, *self.map_points(self.explorer))])
        return self.writer.close()[0]
