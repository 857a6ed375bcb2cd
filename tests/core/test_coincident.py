"""core coincident: which coplanar triangles a hit must test, and what it counts there."""
import numpy as np

from addon.core.scene.coincident import Contacts


def grid_triangles(n, z=0.0, flip=False):
    """An n x n grid of unit squares in the plane z, two triangles a square, (2 n^2, 3, 3)."""
    out = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = (i, j, z), (i + 1, j, z), (i + 1, j + 1, z), (i, j + 1, z)
            out += [(a, b, c), (a, c, d)] if not flip else [(a, c, b), (a, d, c)]
    return np.array(out, dtype=np.float64) * 0.1


def test_a_grids_neighbours_are_not_pairs_but_faces_lying_on_it_are():
    """A grid's triangles share edges and corners (their bounding boxes meet) but no inside: a hit
    on one has nothing to test. Before, every neighbour was a pair (a 4 x 4 grid: 32 triangles,
    hundreds of tests for nothing). A second grid lying on it, shifted half a square and facing
    the other way, pairs each triangle with the ones it overlaps, and a hit counts them."""
    alone = Contacts(grid_triangles(4))
    assert alone.partner.size == 0 and not alone.any
    under = grid_triangles(4)
    over = grid_triangles(2, flip=True) + np.array([0.05, 0.05, 0.0])
    both = Contacts(np.concatenate([under, over]))
    assert both.any
    first = np.repeat(np.arange(len(both.first) - 1), np.diff(both.first))
    assert set(range(len(under), len(under) + len(over))) <= set(first.tolist())  # each over triangle
    assert not {len(under) - 2, len(under) - 1} & set(first.tolist())  # the far square's: nothing on them
    # a hit at the centre of the over grid's first square (0.1, 0.1) lies inside under-triangles of
    # the square (1,1) and inside the over-triangle (a,c,b) there: counted -1 (facing the other way)
    point = np.array([[0.11, 0.105, 0.0]])
    hit = next(t for t in range(len(under)) if _inside(under[t], point[0]))
    assert both.faces_at(np.array([hit]), point)[0] == 0  # itself, minus the face over it
    edge = np.array([[0.1, 0.07, 0.0]])  # on an under edge, inside an over triangle: counted once
    assert both.faces_at(np.array([0]), edge)[0] == 0


def _inside(tri, p):
    e1, e2, w = tri[1] - tri[0], tri[2] - tri[0], p - tri[0]
    m = np.array([[e1 @ e1, e1 @ e2], [e1 @ e2, e2 @ e2]])
    v, u = np.linalg.solve(m, [w @ e1, w @ e2])
    return v > 0 and u > 0 and u + v < 1


def test_a_slabs_grid_of_partners_counts_what_testing_every_partner_counts():
    """A slab (two triangles) under 36 small squares facing either way, and a tilted slab under
    them too: a hit tests only the partners filed in its cell of the slab's grid, and counts what
    testing every partner of its triangle counts, at 5,000 random points, on the squares' edges
    and corners as well."""
    rng = np.random.default_rng(7)
    slab = np.array([[(0, 0, 0), (1.2, 0, 0), (1.2, 1.2, 0)], [(0, 0, 0), (1.2, 1.2, 0), (0, 1.2, 0)]], float)
    squares = grid_triangles(6) * 1.5 + np.array([0.1, 0.1, 0.0])  # (0.15 m squares)
    flipped = squares.copy()
    flip = rng.random(len(flipped)) < 0.5
    flipped[flip] = flipped[flip][:, ::-1]
    tilt = np.array([[1, 0, 0], [0, 0.8, -0.6], [0, 0.6, 0.8]])
    corners = np.concatenate([slab, flipped, slab @ tilt.T, flipped @ tilt.T])
    contacts = Contacts(corners)
    assert contacts.side.max() > 1  # (the slabs' partners are filed on grids)
    points = np.concatenate([rng.random((5000, 2)) * 1.2, squares[:, :, :2].reshape(-1, 2)])
    points = np.column_stack([points, np.zeros(len(points))])
    triangle = np.where(points[:, 0] > points[:, 1], 0, 1)
    for frame, first in ((np.eye(3), 0), (tilt, len(slab) + len(flipped))):
        at = points @ frame.T
        assert np.array_equal(contacts.faces_at(triangle + first, at), _every_partner(contacts, corners, triangle + first, at))


def _every_partner(contacts, corners, triangle, points):
    """faces_at by testing each hit against every partner of its triangle."""
    out = np.ones(len(triangle), np.int64)
    for k, (t, p) in enumerate(zip(triangle, points)):
        for r in range(contacts.first[t], contacts.first[t + 1]):
            tri = corners[contacts.partner[r]]
            w = p - contacts.origin[r]
            v, u = w @ contacts.to_v[r], w @ contacts.to_u[r]
            if 1e-6 < v < 1 - 1e-6 and u > 1e-6 and u + v < 1 - 1e-6:
                out[k] += 1 if contacts.same[r] else -1
    return out
