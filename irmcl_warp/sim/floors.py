"""Simulated floors nobody tuned on (issue 33): four kinds of building, each drawn from a seed, with a drive of
its own, and a fixed split into worlds for tuning and worlds only for testing.

* ``office``: a corridor with rooms on both sides (``world.office``), its sizes drawn from the seed;
* ``loop``: a square building of corridors around a closed core (the building where the filter once locked onto
  the wrong corridor), with a few niches and cabinets along the walls;
* ``hall``: an open hall cluttered with boxes and pillars (few long walls to align on);
* ``twin``: a floor whose walls repeat after a half turn about its centre (only its furniture breaks the
  symmetry): a scan alone cannot tell the two halves apart.

A world is named ``<kind>-<seed>``. ``SPLIT["tuning"]`` are the worlds settings and the confidence's calibration
may be chosen on; ``SPLIT["test"]`` are only for reporting. Seeds below 1000 are tuning seeds, from 1000 on test
seeds, so a world's name says which side it is on (``split_of``).

A drive is a random walk over a roadmap of free points (each at least ``clearance_m`` from every wall, joined by
straight lines that keep that clearance), so every kind gets a path without a hand-written route. A mapping drive
(``coverage_drive``) visits every point of the roadmap instead, so that its map covers every room a drive can enter.
"""

from __future__ import annotations

import copy

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from irmcl_warp.sim.world import World, _box, office

KINDS = ("office", "loop", "hall", "twin")
SPLIT = {
    "tuning": tuple(f"{k}-{s}" for k in KINDS for s in (1, 2)),
    "test": tuple(f"{k}-{s}" for k in KINDS for s in (1001, 1002)),
}
TEST_SEEDS_FROM = 1000


def parse(name: str) -> tuple[str, int]:
    """``"loop-1001"`` -> ("loop", 1001); a clear error for anything else."""
    kind, _, seed = name.rpartition("-")
    if kind not in KINDS or not seed.isdigit():
        raise ValueError(f"world {name!r}: expected <kind>-<seed> with kind one of {', '.join(KINDS)}")
    return kind, int(seed)


def split_of(name: str) -> str:
    return "test" if parse(name)[1] >= TEST_SEEDS_FROM else "tuning"


def build(name: str) -> World:
    kind, seed = parse(name)
    rng = np.random.default_rng(seed)
    return {"office": _office, "loop": _loop, "hall": _hall, "twin": _twin}[kind](rng, seed)


def _office(rng, seed) -> World:
    return office(
        seed,
        width_m=float(rng.uniform(24, 40)),
        height_m=float(rng.uniform(13, 18)),
        corridor_width_m=float(rng.uniform(2.0, 3.0)),
        furniture_per_room=int(rng.integers(1, 4)),
    )


def _rect(x0, y0, x1, y1):
    return [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]


def _loop(rng, seed) -> World:
    """Outer walls W x H, a closed core leaving corridors of width c all round; niches (small boxes cut into
    the walls' line of sight) and cabinets placed at random along the corridors."""
    W, H, c = float(rng.uniform(20, 32)), float(rng.uniform(16, 26)), float(rng.uniform(2.0, 3.0))
    segs = _rect(0, 0, W, H) + _rect(c, c, W - c, H - c)
    n_walls = len(segs)
    for _ in range(int(rng.integers(4, 9))):  # cabinets against the outer or the core's walls, 0.4-0.6 m deep
        w, d = float(rng.uniform(0.6, 1.6)), float(rng.uniform(0.4, 0.6))
        side, along = int(rng.integers(4)), float(rng.uniform(0.15, 0.85))
        outer = bool(rng.integers(2))
        if side in (0, 1):  # bottom / top corridor
            x = c + along * (W - 2 * c)
            y = (d / 2 if outer else c - d / 2) if side == 0 else (H - d / 2 if outer else H - c + d / 2)
            segs += _box(x, y, w, d)
        else:  # left / right corridor
            y = c + along * (H - 2 * c)
            x = (d / 2 if outer else c - d / 2) if side == 2 else (W - d / 2 if outer else W - c + d / 2)
            segs += _box(x, y, d, w)
    world = World(np.array(segs, float), [], H / 2, W, H, n_walls)
    world.solid = [(c, c, W - c, H - c)]  # the closed core: no drive inside
    return world


def _hall(rng, seed) -> World:
    W, H = float(rng.uniform(14, 24)), float(rng.uniform(10, 18))
    segs = _rect(0, 0, W, H)
    n_walls = len(segs)
    boxes = []
    for _ in range(400):
        if len(boxes) >= int(W * H / 12):
            break
        w, h = (float(v) for v in rng.uniform(0.3, 1.5, 2))
        cx, cy = float(rng.uniform(1.5, W - 1.5)), float(rng.uniform(1.5, H - 1.5))
        if any(abs(cx - bx) < (w + bw) / 2 + 1.2 and abs(cy - by) < (h + bh) / 2 + 1.2 for bx, by, bw, bh in boxes):
            continue  # keep aisles of at least 1.2 m between boxes
        boxes.append((cx, cy, w, h))
    for b in boxes:
        segs += _box(*b)
    return World(np.array(segs, float), [], H / 2, W, H, n_walls)


