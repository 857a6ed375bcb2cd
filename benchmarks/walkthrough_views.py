"""Where the walkthrough's cameras stand and where they look (numpy only): a camera stands in the
room's air (the union of boxes), clear of its walls and of what stands in it (furniture, lamps:
boxes), as someone walking through would; views placed by hand are checked, and the existing
interiors' views are placed here (``auto_views``).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

CLEARANCE = 0.25  # metres a camera keeps from walls and furniture (a person's head, half a step)


@dataclass(frozen=True)
class View:
    """A camera at ``location`` looking at ``target`` (up +Z) with a ``lens`` in mm (36 mm sensor)."""

    location: tuple
    target: tuple
    lens: float = 18.0
    label: str = ""

    @property
    def direction(self):
        d = np.subtract(self.target, self.location).astype(float)
        return d / np.linalg.norm(d)


def inside(points, boxes):
    """(N,) whether each point lies in at least one of the (lo, hi) boxes (faces included)."""
    points = np.atleast_2d(np.asarray(points, float))
    found = np.zeros(len(points), bool)
    for lo, hi in boxes:
        found |= ((points >= np.asarray(lo, float)) & (points <= np.asarray(hi, float))).all(axis=1)
    return found


def box_distance(point, box):
    """Distance from a point to an axis-aligned (lo, hi) box: 0 inside."""
    lo, hi = (np.asarray(c, float) for c in box)
    p = np.asarray(point, float)
    return float(np.linalg.norm(np.maximum(np.maximum(lo - p, 0.0), p - hi)))


def placement_problems(location, air, obstacles, clearance=CLEARANCE):
    """What is wrong with a camera at ``location``: outside the air, nearer than ``clearance`` to
    its walls (a cube of that half-size about it leaves the air's union: checked at its corners,
    edges' and faces' middles), or to an obstacle; [] where it is fine."""
    p = np.asarray(location, float)
    problems = []
    if not inside(p, air)[0]:
        return ["outside the room"]
    offsets = np.array(list(itertools.product((-clearance, 0.0, clearance), repeat=3)))
    if not inside(p + offsets, air).all():
        problems.append(f"within {clearance:g} m of a wall, floor or ceiling")
    for k, box in enumerate(obstacles):
        d = box_distance(p, box)
        if d < clearance:
            problems.append(f"inside obstacle {k}" if d == 0 else f"within {clearance:g} m of obstacle {k} ({d:.2f} m)")
    return problems


def spans_room(box, room, share=0.9):
    """Whether a (lo, hi) box spans ``share`` of the room's extent along two axes or more (a
    wall, the floor, the ceiling: not furniture)."""
    extent = np.subtract(box[1], box[0])
    room_extent = np.subtract(room[1], room[0])
    return int((extent >= share * room_extent).sum()) >= 2


def wall_middles(room, height=1.0):
    """The middles of a box room's four walls at ``height`` (targets to look at)."""
    (x0, y0, _), (x1, y1, _) = room
    xm, ym = (x0 + x1) / 2, (y0 + y1) / 2
    return [np.array(p, float) for p in ((xm, y0, height), (xm, y1, height), (x0, ym, height), (x1, ym, height))]


def candidates(air, obstacles, eye=1.6, step=0.25, clearance=CLEARANCE):
    """(N,3) points of a grid of ``step`` at height ``eye`` over the air where a camera may stand."""
    lo = np.min([np.asarray(b[0], float) for b in air], axis=0)
    hi = np.max([np.asarray(b[1], float) for b in air], axis=0)
    xs = np.arange(lo[0] + step / 2, hi[0], step)
    ys = np.arange(lo[1] + step / 2, hi[1], step)
    grid = [(x, y, eye) for x in xs for y in ys]
    return np.array([p for p in grid if not placement_problems(p, air, obstacles, clearance)]).reshape(-1, 3)


def spread(points, count, start):
    """Indices of ``count`` points spread apart: the one nearest ``start``, then each next the
    farthest from those taken (a walk's stops round the room, several near its walls)."""
    points = np.asarray(points, float)
    taken = [int(np.argmin(np.linalg.norm(points - np.asarray(start, float), axis=1)))]
    nearest = np.linalg.norm(points - points[taken[0]], axis=1)
    while len(taken) < count:
        k = int(np.argmax(nearest))
        taken.append(k)
        nearest = np.minimum(nearest, np.linalg.norm(points - points[k], axis=1))
    return taken


def auto_views(air, obstacles, targets, count, eye=1.6, lens=18.0, near=1.5):
    """``count`` views spread over the air (``spread``), each looking at one of ``targets`` (lamps,
    walls' middles) at least ``near`` metres away along the floor, the least looked-at first,
    then the farthest. ValueError where the room has not room for them."""
    points = candidates(air, obstacles, eye)
    if len(points) < count:
        raise ValueError(f"only {len(points)} places for a camera clear of walls and furniture; {count} views asked")
    start = np.min([np.asarray(b[0], float) for b in air], axis=0)
    targets = [np.asarray(t, float) for t in targets]
    used = np.zeros(len(targets), int)
    views = []
    for k, i in enumerate(spread(points, count, start)):
        p = points[i]
        along = np.array([np.linalg.norm((t - p)[:2]) for t in targets])
        far = along >= near
        pool = np.flatnonzero(far) if far.any() else np.arange(len(targets))
        best = min(pool, key=lambda j: (used[j], -along[j]))
        used[best] += 1
        views.append(View(tuple(p), tuple(targets[best]), lens, f"placed {k + 1}"))
    return views


def compass(view, sectors=8):
    """The sector (0..sectors-1, 0 east, counter-clockwise) the view looks towards along the floor."""
    d = view.direction
    angle = np.arctan2(d[1], d[0]) % (2 * np.pi)
    return int(np.floor(angle / (2 * np.pi / sectors) + 0.5)) % sectors
