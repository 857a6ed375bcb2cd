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