def _twin(rng, seed) -> World:
    """An office floor whose walls are repeated after a half turn about the floor's centre: the left half's
    rooms are the right half's, turned. Its furniture is drawn afresh for the whole floor (not repeated)."""
    half = office(
        seed,
        width_m=float(rng.uniform(12, 18)),
        height_m=float(rng.uniform(13, 16)),
        corridor_width_m=2.5,
        furniture_per_room=0,
    )
    W, H = 2 * half.width_m, half.height_m
    walls = [s for s in half.segments[: half.n_walls] if not (s[0] == s[2] == half.width_m)]  # drop the right wall
    turned = [(W - x0, H - y0, W - x1, H - y1) for x0, y0, x1, y1 in walls]
    segs = walls + turned
    n_walls = len(segs)
    rooms = []
    for r in half.rooms:  # the rooms and their turned twins, for the furniture
        rooms.append((r.x0, r.x1, r.y0, r.y1))
        rooms.append((W - r.x1, W - r.x0, H - r.y1, H - r.y0))
    for x0, x1, y0, y1 in rooms:
        if rng.random() < 0.5 and x1 - x0 > 2.0 and y1 - y0 > 2.0:
            w, h = (float(v) for v in rng.uniform(0.4, 1.0, 2))
            corner = int(rng.integers(4))  # in a corner away from the door side
            cx = x0 + 0.3 + w / 2 if corner % 2 == 0 else x1 - 0.3 - w / 2
            cy = y0 + 0.3 + h / 2 if corner < 2 else y1 - 0.3 - h / 2
            segs += _box(cx, cy, w, h)
    return World(np.array(segs, float), [], H / 2, W, H, n_walls)


# --- drives ------------------------------------------------------------------------------------------------


