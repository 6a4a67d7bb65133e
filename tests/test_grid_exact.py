"""The grid helpers behind the planners' free space: exact, faster stand-ins for scipy's distance
transform (``geometry.distance_to_false``) and the geodesic search's reachability
(``planning.grid.reachable_region``). They must give the same values, so no run changes."""

from __future__ import annotations

import numpy as np


def test_distance_to_false_is_scipys_euclidean_distance_transform_bit_for_bit():
    """The planning grids' clearance (frontiernet.geometry.distance_to_false, OpenCV's exact transform):
    the same float64 values as scipy's, so runs do not change, on masks of every kind."""
    from scipy import ndimage

    from frontiernet.geometry import distance_to_false

    rng = np.random.default_rng(0)
    masks = [np.ones((7, 9), bool), np.zeros((7, 9), bool), np.ones((1, 40), bool) & (np.arange(40) != 3)]
    for k in range(40):
        shape = tuple(rng.integers(2, 400, 2))
        mask = rng.random(shape) > rng.uniform(0.0005, 0.5)
        if k % 2:  # walls: blobs of False
            mask = ~ndimage.binary_dilation(~mask, iterations=int(rng.integers(1, 6)))
        masks.append(mask)
    far = np.ones((1300, 1300), bool)
    far[0, 0] = False  # distances up to 1,838 cells
    masks.append(far)
    for mask in masks:
        expected = ndimage.distance_transform_edt(mask)
        got = distance_to_false(mask)
        assert got.dtype == np.float64 and np.array_equal(got, expected)


def test_the_reachable_region_is_where_the_geodesic_search_reaches():
    """planning.grid.reachable_region (labelling) against the minimum-cost-path search it replaces for
    reachability (omniscient's views): the same cells on random grids, from open and blocked starts."""
    from frontiernet.planning.grid import geodesic_distance, reachable_region

    rng = np.random.default_rng(1)
    for _ in range(150):
        shape = tuple(rng.integers(3, 120, 2))
        open_cells = rng.random(shape) > rng.uniform(0.1, 0.7)
        start = (int(rng.integers(0, shape[0])), int(rng.integers(0, shape[1])))
        expected = np.isfinite(geodesic_distance(np.where(open_cells, 1.0, np.inf), start))
        assert np.array_equal(reachable_region(open_cells, start), expected)
    assert not reachable_region(np.ones((4, 4), bool), (9, 0)).any()  # a start off the grid
