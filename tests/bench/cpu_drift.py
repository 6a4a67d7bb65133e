"""Does a run repeat on another CPU? (docs/benchmark.md, "Both depth regimes".)

Runs one ``frontiernet`` command twice in subprocesses, with numpy's SIMD dispatch as this CPU has it
and with its AVX-512 loops switched off (``NPY_DISABLE_CPU_FEATURES``, read when numpy is imported:
one machine then stands in for a CPU without AVX-512), and hashes what each stage of the loop hands
on: the perception's inputs to anchoring and the anchored frontiers, the tracker after each update,
the pose and map after each frame, each plan. Prints each run's summary line and the first stage
whose hash differs, or that the runs agree. It found the two causes fixed in the code (numpy's
arctan2 in headings, hdbscan's unstable sort of equal weights: ``geometry.atan2``,
``anchoring._hdbscan``). It does not vary what numpy does not run: the model's runtime (ONNX
Runtime, torch) picks its kernels for the CPU too.

    .venv/bin/python tests/bench/cpu_drift.py explore --scene procedural:2000 --method oracle --depth gt \
        --start 13.5,7.9,1.2,-51.6353 --max-steps 500 --no-video --out /tmp/drift
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

AVX512 = "X86_V4 AVX512_ICL"
"""numpy 2.x's names of its AVX-512 dispatch targets."""


def digest(value) -> str:
    h = hashlib.md5()

    def add(v):
        if isinstance(v, np.ndarray):
            h.update(np.ascontiguousarray(v).tobytes())
        elif isinstance(v, (list, tuple)):
            for e in v:
                add(e)
        elif hasattr(v, "__dict__"):
            for _, e in sorted(vars(v).items()):
                add(e)
        else:
            h.update(repr(v).encode())
    add(value)
    return h.hexdigest()[:10]


def traced(trace_path: str, argv: list[str]) -> int:
    """Run the frontiernet command `argv` in this process, writing one line per stage to `trace_path`."""
    import frontiernet.frontiers as frontiers
    from frontiernet.exploration import explorer
    from frontiernet.frontiers import anchoring, tracking

    out = open(trace_path, "w")
    count = [0]

    def log(stage, value):
        out.write(json.dumps({"n": count[0], "stage": stage, "hash": digest(value)}) + "\n")

    anchor = anchoring.anchor_prediction

    def anchor_prediction(*args, **kwargs):
        result = anchor(*args, **kwargs)
        log("anchoring input (D, gain, depth, K, T_world_cam)", args[:5])
        log("anchored frontiers", result)
        count[0] += 1
        return result
    anchoring.anchor_prediction = frontiers.anchor_prediction = anchor_prediction

    def wrap(cls, name, what):
        original = getattr(cls, name)

        def call(self, *args, **kwargs):
            result = original(self, *args, **kwargs)
            log(f"{cls.__name__}.{name}", what(self))
            return result
        setattr(cls, name, call)
    frontier_state = lambda t: [(f.id, f.position, f.direction, f.gain_m3) for f in t]  # noqa: E731
    for name in ("add", "update_gains", "prune"):
        wrap(tracking.FrontierTracker, name, frontier_state)
    wrap(explorer.Explorer, "sense", lambda e: (e.agent.pose, e.map.log_odds))
    wrap(explorer.Explorer, "plan", lambda e: None if e.route is None else (e.route.frontier_id, e.route.waypoints))

    from frontiernet.cli.main import main
    return main(argv)


def main(argv: list[str]) -> int:
    if argv and argv[0] == "--traced":
        return traced(argv[1], argv[2:])
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1")  # as a benchmark worker
    traces = []
    with tempfile.TemporaryDirectory() as folder:
        for name, disabled in (("this CPU", ""), ("no AVX-512", AVX512)):
            path = os.path.join(folder, f"{len(traces)}.jsonl")
            result = subprocess.run([sys.executable, __file__, "--traced", path, *argv], capture_output=True, text=True,
                                    env=dict(env, NPY_DISABLE_CPU_FEATURES=disabled))
            print(f"{name}: {(result.stdout.strip().splitlines() or [result.stderr.strip()])[-1]}")
            traces.append([json.loads(line) for line in open(path)])
    for a, b in zip(*traces):
        if a != b:
            print(f"first difference: {a['stage']} (frame {a['n']})")
            return 1
    print(f"the runs agree at all {min(map(len, traces))} stages" +
          ("" if len(traces[0]) == len(traces[1]) else " both have (their lengths differ)"))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
