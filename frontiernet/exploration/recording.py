"""Optional Rerun recording of a run (``frontiernet explore --rerun``), to scrub through it in 3D.

Needs ``rerun-sdk`` (``pip install "frontiernet[rerun]"``); open the file with ``rerun FILE.rrd``.
Per iteration (timeline ``step``): the camera pose, its image with the perceived frontier
overlay, the live frontiers as arrows coloured by gain, the trajectory, and (every
``every_map`` iterations) the occupied voxels of the robot's map.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError


def require_rerun():
    """The ``rerun`` module, or InputError saying how to install it."""
    try:
        import rerun
    except ImportError:
        raise InputError("--rerun needs the rerun-sdk package: pip install 'frontiernet[rerun]' "
                         "(or pip install rerun-sdk)") from None
    return rerun


class RerunRecorder:
    """An ``on_step`` consumer writing a ``.rrd`` recording to `path` (world frame Z-up, metres)."""

    def __init__(self, path: Path, every_map: int = 10) -> None:
        rr = require_rerun()
        self.rr, self.path, self.every_map = rr, Path(path), max(1, int(every_map))
        self.stream = rr.RecordingStream("frontiernet")
        self.stream.save(str(self.path))
        self.stream.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._colour = None

    def __call__(self, explorer, record, frame, seen) -> None:
        from ..model.overlay import frontier_overlay
        from .drawing import gain_colour_map

        rr, log = self.rr, self.stream.log
        self.stream.set_time("step", sequence=int(record.iteration))
        T = explorer.agent.pose
        log("world/camera", rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]))
        height, width = seen.distance_field.shape
        log("world/camera/image", rr.Pinhole(image_from_camera=seen.K, width=width, height=height,
                                             camera_xyz=rr.ViewCoordinates.RDF))
        threshold = explorer.conf.anchoring.frontier_threshold_px
        threshold = float(seen.labels["frontier_threshold_px"] if threshold is None else threshold)
        log("world/camera/image/frontiers", rr.Image(frontier_overlay(seen.rgb, seen.distance_field, seen.gain_class,
                                                                      threshold, int(seen.labels["num_classes"]))))
        if self._colour is None:
            self._colour = gain_colour_map(seen.labels["bin_edges"], float(seen.labels["bin_unit_m3"]))
        frontiers = list(explorer.tracker)
        if frontiers:
            log("world/frontiers", rr.Arrows3D(origins=[f.position for f in frontiers],
                                               vectors=[0.5 * f.direction for f in frontiers],
                                               colors=[self._colour(f.gain_m3) for f in frontiers],
                                               labels=[f"{f.id}: {f.gain_m3:.1f} m3" for f in frontiers]))
        else:
            log("world/frontiers", rr.Clear(recursive=False))
        log("world/trajectory", rr.LineStrips3D([np.array([P[:3, 3] for P in explorer.poses])], colors=[(40, 90, 230)]))
        if record.iteration % self.every_map == 0:
            occupied = explorer.map.index_to_world(np.argwhere(explorer.map.occupied_mask()))
            log("world/map/occupied", rr.Points3D(occupied, radii=explorer.map.voxel_size / 2, colors=[(90, 90, 100)]))

    def close(self) -> Path:
        self.stream.flush()
        return self.path
