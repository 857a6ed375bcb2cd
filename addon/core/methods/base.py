"""The interface every method offers the solver, the forecast, the panel and the cluster.

A method (``Method``) is its policy, made from its name and direct light and nothing else: the
knobs at the top of its module, its plan (the paths it plans for, a chunk's paths) and what it
predicts (whether the paper's formulas hold for its error, the rays a path costs, how its
variance per path changes with the chunk). ``create`` gives the state a solve's chunks read
(an ``Integrator``): the walk tables, and what the method builds for the solve beyond them
(the gathering of the direct light, from the solve's seed). A cluster worker rebuilds the same
state from ``Integrator.spec`` (``rebuild``): its chunks then give the same bits.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from .first_shot import FATE_RAYS, FATE_STREAM, Gathering
from ..scene.rays import cast as ray_cast, leave_sources, region_of
from ..estimate.plan import chunk_paths_for

# A method beyond the paper's formulas plans its chunks for this fraction of the paths they
# predict for the target: it needs several times fewer (docs/performance.md).
UNPREDICTED_PLAN_DIVISOR = 4


class Method:
    """A method's policy (subclasses set ``name`` and ``direct_lights``, its own first)."""

    name = ""
    direct_lights = ()

    def __init__(self, direct_light=None):
        """The method with ``direct_light`` (None: its own); ValueError where it cannot take it."""
        if direct_light is not None and direct_light not in self.direct_lights:
            if len(self.direct_lights) == 1:
                raise ValueError(f"method='{self.name}' gathers its direct light: direct_light must be "
                                 f"'{self.direct_lights[0]}' (or None); got {direct_light!r}")
            raise ValueError(f"direct_light must be one of {', '.join(self.direct_lights)}; got {direct_light!r}")
        self.direct_light = self.direct_lights[0] if direct_light is None else direct_light

    def __repr__(self):
        return f"{type(self).__name__}(direct_light={self.direct_light!r})"

    @property
    def predicted(self):
        """Whether the paper's formulas (2)/(3) predict its error (else it is measured)."""
        return False

    def planned_paths(self, predicted_paths):
        """The paths a solve stopping on its measured error plans its chunks for, from the
        paper's prediction for the target."""
        return max(1, predicted_paths // UNPREDICTED_PLAN_DIVISOR)

    def chunk_paths(self, patch_count, expected_path_length, planned_paths, time_limited=False, guessed=False):
        """A chunk's paths in a plan of ``planned_paths`` (``guessed``: the prediction's, for a run
        that stops on its measured error)."""
        return chunk_paths_for(expected_path_length, planned_paths)

    def rays_per_path(self, bounces):
        """About the rays a path costs, before any is traced (the forecast's guess)."""
        return max(bounces, 1.0)

    def variance_scale(self, patch_count, pilot_chunk, chunk):
        """Its variance per path in chunks of ``chunk`` paths over that in chunks of
        ``pilot_chunk`` (the forecast's pilot): 1 where paths are independent."""
        return 1.0

    sizes_later_chunks = False  # (whether later_chunk sizes a run's chunks from its first ones)

    def later_chunk(self, patch_count, first, done, variance, target_mse, most):
        """The paths of a run's chunks after its first ``done`` chunks of ``first`` paths measured
        ``variance`` per path, for a measured stop at ``target_mse``, ``most`` the plan's chunk (a
        method whose variance per path falls with its chunk may go past it: two_way): ``first``
        where paths are independent (the chunk's size changes nothing but the stop's steps)."""
        return first

    def again_chunk(self, patch_count, sizes, increments, terms, target_mse, running, most):
        """The paths of a run's chunks from plan.RESIZE_AGAIN_FROM on, sized again on its first
        chunks of ``sizes`` paths, their Batches ``increments`` and ``spread_terms`` (``terms``), for
        a measured stop at ``target_mse``, the chunks of ``running`` paths before them already sized,
        ``most`` the plan's chunk; None: not sized again (paths independent, as ``later_chunk``)."""
        return None

    def resized(self, state, chunk, new_chunk):
        """The Integrator ``state`` (made for chunks of ``chunk`` paths) for chunks of ``new_chunk``."""
        return state

    def create(self, scene, tables, chunk, seed, prediction):
        """The Integrator a solve's chunks of ``chunk`` paths read."""
        raise NotImplementedError

    def rebuild(self, scene, tables, spec):
        """The Integrator ``create`` made, from its ``spec`` (on a cluster worker)."""
        raise NotImplementedError


@dataclass(frozen=True)
class GatheringSpec:
    """What a gathering of the direct light is rebuilt from: each patch's expected samples, and
    the solve's (escaped, blocked) split of what it finds on no front (fate_shares, below),
    which is a solve's own and no part of the key a worker keeps its state under."""

    samples: tuple
    fate_shares: tuple = field(default=(1.0, 0.0), compare=False)


class Integrator:
    """The state a solve's chunks read. ``run(sizes, rng, abort)`` traces chunks of ``sizes``
    paths and returns their tallies; ``group(chunk, expected_path_length)`` is how many
    chunks a task traces together; ``spec`` what a worker rebuilds it from (None: the tables
    alone), ``with_spec(spec)`` the same state with a solve's own spec; ``gather_rays`` the
    rays a chunk's gathering of the direct light casts on average (0: none)."""

    spec = None
    gather_rays = 0

    def __init__(self, tables):
        self.tables = tables

    def group(self, chunk_paths, expected_path_length):
        return 1

    def with_spec(self, spec):
        return self

    def run(self, sizes, rng, abort=None):
        raise NotImplementedError


class GatheringIntegrator(Integrator):
    """The state of a method that gathers its direct light: the tables and the ``gathering``
    (first_shot.Gathering) its chunks read."""

    def __init__(self, tables, gathering):
        super().__init__(tables)
        self.gathering = gathering

    @property
    def spec(self):
        return GatheringSpec(tuple(self.gathering.samples.tolist()), tuple(self.gathering.fate_shares))

    @property
    def gather_rays(self):
        return round(2 * self.gathering.samples.sum())

    def with_spec(self, spec):
        """The same state, its gathering with the solve's own split (shared otherwise)."""
        if tuple(spec.fate_shares) == self.gathering.fate_shares:
            return self
        other = copy.copy(self)
        other.gathering = copy.copy(self.gathering)
        other.gathering.fate_shares = tuple(spec.fate_shares)
        return other


def solve_gathering(scene, tables, samples, seed):
    """The Gathering a solve's chunks read: ``samples`` (P,) expected a patch, and the split of
    what it finds on no front measured from the seed (it casts, and a cast lets go of the turn
    while it traces)."""
    with tables.numpy_turn:
        shares = fate_shares(tables, int(seed))
    return Gathering(scene, samples, fate_shares=shares)


def spec_gathering(scene, spec):
    """The Gathering a GatheringSpec was made of."""
    return Gathering(scene, np.asarray(spec.samples), fate_shares=spec.fate_shares)


def fate_shares(tables, seed):
    """(escaped, blocked): how FATE_RAYS rays from the sources (drawn and leaving as the walk's
    first rays) that find no patch's front divide between nothing and a back side, so that
    light landing on back sides (flipped normals) is reported as such; (1, 0) where none ends
    either way (a closed scene, whose lost direct light is the gathering's noise about 0).
    Measured once a solve, from the seed's own stream: the chunks split their lost light alike
    (only the accounts read it), and no chunk pays for a cast of its own."""
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(FATE_STREAM,))))
    source = tables.sources.sample(FATE_RAYS, rng)
    u = rng.random((tables.uniforms_per_ray, FATE_RAYS), dtype=np.float32)
    hits = ray_cast(tables, *leave_sources(tables, source, u), region_of(tables, source))
    escaped = np.count_nonzero(hits.hit < 0)
    blocked = np.count_nonzero((hits.hit >= 0) & ~hits.front)
    if escaped + blocked == 0:
        return 1.0, 0.0
    share = blocked / (escaped + blocked)
    return 1.0 - share, share


class Aborted(Exception):
    """The walk was asked to stop; its partial chunk is discarded."""


def check(abort):
    """Raises Aborted once ``abort`` (a threading.Event, or None) is set."""
    if abort is not None and abort.is_set():
        raise Aborted
