"""Pictures of a run: the camera view with frontier pixels, and the robot's map from above."""

from __future__ import annotations

import numpy as np

FREE = (236, 236, 230)
OCCUPIED = (60, 60, 70)
UNKNOWN = (120, 120, 128)
UNKNOWN_INSIDE = (176, 176, 184)  # unknown to the robot, explorable in the scene (for the viewer only)
PATH = (40, 90, 230)
ROBOT = (30, 170, 60)
GOAL = (230, 40, 40)
PREDICTED_FREE = (190, 222, 246)  # unknown to the robot, predicted free (probability 0) ...
PREDICTED_OCCUPIED = (96, 48, 128)  # ... predicted occupied (probability 1); blended in between


class TopDown:
    """World xy -> pixels of a top-down picture of the map, scaled to `height_px`.

    Args:
        origin_xy: (2,) world corner of the map grid; shape_xy: (X, Y) cells; cell_m: metres.
    """

    def __init__(self, origin_xy: np.ndarray, shape_xy: tuple[int, int], cell_m: float, height_px: int = 480) -> None:
        self.origin_xy = np.asarray(origin_xy, np.float64)
        self.shape_xy, self.cell_m = tuple(shape_xy), float(cell_m)
        self.scale = height_px / max(shape_xy[1], 1)  # pixels per cell; rows run along -y
        width = max(2 * int(round(shape_xy[0] * self.scale / 2)), 2)  # even: video encoders want it
        self.size = (width, int(height_px))  # (width, height)

    def pixels(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) world points -> (N, 2) int32 pixel (col, row)."""
        cells = (np.asarray(xy, np.float64).reshape(-1, 2) - self.origin_xy) / self.cell_m
        return np.stack([cells[:, 0] * self.scale, (self.shape_xy[1] - cells[:, 1]) * self.scale], 1).astype(np.int32)

    def background(self, free: np.ndarray, occupied: np.ndarray, layout: np.ndarray | None = None) -> np.ndarray:
        """(H, W, 3) uint8 picture of (X, Y) free / occupied cells (the rest unknown); `layout`
        (X, Y) bool shows the scene's explorable cells, unknown to the robot, a shade lighter."""
        import cv2

        image = np.empty(free.shape + (3,), np.uint8)
        image[:] = UNKNOWN
        if layout is not None:
            image[layout] = UNKNOWN_INSIDE
        image[free] = FREE
        image[occupied] = OCCUPIED
        image = np.ascontiguousarray(np.transpose(image, (1, 0, 2))[::-1])  # rows: +y up
        return cv2.resize(image, self.size, interpolation=cv2.INTER_NEAREST)

    def prediction(self, known_free: np.ndarray, known_occupied: np.ndarray, probability: np.ndarray) -> np.ndarray:
        """(H, W, 3) uint8 picture of a predicted map: the (X, Y) bool cells the robot knows free or
        occupied as in :meth:`background`, every other cell blended from :data:`PREDICTED_FREE` to
        :data:`PREDICTED_OCCUPIED` by its (X, Y) predicted occupancy `probability` (0 .. 1)."""
        import cv2

        p = np.clip(np.asarray(probability, np.float32), 0.0, 1.0)[..., None]
        image = ((1.0 - p) * np.asarray(PREDICTED_FREE, np.float32) + p * np.asarray(PREDICTED_OCCUPIED, np.float32))
        image = image.round().astype(np.uint8)
        image[known_free] = FREE
        image[known_occupied] = OCCUPIED
        image = np.ascontiguousarray(np.transpose(image, (1, 0, 2))[::-1])  # rows: +y up
        return cv2.resize(image, self.size, interpolation=cv2.INTER_NEAREST)

    def draw(self, image: np.ndarray, path_xy: np.ndarray, robot_xy: np.ndarray, robot_yaw: float,
             frontiers, goal_id: int | None, gain_colour) -> np.ndarray:
        """Draw the path, frontiers (dot + arrow along the view direction, coloured by `gain_colour(gain)`),
        the goal (ring) and the robot (dot + heading) onto a copy of `image`."""
        import cv2

        image = image.copy()
        thick = max(1, image.shape[0] // 240)
        if len(path_xy) > 1:
            cv2.polylines(image, [self.pixels(path_xy).reshape(-1, 1, 2)], False, PATH, thick, cv2.LINE_AA)
        arrow = 0.5 / self.cell_m * self.scale
        for frontier in frontiers:
            p = self.pixels(frontier.position[:2])[0]
            d = frontier.direction[:2] / max(np.linalg.norm(frontier.direction[:2]), 1e-9)
            q = (p + arrow * np.array([d[0], -d[1]])).astype(np.int32)
            colour = gain_colour(frontier.gain_m3)
            cv2.arrowedLine(image, tuple(map(int, p)), tuple(map(int, q)), colour, thick, cv2.LINE_AA, tipLength=0.3)
            cv2.circle(image, tuple(map(int, p)), 2 * thick + 1, colour, -1, cv2.LINE_AA)
            if frontier.id == goal_id:
                cv2.circle(image, tuple(map(int, p)), 5 * thick + 3, GOAL, thick + 1, cv2.LINE_AA)
        p = self.pixels(robot_xy)[0]
        q = (p + 0.6 / self.cell_m * self.scale * np.array([np.cos(robot_yaw), -np.sin(robot_yaw)])).astype(np.int32)
        cv2.arrowedLine(image, tuple(map(int, p)), tuple(map(int, q)), ROBOT, thick + 1, cv2.LINE_AA, tipLength=0.35)
        cv2.circle(image, tuple(map(int, p)), 3 * thick + 1, ROBOT, -1, cv2.LINE_AA)
        return image


def gain_colour_map(bin_edges, bin_unit_m3: float):
    """``gain_m3 -> (r, g, b)`` with the gain-class colours of the frontier overlay."""
    from ..frontiers.gain import gain_classes
    from ..model.overlay import gain_colours

    colours = gain_colours(len(bin_edges))

    def colour(gain_m3: float) -> tuple[int, int, int]:
        k = int(gain_classes(np.asarray([gain_m3]), bin_edges, bin_unit_m3)[0])
        return tuple(int(c) for c in colours[k])

    return colour


def label(image: np.ndarray, text: str) -> np.ndarray:
    """`image` with `text` in its top-left corner (white on a dark band)."""
    import cv2

    image = image.copy()
    height = max(18, image.shape[0] // 24)
    image[:height] = (image[:height] * 0.35).astype(np.uint8)
    cv2.putText(image, text, (6, int(height * 0.75)), cv2.FONT_HERSHEY_SIMPLEX, height / 32, (255, 255, 255), 1,
                cv2.LINE_AA)
    return image
