"""Stochastic Jacobi iteration (``jacobi``, beyond the paper): the walk's light shot generation
by generation, each generation's rays allotted to patches by their unshot power.

Its plan and its direct light (shot, or gathered by shadow rays) are the gathered walk's
(``methods.walk``): the paper's formulas do not predict its error, which is measured. Small
chunks are traced together, a generation of every chunk in one wavefront, up to
GROUP_PATHS_JACOBI first rays a group.
"""
from __future__ import annotations

from . import walk_stages as stages
from .jacobi_iteration import jacobi_chunk, jacobi_chunks
from ..names import JACOBI
from .base import Integrator
from .walk import Walk, chunks_per_group

# A group's wavefront is a generation, whose first has a ray a path: chunks go together up to
# this many first rays in a group.
GROUP_PATHS_JACOBI = 1 << 16


class Jacobi(Walk):
    """Shooting stochastic Jacobi iteration."""

    name = JACOBI

    @property
    def predicted(self):
        return False

    def shot(self, tables):
        return ShotJacobi(tables)

    @staticmethod
    def one_chunk(tables, paths, rng, abort):
        return jacobi_one(tables, paths, rng, abort)


class ShotJacobi(Integrator):
    """Stochastic Jacobi iteration from the sources: its tables alone."""

    def group(self, chunk_paths, expected_path_length):
        return chunks_per_group(self.tables, chunk_paths, GROUP_PATHS_JACOBI)

    def run(self, sizes, rng, abort=None):
        sizes = [int(n) for n in sizes]
        tables = stages.chunk_wide(self.tables, sum(sizes))
        with tables.numpy_turn:
            return jacobi_chunks(tables, sizes, rng, lambda: stages.check(abort))


def jacobi_one(tables, paths, rng, abort):
    """One chunk of Jacobi iteration (from the sources ``tables`` has)."""
    return jacobi_chunk(tables, paths, rng, lambda: stages.check(abort))
