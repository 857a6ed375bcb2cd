"""The paper's method: shooting random walks, path by path (``walk``), its direct light shot
by the walks (the paper's) or gathered by shadow rays (``first_shot``, beyond the paper).

Its estimator (finite or biased infinite) and exit point (random or hit) are the walk tables'
(``tables``); here is what a solve plans for it. With the direct light shot, the paper's
formulas (2)/(3) predict its error and the paths for a target; gathered, they do not (it needs
several times fewer: the plan takes base.UNPREDICTED_PLAN_DIVISOR of them), and its error is
measured. Small chunks of the shot walk are traced together in groups (one wavefront).

The walk is a wavefront of named stages.

A batch of paths ("chunk") is traced as a wavefront: every live path advances one bounce per
step, and the live paths' rays go to the ray tracer together. Each step runs the same stages:

    refill          new paths from the sources (emissive patches, lights) take the places of
                    ended ones
    generate        each live path's next ray: from its source's own distribution of points
                    and directions at the start, then cosine-distributed from the patch it hit
    intersect       the ray tracer: what each ray meets first
    handle_escaped  rays that hit nothing escape; rays that hit a back side are absorbed there
    score           the power a path carries scores on the patch it hit
    survive_or_cut  the estimator's rule (``estimators``): finite paths survive with R_bar,
                    biased paths carry R and end below the threshold t

until the chunk's paths have all ended. Small chunks go through in groups: one wavefront, each
path tagged with its chunk, every chunk with its own tallies. The stages run on one of two
states: :class:`.path_walk.PathWalk` (paths as arrays of what they carry) or, for the paper's
plain walk whose paths are interchangeable, :class:`.interchangeable.InterchangeableWalk`.
With the direct light gathered (``first_shot``), each chunk first gathers every patch's direct
light by shadow rays, then runs these stages from what the patches reflect of it. Which chunks
a solve runs, and with what, is its method's (``methods``).
"""
from __future__ import annotations

from .first_shot import gather_samples
from .gathered_walk import gathered_chunk
from ..names import GATHERED, SHOT, WALK
from .two_way import rays_per_path as gathered_rays_per_path
from .base import GatheringIntegrator, Integrator, Method, check, solve_gathering, spec_gathering
from .interchangeable import InterchangeableWalk
from .path_walk import PathWalk
from .tables import chunk_wide

# Grouped chunks: up to GROUP_MAX_CHUNKS chunks (a power of two, so that a run of MIN_CHUNKS
# chunks makes an even number of tasks) are traced as one wavefront while a group has fewer rays
# than GROUP_RAYS (GROUP_RAYS_COUNTED for interchangeable paths, whose steps also pass over the
# patches), and its scores take at most GROUP_SCORES float64s.
GROUP_RAYS = 1 << 16
GROUP_RAYS_COUNTED = 1 << 18
GROUP_MAX_CHUNKS = 16
GROUP_SCORES = 1 << 22


class Walk(Method):
    """The paper's shooting random walk."""

    name = WALK
    direct_lights = (SHOT, GATHERED)

    @property
    def predicted(self):
        return self.direct_light == SHOT

    def planned_paths(self, predicted_paths):
        return predicted_paths if self.predicted else super().planned_paths(predicted_paths)

    def rays_per_path(self, bounces):
        # (gathered, guessed as the two-way iteration's: its gathering costs about as much)
        return super().rays_per_path(bounces) if self.direct_light == SHOT else gathered_rays_per_path(bounces)

    def create(self, scene, tables, chunk, seed, prediction):
        if self.direct_light == SHOT:
            return self.shot(tables)
        samples = gather_samples(chunk, prediction.expected_path_length, scene)
        return Gathered(tables, solve_gathering(scene, tables, samples, seed), self.one_chunk)

    def rebuild(self, scene, tables, spec):
        if spec is None:
            return self.shot(tables)
        return Gathered(tables, spec_gathering(scene, spec), self.one_chunk)

    # What a subclass with chunks of its own (Jacobi) replaces: its integrator with the direct
    # light shot, and one chunk from given sources (what the gathered variant runs).
    def shot(self, tables):
        return ShotWalk(tables)

    @staticmethod
    def one_chunk(tables, paths, rng, abort):
        return walk_one(tables, paths, rng, abort)


class ShotWalk(Integrator):
    """The paper's walk: its tables alone."""

    def group(self, chunk_paths, expected_path_length):
        group_rays = GROUP_RAYS_COUNTED if self.tables.speedups.interchangeable else GROUP_RAYS
        return chunks_per_group(self.tables, max(1.0, chunk_paths * expected_path_length), group_rays)

    def run(self, sizes, rng, abort=None):
        return walk_chunks(self.tables, sizes, rng, abort)


def walk_one(tables, paths, rng, abort):
    """One chunk of the paper's walk (from the sources ``tables`` has), in the caller's turn."""
    return run_stages(tables, [paths], rng, abort)[0]


class Gathered(GatheringIntegrator):
    """A walk whose chunks first gather every patch's direct light (``gathering``), then walk
    from its reflection (``walk(tables, paths, rng, abort)``, a chunk's tally)."""

    def __init__(self, tables, gathering, walk):
        super().__init__(tables, gathering)
        self.walk = walk

    def run(self, sizes, rng, abort=None):
        tables = chunk_wide(self.tables, sum(int(n) for n in sizes))
        walk = self.walk
        tallies = []
        with tables.numpy_turn:
            for n in sizes:
                check(abort)
                tallies.append(gathered_chunk(tables, self.gathering, int(n), rng,
                                              lambda t, paths, r: walk(t, paths, r, abort)))
        return tallies


def chunks_per_group(tables, chunk_rays, group_rays):
    """How many chunks of ``chunk_rays`` a task traces together: 1 unless the chunks are small
    and grouped chunks are on, else a power of two, up to ``group_rays`` rays a group. It
    depends on the walk and the chunk plan alone, never on the threads, so runs stay bitwise
    reproducible."""
    if not tables.speedups.grouped_chunks:
        return 1
    sources = 1 if tables.groups is None else tables.groups.count  # (per source: a chunk's scores S times over)
    by_scores = GROUP_SCORES // (tables.channels * tables.patch_count * sources)
    most = int(min(GROUP_MAX_CHUNKS, group_rays // chunk_rays, by_scores))
    return 1 << (most.bit_length() - 1) if most > 1 else 1


# -- the stages ---------------------------------------------------------------------------------
def walk_chunks(tables, sizes, rng, abort=None):
    """Trace the paths of chunks of ``sizes`` paths as one wavefront; return each chunk's own
    tallies (ChunkTally), in order. ``abort`` (a threading.Event) stops it at the next step.

    Walks on several threads take turns at their numpy work (``tables.numpy_turn``, released
    while they trace): taking turns hands the GIL over about once a step."""
    with tables.numpy_turn:
        return run_stages(tables, [int(n) for n in sizes], rng, abort)


def run_stages(tables, sizes, rng, abort=None):
    """The stages, step after step, until the chunks' paths have all ended (the caller holds
    the numpy turn)."""
    state = InterchangeableWalk if tables.speedups.interchangeable else PathWalk
    walk = state(tables, sizes, rng)
    while True:
        check(abort)
        if not walk.refill():
            break
        hits = walk.intersect(*walk.generate(rng))
        walk.handle_escaped(hits)
        walk.score(hits)
        walk.survive_or_cut(hits, rng)
    return walk.tallies()


def walk_chunk(tables, paths, rng, abort=None):
    """Trace ``paths`` random walks from the sources to their end; return their tallies."""
    return walk_chunks(tables, [paths], rng, abort)[0]
