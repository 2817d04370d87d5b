"""Procedural office floor plans as wall segments: a corridor with rooms on both sides, a door per room
and furniture. ``repetitive=True`` gives every room the same width, door and furniture: a long corridor
of look-alike bays, where a scan alone cannot tell places apart (perceptual aliasing)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Room:
    x0: float
    x1: float
    y0: float
    y1: float
    door_x: float
    door_y: float  # on the corridor wall

    @property
    def centre(self):
        return np.array([(self.x0 + self.x1) / 2, (self.y0 + self.y1) / 2])


@dataclass
class World:
    segments: np.ndarray  # [K, 4] x0 y0 x1 y1
    rooms: list = field(default_factory=list)
    corridor_y: float = 0.0
    width_m: float = 0.0
    height_m: float = 0.0
    n_walls: int = -1  # segments[:n_walls] are full-height walls, the rest furniture (-1: all walls)


def _box(cx, cy, w, h):
    x0, x1, y0, y1 = cx - w / 2, cx + w / 2, cy - h / 2, cy + h / 2
    return [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]


def _wall_with_doors(y, x_from, x_to, doors, door_w):
    segs, x = [], x_from
    for dx in sorted(doors):
        segs.append((x, y, dx - door_w / 2, y))
        x = dx + door_w / 2
    segs.append((x, y, x_to, y))
    return segs


def _room_widths(rng, width, wmin, wmax, repetitive):
    if repetitive:
        n = max(1, int(width // wmin))
        return [width / n] * n
    widths, left = [], width
    while left > wmax and left >= 2 * wmin:  # every room, the last one too, is at least wmin wide
        widths.append(float(rng.uniform(wmin, min(wmax, left - wmin))))
        left -= widths[-1]
    return widths + [left]


def _furniture(rng, room: Room, count, door_w, repetitive_template=None):
    """Boxes inside a room, clear of the walls and of the straight path door -> centre."""
    if repetitive_template is not None:
        return [(room.x0 + fx, room.y0 + fy, w, h) for fx, fy, w, h in repetitive_template]
    boxes, tries = [], 0
    lane = (room.door_x, room.centre[0])
    while len(boxes) < count and tries < 200:
        tries += 1
        w, h = rng.uniform(0.4, 1.2, size=2)
        cx = rng.uniform(room.x0 + 0.3 + w / 2, room.x1 - 0.3 - w / 2) if room.x1 - room.x0 > w + 0.6 else None
        cy = rng.uniform(room.y0 + 0.3 + h / 2, room.y1 - 0.3 - h / 2) if room.y1 - room.y0 > h + 0.6 else None
        if cx is None or cy is None:
            continue
        if min(lane) - door_w < cx + w / 2 and cx - w / 2 < max(lane) + door_w:  # keep the walking lane free
            continue
        if any(abs(cx - bx) < (w + bw) / 2 + 0.3 and abs(cy - by) < (h + bh) / 2 + 0.3 for bx, by, bw, bh in boxes):
            continue
        boxes.append((cx, cy, w, h))
    return boxes


def office(
    seed: int,
    width_m=30.0,
    height_m=16.0,
    corridor_width_m=2.5,
    room_min_width_m=3.5,
    room_max_width_m=6.0,
    door_width_m=1.0,
    furniture_per_room=2,
    repetitive=False,
) -> World:
    rng = np.random.default_rng(seed)
    yc0, yc1 = height_m / 2 - corridor_width_m / 2, height_m / 2 + corridor_width_m / 2
    segs = [(0, 0, width_m, 0), (width_m, 0, width_m, height_m), (width_m, height_m, 0, height_m), (0, height_m, 0, 0)]
    rooms, template = [], None
    for y0, y1, door_y in ((0.0, yc0, yc0), (yc1, height_m, yc1)):
        x = 0.0
        doors = []
        for w in _room_widths(rng, width_m, room_min_width_m, room_max_width_m, repetitive):
            margin = min(door_width_m, w / 2)
            door_x = x + w / 2 if repetitive else float(rng.uniform(x + margin, x + w - margin))
            rooms.append(Room(x, x + w, y0, y1, door_x, door_y))
            doors.append(door_x)
            if x > 0:
                segs.append((x, y0, x, y1))
            x += w
        segs += _wall_with_doors(door_y, 0.0, width_m, doors, door_width_m)
    n_walls = len(segs)
    for room in rooms:
        boxes = _furniture(rng, room, furniture_per_room, door_width_m, template)
        if repetitive and template is None:
            template = [(cx - room.x0, cy - room.y0, w, h) for cx, cy, w, h in boxes]
        for b in boxes:
            segs += _box(*b)
    return World(np.array(segs, dtype=np.float64), rooms, height_m / 2, width_m, height_m, n_walls)
