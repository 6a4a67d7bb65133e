"""The exploration benchmark (``frontiernet bench --scenes ... --methods ...``).

Every method runs on the same scenes, start poses, camera and step budget; the report is the
paper's Table I for any scene set. Steps, one module each (hloc style):

* :mod:`.plan`: start poses sampled once per scene (seeded) and the list of runs;
* :mod:`.runner`: the runs, in parallel (local processes or Ray), resumable, failures recorded;
* :mod:`.report`: ``results.csv``, ``table.md`` (Vox@25/50/100 with shared step thresholds,
  success) and coverage curves per scene; :func:`report` rebuilds it from the runs finished so
  far (``--report``);
* :mod:`.store`: the finished runs' records, one ``metrics.json`` per run as they finish, or
  packed into one compressed file per (scene, method) by :func:`pack` (``--pack``).

Beside it, :mod:`.perf` holds the hot-path benchmarks (``frontiernet bench render|map|explore``:
stage times as ratios to a render or a bare ray cast of the same run) and their timing helpers.
"""

from .main import main, report
from .plan import RunSpec, plan_runs, start_poses
from .report import write_report
from .runner import run_all
from .store import pack

__all__ = ["main", "report", "RunSpec", "plan_runs", "start_poses", "run_all", "write_report", "pack"]
