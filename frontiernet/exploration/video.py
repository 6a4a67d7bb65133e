"""Per-step video frames and progress of a run (an ``on_step`` consumer of the explorer)."""

from __future__ import annotations

import numpy as np

from .drawing import TopDown, gain_colour_map, label


class StepPictures:
    """Draws [camera view with frontier pixels | the robot's map from above] for every
    ``run.video_every_steps``-th iteration into a video writer, and shows a progress bar. With a
    `prediction` (:class:`~frontiernet.exploration.predicted.TopdownPrediction`, ``explore
    --show-prediction``) a third panel shows the map as the predictor completes it: the cells the robot
    knows as in the second, the others by their predicted occupancy (light blue free, purple occupied);
    `predicts` False: the prediction is the method's own, which the panel only reads (the run unchanged).

    Use as a context manager around :meth:`Explorer.run`.
    """

    def __init__(self, voxels, conf, writer, budget: int, progress: bool = True, prediction=None,
                 predicts: bool = True) -> None:
        self.voxels, self.conf, self.writer, self.budget = voxels, conf, writer, int(budget)
        self.prediction, self.predicts = prediction, predicts
        self.every = max(1, int(conf.run.video_every_steps))
        self.band = float(conf.planner.height_band_m)
        self.topdown = TopDown(voxels.origin[:2], voxels.shape[:2], voxels.voxel_size, height_px=480)
        self.progress = progress
        self._layout = None
        self._bar = self._task = None
        self._colour = None

    def __enter__(self):
        if self.progress:
            from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

            self._bar = Progress(TextColumn("exploring"), BarColumn(), TextColumn("{task.completed}/{task.total} steps"),
                                 TextColumn("coverage {task.fields[coverage]:.1%}"), TimeRemainingColumn(),
                                 transient=True)
            self._bar.__enter__()
            self._task = self._bar.add_task("explore", total=self.budget, coverage=0.0)
        return self

    def __exit__(self, *exc) -> None:
        if self._bar is not None:
            self._bar.__exit__(*exc)

    def __call__(self, explorer, record, frame, seen) -> None:
        if self._bar is not None:
            self._bar.update(self._task, completed=min(record.step, self.budget), coverage=record.coverage)
        if self.writer is None or record.iteration % self.every:
            return
        self.writer.add(self.picture(explorer, record, seen))

    def picture(self, explorer, record, seen) -> np.ndarray:
        """(480, 480 + map width (x 2 with a prediction), 3) uint8 frame of one iteration."""
        import cv2

        from ..model.overlay import frontier_overlay

        labels = seen.labels
        if self._colour is None:
            self._colour = gain_colour_map(labels["bin_edges"], float(labels["bin_unit_m3"]))
        threshold = explorer.conf.anchoring.frontier_threshold_px
        threshold = float(labels["frontier_threshold_px"] if threshold is None else threshold)
        camera = frontier_overlay(seen.rgb, seen.distance_field, seen.gain_class, threshold, int(labels["num_classes"]))
        camera = cv2.resize(camera, (480, 480), interpolation=cv2.INTER_NEAREST)
        camera = label(camera, f"step {record.step}  coverage {record.coverage:.1%}  frontiers {record.frontiers}")
        z = explorer.motion.z
        free, occupied = explorer.map.slice_2d(z - self.band, z + self.band)
        path = np.array([T[:2, 3] for T in explorer.poses])
        if self._layout is None:
            self._layout = self.voxels.explorable[:, :, self.voxels.layer(z)]
        top = self.topdown.draw(self.topdown.background(free, occupied, self._layout), path, path[-1], record.yaw,
                                list(explorer.tracker), record.goal, self._colour)
        if self.prediction is None:
            return np.concatenate([camera, top], axis=1)
        from ..mapping.occupancy import FREE, OCCUPIED
        from ..mapprediction import map_topdown_states

        states = map_topdown_states(explorer.map, z, self.prediction.predictor.spec.band_m)  # the predictor's band
        mean, _ = self.prediction(states, predict=self.predicts)
        predicted = self.topdown.draw(self.topdown.prediction(states == FREE, states == OCCUPIED, mean), path,
                                      path[-1], record.yaw, [], None, self._colour)
        return np.concatenate([camera, top, label(predicted, "predicted map")], axis=1)
