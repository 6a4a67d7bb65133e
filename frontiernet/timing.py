"""Wall time per named stage: :class:`Stopwatch`, the one stage timer of the library.

``with stopwatch("render"): frame = renderer.render(T)`` adds the block's wall time (seconds,
``time.perf_counter``) to ``stopwatch.seconds["render"]``. The timed code runs in the caller's
own frame: the stopwatch never calls back into it (docs/design.md, "Walk (a)" and "Walk (b)").
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from typing import Iterator


class Stopwatch:
    """Seconds per stage, summed over the stage's blocks since the last :meth:`reset`.

    Attributes:
        seconds: stage name -> float seconds, in the order the stages first ran.
    """

    def __init__(self, seconds: dict[str, float] | None = None) -> None:
        """`seconds`: the dict to add to (a record's field); None: a new one."""
        self.seconds: dict[str, float] = {} if seconds is None else seconds

    @contextmanager
    def __call__(self, stage: str) -> Iterator[None]:
        """Time the ``with`` block as `stage` (a block that raises is not counted)."""
        start = time.perf_counter()
        yield
        self.seconds[stage] = self.seconds.get(stage, 0.0) + time.perf_counter() - start

    def reset(self) -> None:
        """Forget every stage (a new step)."""
        self.seconds = {}
