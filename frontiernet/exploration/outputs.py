"""What an exploration run writes: metrics, trajectory, frontiers, video, coverage plot.

``metrics.json`` holds coverage per step (the fraction of the scene's explorable volume
observed), Vox@k at 25 / 50 / 100 % of the step budget (docs/design.md item 7; the benchmark
shares the 25 / 50 % step counts across methods), path length, collisions, the mean time
per stage and where the steps went (:mod:`.steps`: ``step_account``, ``unseen_reachable``,
``premature_stop``). The video shows, per step, the camera image with the perceived frontier pixels
coloured by gain class beside a top-down view of the robot's map with its path, the live
frontiers (arrows along their view directions) and the goal.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io import atomic_path, write_json
from .explorer import SIMULATOR_STAGES, STAGES, ExplorationResult
from .surface import coverage_auc

VOX_PERCENTS = (25, 50, 100)


def coverage_per_step(records, steps: int, field: str = "coverage") -> np.ndarray:
    """(steps + 1,) float64: a record field (``coverage``, ``surface_coverage``) after each step
    count 0..steps (the last record at or below it)."""
    coverage = np.zeros(steps + 1)
    for record in records:
        coverage[record.step:] = getattr(record, field)
    return coverage


def vox_at(coverage: np.ndarray, budget: int, percents=VOX_PERCENTS) -> dict:
    """Vox@k: coverage when the step count reaches k % of `budget` (the run's end if it stopped
    earlier, since coverage no longer grows then)."""
    return {str(k): float(coverage[min(int(round(budget * k / 100)), len(coverage) - 1)]) for k in percents}


def timing_summary(records) -> dict:
    """Mean milliseconds per stage over the steps, the robot's step cost (all but the simulator's
    motion check and coverage bookkeeping), and the rate of image-to-3D-frontiers (perception +
    anchoring)."""
    rows = [r.timings for r in records[1:]] or [r.timings for r in records]
    mean = {stage: float(np.mean([row.get(stage, 0.0) for row in rows])) for stage in STAGES}
    sensing = sum(v for k, v in mean.items() if k not in SIMULATOR_STAGES)
    frontiers_ms = mean["perception"] + mean["anchoring"]
    return {"mean_ms": {k: round(v, 2) for k, v in mean.items()}, "step_ms_without_motion": round(sensing, 2),
            "image_to_frontiers_ms": round(frontiers_ms, 2),
            "image_to_frontiers_hz": round(1000.0 / frontiers_ms, 2) if frontiers_ms > 0 else None}


def metrics(result: ExplorationResult, budget: int, info: dict, tracker=None) -> dict:
    """The ``metrics.json`` record of a run (`info`: scene, method, depth, model, seed, start)."""
    steps = result.records[-1].step if result.records else 0
    coverage = coverage_per_step(result.records, steps)
    surface = coverage_per_step(result.records, steps, "surface_coverage")
    vox = vox_at(coverage, budget)
    return {**info, "max_steps": int(budget), "steps": int(steps), "iterations": len(result.records) - 1,
            "stop_reason": result.stop_reason, "coverage": float(coverage[-1]),
            "vox_at": vox, "success": bool(vox["100"] > 0.4),
            "explorable_m3": round(result.explorable_m3, 3),
            "known_m3": round(result.records[-1].known_m3, 3) if result.records else 0.0,
            "path_length_m": round(result.path_length_m, 3), "collisions": int(result.collisions),
            "goals": len(result.goals), "widened_at_step": result.widened_at_step,
            "frontiers_left": result.records[-1].frontiers if result.records else 0,
            "frontiers_removed": dict(tracker.removed) if tracker is not None else {},
            "surface_coverage": float(surface[-1]), "surface_auc": round(coverage_auc(surface, budget), 5),
            "chamfer_m": _finite_or_none(result.reconstruction.get("chamfer_m")),
            "completeness": result.reconstruction.get("completeness"),
            **result.account,  # step_account, unseen_reachable, premature_stop (.steps.run_account)
            "timing": timing_summary(result.records), "coverage_per_step": np.round(coverage, 5).tolist(),
            "surface_coverage_per_step": np.round(surface, 5).tolist()}


def _finite_or_none(value):
    """JSON has no infinity: an empty map's Chamfer distance is written as null."""
    return round(float(value), 5) if value is not None and np.isfinite(value) else None


def write_run(out: Path, result: ExplorationResult, budget: int, info: dict, tracker=None) -> dict:
    """Write ``metrics.json``, ``trajectory.json`` (poses, per-step records, goals), ``frontiers.json``
    and ``coverage.png`` to `out`; returns the metrics."""
    record = metrics(result, budget, info, tracker)
    write_json(out / "metrics.json", record)
    write_json(out / "trajectory.json", {"T_world_cam": result.poses, "goals": result.goals,
                                         "steps": [vars(r) for r in result.records]})
    if tracker is not None:
        write_json(out / "frontiers.json", {"frontiers": tracker.as_list(), "removed": dict(tracker.removed)})
    plot_coverage(out / "coverage.png", np.asarray(record["coverage_per_step"]), budget, str(info.get("scene", "")))
    return record


def plot_coverage(path: Path, coverage: np.ndarray, budget: int, title: str) -> None:
    """Coverage (%) against steps, with the Vox@k step marks."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6, 3.6), dpi=120)
    axis.plot(np.arange(len(coverage)), 100 * coverage, color="tab:blue", lw=2)
    for k in VOX_PERCENTS:
        axis.axvline(budget * k / 100, color="0.6", ls="--", lw=1)
        axis.text(budget * k / 100, 2, f" {k}%", color="0.4", fontsize=8)
    axis.set(xlabel="step", ylabel="explored volume (%)", xlim=(0, budget), ylim=(0, 100), title=title)
    axis.grid(alpha=0.3)
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png")
    plt.close(figure)


class VideoWriter:
    """Streams (H, W, 3) uint8 RGB frames into an MP4 that appears atomically on :meth:`close`."""

    def __init__(self, path: Path, fps: float) -> None:
        self.path, self.fps = Path(path), float(fps)
        self.tmp = self.scratch(self.path)
        self.writer = None
        self.frames = 0

    @staticmethod
    def scratch(path: Path) -> Path:
        """The file the video of `path` is written to before it is renamed into place."""
        return Path(path).with_name(f".{Path(path).name}.partial.mp4")

    def add(self, frame: np.ndarray) -> None:
        import cv2

        if self.writer is None:
            height, width = frame.shape[:2]
            self.writer = cv2.VideoWriter(str(self.tmp), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, (width, height))
        self.writer.write(np.ascontiguousarray(frame[..., ::-1]))
        self.frames += 1

    def close(self) -> Path | None:
        if self.writer is None:
            return None
        self.writer.release()
        self.tmp.replace(self.path)
        return self.path