def distance_to_segments(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distance of each point [n, 2] to the nearest segment [K, 4] (x0 y0 x1 y1): [n]."""
    p = np.asarray(points, float)[:, None, :]
    a, b = segments[None, :, :2], segments[None, :, 2:]
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, -1) / np.maximum(np.sum(ab * ab, -1), 1e-12), 0.0, 1.0)
    return np.min(np.linalg.norm(a + t[..., None] * ab - p, axis=-1), axis=1)


def _clear(world: World, p, q, clearance_m: float, step_m: float = 0.1) -> bool:
    n = max(2, int(np.ceil(np.hypot(*(q - p)) / step_m)) + 1)
    line = p + np.linspace(0, 1, n)[:, None] * (q - p)
    return bool(distance_to_segments(line, world.segments).min() >= clearance_m)


def roadmap(world: World, rng, clearance_m: float = 0.3, num_nodes: int = 300, link_m: float = 4.0):
    """Free points (inside the outer walls, outside the world's closed cores, ``clearance_m`` from every
    segment) and the straight links between those less than ``link_m`` apart that keep the clearance:
    (nodes [n, 2], a sparse matrix of link lengths). A link's clearance is checked every 0.1 m, so between
    those checks it may come as close as ``clearance_m`` - 0.05 m (no point lies farther than 0.05 m from one)."""
    nodes = []
    for _ in range(40):
        cand = rng.uniform([0.0, 0.0], [world.width_m, world.height_m], (num_nodes * 4, 2))
        ok = distance_to_segments(cand, world.segments) >= clearance_m
        for x0, y0, x1, y1 in getattr(world, "solid", ()):
            ok &= ~((cand[:, 0] > x0) & (cand[:, 0] < x1) & (cand[:, 1] > y0) & (cand[:, 1] < y1))
        nodes += list(cand[ok])
        if len(nodes) >= num_nodes:
            break
    nodes = np.array(nodes[:num_nodes])
    if len(nodes) < 2:
        raise ValueError("the world has no free space for a drive")
    d = np.linalg.norm(nodes[:, None] - nodes[None], axis=-1)
    links = np.zeros_like(d)
    for i, j in zip(*np.nonzero(np.triu(d < link_m, 1))):
        if _clear(world, nodes[i], nodes[j], clearance_m):
            links[i, j] = links[j, i] = d[i, j]
    return nodes, csr_matrix(links)


def _largest_part(world: World, rng, clearance_m: float, num_nodes: int = 300):
    """A roadmap of the world (``roadmap``) and the nodes of its largest connected part: (nodes, links, part)."""
    nodes, links = roadmap(world, rng, clearance_m, num_nodes=num_nodes)
    _, label = connected_components(links, directed=False)
    part = np.flatnonzero(label == np.bincount(label).argmax())
    if len(part) < 2:
        raise ValueError("the world's roadmap has no link: no drive possible")
    return nodes, links, part


def _steps(pred: np.ndarray, at: int, goal: int) -> list[int]:
    """The nodes after ``at`` on the shortest path to ``goal``, in order (``pred``: dijkstra's predecessors)."""
    path = [goal]
    while path[-1] != at:
        path.append(int(pred[path[-1]]))
    return path[-2::-1]


def drive(world: World, rng, length_m: float, clearance_m: float = 0.3) -> np.ndarray:
    """Waypoints [k, 2] of a drive ``length_m`` long: from a random node of the largest connected part of the
    roadmap to random goals in it, each by the shortest path (so the robot crosses the building rather than
    circling one spot)."""
    nodes, links, part = _largest_part(world, rng, clearance_m)
    at = int(rng.choice(part))
    points, travelled = [nodes[at]], 0.0
    while travelled < length_m:
        goal = int(rng.choice(part[part != at]))
        _, pred = dijkstra(links, indices=at, return_predecessors=True)
        for i in _steps(pred, at, goal):
            travelled += float(np.hypot(*(nodes[i] - points[-1])))
            points.append(nodes[i])
            if travelled >= length_m:
                break
        at = goal
    return np.array(points)


def coverage_drive(world: World, rng, clearance_m: float = 0.3, num_nodes: int = 600) -> np.ndarray:
    """Waypoints [k, 2] of a drive that passes every node of the largest connected part of a dense roadmap: from a
    random node, always on to the nearest node not yet passed (by the shortest path), so that a map of its scans
    covers every room a drive can enter. (A random drive of fixed length left whole rooms unmapped, and so did a
    roadmap of 300 nodes, whose links missed some doors: twin-1002's had two rooms apart from the rest.)"""
    nodes, links, part = _largest_part(world, rng, clearance_m, num_nodes)
    at = int(rng.choice(part))
    passed = np.zeros(len(nodes), bool)
    passed[at] = True
    points = [nodes[at]]
    while not passed[part].all():
        dist, pred = dijkstra(links, indices=at, return_predecessors=True)
        left = part[~passed[part]]
        goal = int(left[np.argmin(dist[left])])
        for i in _steps(pred, at, goal):
            points.append(nodes[i])
            passed[i] = True
        at = goal
    return np.array(points)


# --- what the map does not hold ----------------------------------------------------------------------------

UNMAPPED_SIZE_M = (0.3, 0.8)  # an unmapped object's sides (a person, a bin, a chair, a moved box), drawn uniformly
UNMAPPED_FROM_PATH_M = (0.6, 3.0)  # how far from the drive's path it stands, drawn uniformly


def outline(centre, w: float, h: float, step_m: float = 0.05) -> np.ndarray:
    """Points [n, 2] along the sides of the box ``w`` x ``h`` about ``centre``, ``step_m`` apart or closer."""
    t = np.linspace(0.0, 1.0, max(2, int(np.ceil(max(w, h) / step_m)) + 1))[:, None]
    corners = np.asarray(centre, float) + 0.5 * np.array([[-w, -h], [w, -h], [w, h], [-w, h], [-w, -h]])
    return np.vstack([a + t * (b - a) for a, b in zip(corners[:-1], corners[1:])])


def with_unmapped(world: World, path_xy: np.ndarray, rng, per_m: float) -> World:
    """``world`` with objects its map does not hold, for a drive along the waypoints ``path_xy`` [k, 2]: about
    ``per_m`` objects per metre of the drive, each a box of UNMAPPED_SIZE_M sides standing UNMAPPED_FROM_PATH_M
    from a random point of the path, in free space (its centre 0.3 m from every segment) and never on the path
    (its sides at least the roadmap's clearance, 0.3 m, from the path's lines). Real logs have them (people, moved
    furniture, clutter: MIT Killian's scans fit its own SLAM map at the SLAM pose below 0.8 at 12 % of the scans),
    where the simulated floors' drives see only what was mapped. ``per_m`` 0 returns ``world`` itself."""
    if per_m <= 0 or len(path_xy) < 2:
        return world
    path = np.asarray(path_xy, float)
    legs = np.column_stack([path[:-1], path[1:]])
    lengths = np.hypot(*(path[1:] - path[:-1]).T)
    want = int(round(per_m * lengths.sum()))
    boxes = []
    for _ in range(20 * want):
        if len(boxes) >= want:
            break
        leg = int(rng.choice(len(legs), p=lengths / lengths.sum()))
        at = path[leg] + rng.uniform() * (path[leg + 1] - path[leg])
        heading, dist = rng.uniform(-np.pi, np.pi), rng.uniform(*UNMAPPED_FROM_PATH_M)
        w, h = (float(v) for v in rng.uniform(*UNMAPPED_SIZE_M, 2))
        c = at + dist * np.array([np.cos(heading), np.sin(heading)])
        if distance_to_segments(c[None], world.segments)[0] < 0.3:
            continue  # in or against a wall
        if distance_to_segments(outline(c, w, h), legs).min() < 0.3:
            continue  # on the way
        boxes.append((float(c[0]), float(c[1]), w, h))
    extra = [s for b in boxes for s in _box(*b)]
    out = copy.copy(world)  # (every attribute, the loop's closed core ``solid`` too)
    out.segments = np.vstack([world.segments, np.array(extra, float).reshape(-1, 4)])
    out.n_walls = world.n_walls if world.n_walls >= 0 else len(world.segments)  # the objects count as furniture
    return out
