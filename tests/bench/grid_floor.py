"""A square floor of square rooms, for step cost against floor size (issue 55 item 2).

    .venv/bin/python tests/bench/grid_floor.py OUT.png SIZE_M [ROOM_M]

Writes a floor plan image (0.05 m/px; white free, black walls): SIZE_M x SIZE_M metres of
ROOM_M (default 5) rooms with 0.2 m walls, each room with a 1 m door in its east and north walls
(the outer wall closed). Explore it as ``floorplan:OUT.png?resolution=0.05``; a 10 m and a 60 m
floor are the same building at two sizes, so a step's cost can be compared across them
(``frontiernet bench explore --scene ...``).
"""

from __future__ import annotations

import sys

import cv2
import numpy as np

RESOLUTION = 0.05  # metres per pixel
WALL_M, DOOR_M = 0.2, 1.0


def grid_floor(size_m: float, room_m: float = 5.0) -> np.ndarray:
    """(H, W) uint8 plan: 255 free, 0 wall."""
    px = lambda metres: int(round(metres / RESOLUTION))  # noqa: E731
    n, wall, door = px(size_m), px(WALL_M), px(DOOR_M)
    plan = np.full((n + 2 * wall, n + 2 * wall), 255, np.uint8)
    plan[:wall], plan[-wall:], plan[:, :wall], plan[:, -wall:] = 0, 0, 0, 0
    rooms = max(1, int(round(size_m / room_m)))
    step = n / rooms
    for k in range(1, rooms):
        c = wall + int(round(k * step))
        plan[c - wall // 2:c + wall - wall // 2, :] = 0  # a wall line across, with a door per room
        plan[:, c - wall // 2:c + wall - wall // 2] = 0
    for i in range(rooms):
        for k in range(1, rooms):
            c = wall + int(round(k * step))
            middle = wall + int(round((i + 0.5) * step))
            plan[c - wall:c + wall, middle - door // 2:middle + door // 2] = 255
            plan[middle - door // 2:middle + door // 2, c - wall:c + wall] = 255
    return plan


if __name__ == "__main__":
    out, size = sys.argv[1], float(sys.argv[2])
    room = float(sys.argv[3]) if len(sys.argv) > 3 else 5.0
    cv2.imwrite(out, grid_floor(size, room))
    print(out)
