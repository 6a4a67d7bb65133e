"""The Ray backend: the same shard tasks as Ray tasks, so a cluster scales a run out.

Connects to the cluster named by ``RAY_ADDRESS`` (``ray start --head`` on one machine,
``ray start --address=...`` on the others), or starts a local Ray instance. Every node
must see the output folder (a shared file system) and the scene files at the same paths.
At most `workers` shards run at once; a shard whose worker dies is retried once by Ray.
"""

from __future__ import annotations

import os
import time

from frontiernet.workers import import_ray

from .backends import run_shard_task


def run_on_ray(tasks: list[dict], conf_dict: dict, info: dict, workers: int, bar) -> list[dict]:
    """Run shard tasks as Ray tasks, `workers` at a time; returns their results."""
    ray = import_ray()
    started_here = not ray.is_initialized()
    if started_here:
        address = os.environ.get("RAY_ADDRESS")
        ray.init(address=address or None, num_cpus=None if address else workers, include_dashboard=False,
                 log_to_driver=False, configure_logging=False)
    remote = ray.remote(num_cpus=1, max_retries=1)(run_shard_task)
    conf_ref, info_ref = ray.put(conf_dict), ray.put(info)
    queue = list(tasks)
    running: dict = {}
    results, failed = [], 0
    try:
        while queue or running:
            while queue and len(running) < workers:
                task = queue.pop(0)
                running[remote.remote(task, conf_ref, info_ref)] = task
            done, _ = ray.wait(list(running), num_returns=1, timeout=1.0)
            for ref in done:
                task = running.pop(ref)
                try:
                    result = ray.get(ref)
                except Exception as error:  # the worker died twice, or Ray itself failed
                    result = {"task": os.path.basename(task["path"]), "spec": task["spec"], "ok": False,
                              "error": f"Ray task failed: {type(error).__name__}", "seconds": 0.0}
                results.append(result)
                failed += not result["ok"]
                bar.advance(task["num_views"], failed)
            if not done:
                time.sleep(0.05)
    finally:
        if started_here:
            ray.shutdown()
    return results
