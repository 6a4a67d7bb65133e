"""The summary of a dataset run: views, frontier statistics, gain classes, failures, speed."""

from __future__ import annotations

import numpy as np

from .shards import read_shard_meta


def scene_error(spec: str, error: Exception) -> str:
    """The message of a scene's bad input `error` without the scene spec it starts with (``scene spec '<spec>':
    ...``), which the run's report of failed scenes puts before it: the scene is named once."""
    return str(error).removeprefix(f"scene spec '{spec}': ").removeprefix(f"{spec}: ")


def summarise(out, tasks, results: list[dict], elapsed_s: float, done_before: int = 0) -> dict:
    """Aggregate the shards on disk and this run's results into a JSON-able summary.

    Frontier statistics are over every view on disk (earlier runs of a resumed dataset
    included); speed is over the views made by this run.
    """
    from pathlib import Path

    views = frontier_views = frontier_pixels = pixels = candidates = 0
    histogram = None
    scenes_with_views = set()
    for task in tasks:
        path = Path(task.path)
        if not path.is_file():
            continue
        meta = read_shard_meta(path)
        candidates += int(meta.get("candidates", 0))
        for record in meta["samples"]:
            views += 1
            scenes_with_views.add(record["scene"])
            frontier_pixels += record.get("frontier_pixels", 0)
            frontier_views += record.get("frontier_pixels", 0) > 0
            pixels += record.get("width", 0) * record.get("height", 0)
            counts = np.asarray(record.get("class_histogram", []), np.int64)
            histogram = counts if histogram is None else histogram + counts
    made = [r for r in results if r["ok"]]
    made_views = sum(r["views"] for r in made)
    failures = {}
    for result in results:
        if not result["ok"]:
            failures.setdefault(result["spec"], {"scene": result["spec"], "error": result["error"],
                                                 "bad_input": bool(result.get("bad_input"))})
    stages: dict[str, float] = {}
    for result in made:
        for stage, seconds in result.get("timings", {}).items():
            stages[stage] = stages.get(stage, 0.0) + seconds
    return {
        "views": views,
        "scenes": len(scenes_with_views),
        "shards": sum(Path(t.path).is_file() for t in tasks),
        "shards_planned": len(tasks),
        "shards_done_before": done_before,
        "frontier_view_fraction": frontier_views / views if views else 0.0,
        "frontier_pixel_ratio": frontier_pixels / pixels if pixels else 0.0,
        "candidates_per_view": candidates / views if views else 0.0,
        "gain_class_pixels": histogram.tolist() if histogram is not None else [],
        "failed_scenes": list(failures.values()),
        "failed_shards": len(results) - len(made),
        "views_this_run": made_views,
        "seconds": elapsed_s,
        "views_per_second": made_views / elapsed_s if elapsed_s > 0 else 0.0,
        "seconds_per_stage_per_view": {k: v / made_views for k, v in stages.items()} if made_views else {},
        "raycast_backends": sorted({r["raycast_backend"] for r in made if "raycast_backend" in r}),
    }


def failed_scenes_exit(failed: list[dict], command: str, kept: str) -> int:
    """A run's exit code after its report: 0 without `failed` scenes (``failed_scenes`` of a
    summary); else one line naming the first failed scene, what became of the rest (`kept`, e.g.
    ``the other scenes' views are in DIR``) and what to do: an InputError (exit 2) when every
    failure is bad input, else the line on stderr and exit 1 (a fault of ours in a scene)."""
    import sys

    from frontiernet.errors import InputError

    if not failed:
        return 0
    others = f" (and {len(failed) - 1} more scene(s), listed above and in summary.json)" if len(failed) > 1 else ""
    text = (f"{failed[0]['scene']}: {failed[0]['error']}{others}; {kept}: fix it and rerun with --resume, or leave "
            f"it out (with another --out)")
    if all(failure.get("bad_input") for failure in failed):
        raise InputError(text)
    print(f"frontiernet {command}: failed: {text}", file=sys.stderr)
    return 1
