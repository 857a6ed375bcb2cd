"""The shooting random walk as a wavefront of named stages.

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

from .interchangeable import InterchangeableWalk
from .path_walk import PathWalk


class Aborted(Exception):
    """The walk was asked to stop; its partial chunk is discarded."""


def walk_chunks(tables, sizes, rng, abort=None):
    """Trace the paths of chunks of ``sizes`` paths as one wavefront; return each chunk's own
    tallies (ChunkTally), in order. ``abort`` (a threading.Event) stops it at the next step.

    Walks on several threads take turns at their numpy work (``tables.numpy_turn``, released
    while they trace): taking turns hands the GIL over about once a step."""
    with tables.numpy_turn:
        return run_stages(tables, [int(n) for n in sizes], rng, abort)


# Chunk-wide work takes no turns where a task's paths or the scene's patches reach this many
# (benchmarks/turns.py: the two-way iteration with 1,250 paths a chunk took 1.14-1.22x the time
# without turns that it took with them in the 600- and 2,504-patch rooms, 0.95x in the
# 66,576-patch figure 4 room with 8,000 a chunk; in the empty room, with turns 0.82x the time
# without at 1,250 paths a chunk, 0.90x at 7,800, 1.24x at 31,000).
TURN_FREE_SIZE = 1 << 14


def takes_turns(tables, paths):
    """Whether chunk-wide work (the gathered walk, the generations of the Jacobi and two-way
    iterations) takes turns at numpy for a task of ``paths`` paths. The paper's walks always do
    (:func:`walk_chunks`: their steps' arrays are a wavefront's, small, and a turn a step keeps
    the GIL from changing hands inside them); chunk-wide arrays span a whole chunk, numpy lets
    go of the GIL inside most of their operations, and two threads' numpy work then runs side
    by side (``benchmarks/turns.py``), unless both the task's paths and the scene's patches,
    the lengths of its arrays, are below TURN_FREE_SIZE."""
    return max(paths, tables.patch_count) < TURN_FREE_SIZE


def chunk_wide(tables, paths):
    """``tables`` for chunk-wide work on a task of ``paths`` paths: with a numpy turn that
    never waits where it takes no turns (:func:`takes_turns`)."""
    return tables if takes_turns(tables, paths) else tables.with_turn(FreeTurn())


class FreeTurn:
    """A numpy turn that never waits (:func:`takes_turns`): the lock's calls, doing nothing."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def acquire(self):
        return True

    def release(self):
        pass

    def locked(self):
        return False


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


def check(abort):
    """Raises Aborted once ``abort`` (a threading.Event, or None) is set."""
    if abort is not None and abort.is_set():
        raise Aborted


def walk_chunk(tables, paths, rng, abort=None):
    """Trace ``paths`` random walks from the sources to their end; return their tallies."""
    return walk_chunks(tables, [paths], rng, abort)[0]
