"""Rounds of samples within a deadline (addon/core/display/sample_rounds.py): the first round always, then
the noisiest points of every source first, as many as the pace each source has shown leaves
time for; without a deadline, every noisy point, every round."""
import threading

import numpy as np

from addon.core.display import sample_rounds


class _Clock:
    """A clock that moves only when a fake source samples (its pace a sample)."""

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def _part(clock, pace, noise, log):
    """A source whose means are 0, whose errors are ``noise`` (n,) over the allowed until sampled
    again (then 0), and whose samples cost ``pace`` seconds each on ``clock``."""
    error = np.asarray(noise, np.float64).copy()

    def sample(rows, count):
        clock.now += pace * rows.size * count
        log.append((pace, rows.copy(), count))
        out = error[rows].copy()
        error[rows] = 0.0
        return np.zeros((rows.size, 3)), out

    return sample_rounds.Part(sample, lambda mean, err: err)


def test_a_deadline_takes_the_noisiest_points_of_every_source_first_and_the_first_round_always(monkeypatch):
    clock = _Clock()
    monkeypatch.setattr(sample_rounds.time, "perf_counter", clock)
    log = []
    cheap = _part(clock, 1e-3, [0.5, 3.0, 9.0, 2.0], log)  # (error over the allowed; above 1: noisy)
    dear = _part(clock, 4e-3, [5.0, 0.2, 1.5, 8.0], log)
    spent = sample_rounds.Spent()
    # first round: 16 samples each, 4 x 16 x (1e-3 + 4e-3) = 0.32 s; the second round's 128 samples
    # cost 0.128 s a point of the cheap source, 0.512 of the dear one: the 1.0 s left takes the
    # cheap one's 9.0 and the dear one's 8.0 (0.64 s), not the dear one's 5.0 (0.512 more would pass
    # it), then the cheap one's 3.0 and 2.0 (0.256); the third round's 1,024 samples fit nowhere
    sample_rounds.rounds([cheap, dear], 4, 16, retries=2, more=8, deadline=1.32, spent=spent)
    assert [(pace, count) for pace, _, count in log[:2]] == [(1e-3, 16), (4e-3, 16)]
    again = {pace: rows.tolist() for pace, rows, count in log[2:]}
    assert again == {1e-3: [1, 2, 3], 4e-3: [3]}
    assert clock.now <= 1.32 + 1e-12 and spent.samples == 8 * 16 + 4 * 128
    assert abs(spent.first - 0.32) < 1e-12 and abs(spent.seconds - clock.now) < 1e-12


def test_without_a_deadline_every_noisy_point_is_sampled_again_each_round(monkeypatch):
    clock = _Clock()
    monkeypatch.setattr(sample_rounds.time, "perf_counter", clock)
    log = []
    part = _part(clock, 1e-3, [0.5, 3.0, 9.0, 2.0], log)
    sample_rounds.rounds([part], 4, 16, retries=2, more=8)
    assert [(rows.tolist(), count) for _, rows, count in log] == [([0, 1, 2, 3], 16), ([1, 2, 3], 128)]


def _box_of_lamps_and_an_emitter():
    """A closed box of 6 x 6 patches a face, an emitting ceiling patch and two point lamps in
    two groups (the emitter with the second): (scene, surface, the groups' keywords)."""
    from boxes import small_source_box

    from addon.core import PatchScene
    from addon.core.display import smoothing
    from addon.core.lights.lights import PointLight

    box, _ = small_source_box(n=6)
    lamps = [PointLight(np.array([0.3, 0.4, 0.7]), np.full(3, 0.5)), PointLight(np.array([0.7, 0.6, 0.3]), np.full(3, 0.2))]
    scene = PatchScene(box.vertices, box.triangles, box.triangle_patch, box.reflectivity, box.emission, lights=lamps)
    surface = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch, scene.patch_count)
    groups = dict(light_group=np.array([0, 1]), patch_group=(scene.emission.sum(axis=1) > 0).astype(np.int64), groups=2)
    return scene, surface, groups


def test_the_blocks_of_samples_are_shared_among_two_threads_and_give_the_same_bits_as_one(monkeypatch):
    """The display's direct light at the corners of a box with two lamps and an emitter, in two
    groups, retries included, blocks of 256 samples: with two local threads the blocks are traced
    on both at once (the first block of each waits for the other's: a barrier of 2), and the
    corners and means are bit for bit those of one thread (a block's random numbers are drawn in
    the blocks' order whichever thread takes it). (The first two threads that trace wait for each
    other; every source's blocks start a pool of their own.)"""
    from addon.core.display import point_direct
    from addon.core.distributed import runners
    from addon.core.methods.tables import WalkTables

    scene, surface, groups = _box_of_lamps_and_an_emitter()
    monkeypatch.setattr(sample_rounds, "BLOCK_SAMPLES", 256)
    with runners.local_threads(1):
        one = point_direct.corner_direct(surface, scene, scene.triangles, seed=4, **groups)
    meet, threads = threading.Barrier(2, timeout=20), set()
    traced = WalkTables.outside_turn

    def outside_turn(tables, trace, *rays):
        ident = threading.get_ident()
        if len(threads) < 2 and ident not in threads:  # (the calling thread takes a share too)
            threads.add(ident)
            meet.wait()
        return traced(tables, trace, *rays)

    monkeypatch.setattr(WalkTables, "outside_turn", outside_turn)
    with runners.local_threads(2):
        two = point_direct.corner_direct(surface, scene, scene.triangles, seed=4, **groups)
    assert len(threads) == 2
    assert one.corners.shape == two.corners.shape == (2, len(scene.triangles), 3, 3) and one.corners.any()
    assert np.array_equal(one.corners, two.corners) and np.array_equal(one.means, two.means)


def test_two_threads_share_each_block_so_the_samples_in_flight_stay_one_blocks(monkeypatch):
    """Two local threads hold no more samples at once than one: each block of BLOCK_SAMPLES is
    cut into a piece a thread (two blocks side by side raised the 162,560-patch command line's
    peak by 11-17 MiB), each piece whole points' samples."""
    from addon.core.display import point_direct
    from addon.core.distributed import runners

    scene, surface, _ = _box_of_lamps_and_an_emitter()
    monkeypatch.setattr(sample_rounds, "BLOCK_SAMPLES", 256)
    sizes, sampled = [], sample_rounds.sampled

    def counted(tables, n, samples, rng, add, *rest, **kwargs):
        def adding(tables, points, u, value):
            sizes.append(u.shape[1])
            return add(tables, points, u=u, value=value)
        return sampled(tables, n, samples, rng, adding, *rest, **kwargs)

    monkeypatch.setattr(point_direct, "sampled", counted)
    with runners.local_threads(2):
        point_direct.corner_direct(surface, scene, scene.triangles, seed=4)
    assert sizes and max(sizes) <= 128 and sum(sizes) % point_direct.SAMPLES == 0

