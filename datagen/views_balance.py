"""The views of one shard: candidate poses, ground truth, and the frontier/no-frontier balance.

A shard of N views keeps about ``frontier_view_fraction * N`` views that show frontier
pixels and the rest that show none (so the model also learns where *not* to fire).
Candidates come from the ``sampling.mode`` sources (uniform poses and/or poses along
simulated exploration paths) in seeded batches; a candidate whose kind (with or without
frontiers) has its quota filled is kept aside, and used only when
``max_candidates_factor * N`` candidates have been tried and the shard is still short.
"""

from __future__ import annotations

import numpy as np

from frontiernet.errors import InputError
from frontiernet.simulator.poses import sample_poses

from .ground_truth import GroundTruth, GroundTruthGenerator
from .views import sample_trajectory_poses

MODES = ("uniform", "trajectory", "mixed")


def candidate_poses(generator: GroundTruthGenerator, n: int, rng: np.random.Generator, conf) -> tuple:
    """`n` candidate poses: (n, 4, 4) float64 ``T_world_cam`` and a list of n kinds
    ("uniform" or "trajectory"), per ``conf.sampling``."""
    sampling = conf.sampling
    mode = sampling.mode
    if mode not in MODES:
        raise InputError(f"sampling.mode must be one of {', '.join(MODES)}, got {mode!r}")
    fraction = {"uniform": 0.0, "trajectory": 1.0}.get(mode, float(sampling.trajectory_fraction))
    if not 0.0 <= fraction <= 1.0:
        raise InputError(f"sampling.trajectory_fraction must be in [0, 1], got {sampling.trajectory_fraction!r}")
    n_path = int(rng.binomial(n, fraction)) if 0.0 < fraction < 1.0 else int(round(fraction * n))
    parts, kinds = [], []
    if n - n_path:
        parts.append(sample_poses(generator.scene, generator.voxels, n - n_path, rng, conf.poses))
        kinds += ["uniform"] * (n - n_path)
    if n_path:
        parts.append(sample_trajectory_poses(generator.scene, generator.voxels, n_path, rng,
                                             sampling.trajectory, conf.poses))
        kinds += ["trajectory"] * n_path
    order = rng.permutation(n)  # interleave the kinds
    return np.concatenate(parts)[order], [kinds[i] for i in order]


def shard_views(generator: GroundTruthGenerator, n: int, rng: np.random.Generator, conf,
                on_view=None) -> tuple[list[tuple[GroundTruth, str]], int]:
    """Generate the `n` views of one shard.

    Args:
        generator: the scene's ground-truth generator.
        n: views to keep.
        rng: the shard's generator (the only source of randomness: same seed, same views).
        conf: the merged datagen config.
        on_view: optional callable(), called once per view kept (progress).
    Returns:
        ([(ground truth, pose kind)] in acceptance order, number of candidates computed).
    """
    sampling = conf.sampling
    share = float(sampling.frontier_view_fraction)
    if not 0.0 <= share <= 1.0:
        raise InputError(f"sampling.frontier_view_fraction must be in [0, 1], got {share!r}")
    factor = float(sampling.max_candidates_factor)
    if not factor >= 1.0:
        raise InputError(f"sampling.max_candidates_factor must be >= 1, got {sampling.max_candidates_factor!r}")
    quota = {True: int(round(share * n)), False: n - int(round(share * n))}
    kept: list[tuple[GroundTruth, str]] = []
    spare: list[tuple[GroundTruth, str]] = []
    budget = int(np.ceil(factor * n))
    tried = 0
    while len(kept) < n and tried < budget:
        batch = min(max(n - len(kept), 1), budget - tried)
        poses, kinds = candidate_poses(generator, batch, rng, conf)
        for T, kind in zip(poses, kinds):
            truth = generator(T, rng)
            tried += 1
            has_frontier = bool(truth.frontier_mask.any())
            if quota[has_frontier] > 0:
                quota[has_frontier] -= 1
                kept.append((truth, kind))
                if on_view is not None:
                    on_view()
            elif len(spare) < n:
                spare.append((truth, kind))
            if len(kept) == n:
                break
    for view in spare[: n - len(kept)]:
        kept.append(view)
        if on_view is not None:
            on_view()
    if len(kept) < n:  # every candidate was kept or spared; cannot happen unless budget < n
        raise InputError(f"{generator.scene.metadata.spec}: only {len(kept)} of {n} views generated")
    return kept, tried
