"""Sources in groups, for per-source results: which group each source's light belongs to.

A group is what relighting scales as one: each light (the world is one), each set of emitting
patches of one label (a material; by default patches of one emittance), or a light group the
caller names, which patches and lights share. A solve with per-source results (``per_source``)
tallies every group's light apart from the same rays (``relighting``): a walk's path carries the
group of the source it left (``grouped_draw``); where a source's light is itself a mix of groups
(the reflected direct light a gathered walk starts from), the path draws one group in
proportion to its share (``Mix``), which keeps the estimate unbiased and the group sums the total.

A walk's groups are kept as virtual chunks: chunk g's paths of group s are chunk g S + s of a
walk of G S chunks (``grouped_draw``), whose tallies ``fold`` adds back into the G chunks.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..lights.lights import WorldLight
from ..lights.sampling import channel_sum, draw_sources
from .tallies import ChunkTally

# The most patches x sources a per-source solve takes: its results hold two (S,P,3) float64
# arrays, and its tallies another while it runs (8.4M: about 200 MB an array).
PER_SOURCE_MAX = 1 << 23
# ... and at most this many groups: a walk's sort key by chunk and patch (16 bits) leads with
# its virtual chunk (path_walk.patch_order).
MAX_GROUPS = 1 << 10


@dataclass(frozen=True)
class SourceGroups:
    """The groups of a scene's sources: ``names`` (S,), and the group of every source id a walk
    draws, ``source_group`` (P + E,) int32 (patches, then the lights' emitters; -1 for a patch
    that emits nothing), with ``light_group`` (L,) the group of each light."""

    names: tuple
    source_group: np.ndarray
    light_group: np.ndarray

    @property
    def count(self):
        return len(self.names)

    def patch_group(self, patch_count):
        """(P,) the group of each patch's own emission (-1: none)."""
        return self.source_group[:patch_count]

    def __eq__(self, other):
        return (isinstance(other, SourceGroups) and self.names == other.names
                and np.array_equal(self.source_group, other.source_group))

    def __hash__(self):
        return hash((self.names, self.source_group.tobytes()))


def source_groups(scene, patch_labels=None, light_labels=None):
    """The SourceGroups of ``scene``. ``patch_labels`` (P,) labels the emitting patches (a
    material's name, a light group's; default: patches of one emittance share a group);
    ``light_labels`` (L,) labels the lights (None, or None for a light: its own group, by its
    name). Patches and lights of one label share its group (Blender's ``lightgroup``)."""
    P, lights = scene.patch_count, scene.lights
    emitting = np.flatnonzero(scene.emission.any(axis=1))
    if patch_labels is None:
        rows, kinds = np.unique(scene.emission[emitting], axis=0, return_inverse=True)
        names_of = [f"emission {tuple(round(float(x), 6) for x in row)}" for row in rows]
        labels = [names_of[k] for k in kinds.reshape(-1)]
    else:
        patch_labels = np.asarray(patch_labels)
        if patch_labels.shape != (P,):
            raise ValueError(f"patch_labels must have one label a patch, shape ({P},); got {patch_labels.shape}")
        labels = [str(x) for x in patch_labels[emitting]]
    if light_labels is None:
        light_labels = [None] * len(lights)
    if len(light_labels) != len(lights):
        raise ValueError(f"light_labels must have one label a light ({len(lights)}); got {len(light_labels)}")
    # Labels name shared groups; a light without one gets a group of its own, named after it.
    taken = set(labels) | {str(label) for label in light_labels if label is not None}
    light_names = [str(label) if label is not None else _own_name(light.name, taken, k)
                   for k, (light, label) in enumerate(zip(lights.lights, light_labels))]
    names = {}
    for name in list(dict.fromkeys(labels)) + light_names:
        names.setdefault(name, len(names))
    source_group = np.full(P + lights.emitter_count, -1, dtype=np.int32)
    source_group[emitting] = [names[label] for label in labels]
    light_group = np.array([names[name] for name in light_names], dtype=np.int32)
    source_group[P:] = light_group.take(lights.light_of) if len(lights) else []
    return SourceGroups(tuple(names), source_group, light_group)


def _own_name(name, taken, k):
    """A light's own group name (added to ``taken``): its name, or its name and place where a
    label or another light has it."""
    name = name if name not in taken else f"{name} ({k})"
    taken.add(name)
    return name


def check_per_source(scene, groups):
    """ValueError, in one line, where ``groups`` do not fit ``scene`` or its per-source results
    would pass PER_SOURCE_MAX patches x sources."""
    if not isinstance(groups, SourceGroups):
        raise ValueError(f"groups must be SourceGroups (source_groups(scene, ...)); got {groups!r}")
    if groups.source_group.size != scene.patch_count + scene.lights.emitter_count:
        raise ValueError("groups were made for another scene (its patches or lights differ)")
    world_group(scene, groups)
    if groups.count > MAX_GROUPS:
        raise ValueError(f"per-source results take at most {MAX_GROUPS:,} sources; got {groups.count:,}: "
                         "put sources in light groups")
    size = scene.patch_count * groups.count
    if size > PER_SOURCE_MAX:
        raise ValueError(
            f"per-source results need patches x sources x 3 floats: {scene.patch_count:,} patches x "
            f"{groups.count} sources = {size:,}, over the cap of {PER_SOURCE_MAX:,} "
            f"({PER_SOURCE_MAX * 24 / 2**20:,.0f} MiB a result); put sources in light groups or use fewer patches")


class Mix:
    """Sources (ids from ``offset`` on) whose light is a mix of groups: ``group`` (M,n) the
    group of each of a source's M parts, ``power`` (M,n,3) each part's power."""

    def __init__(self, offset, group, power):
        self.offset, self.group, self.power = offset, group, power
        # Each source's parts' power summed over the channels, cumulated over its parts (M,n).
        self.cumulative = np.cumsum(np.stack([channel_sum(p) for p in power]), axis=0)

    def draw(self, source, u):
        """(group, part) (n,) each for sources ``source`` (n,) and uniforms ``u`` (n,): a part
        chosen in proportion to its power summed over the channels, as sources are chosen."""
        column = source - self.offset
        cumulative = self.cumulative.take(column, axis=1)
        part = np.count_nonzero(cumulative <= u * cumulative[-1], axis=0)
        part = np.minimum(part, cumulative.shape[0] - 1)
        return self.group[part, column], part

    def start_weight(self, source, part, channels):
        """E_mc / E_bar_m (C,n) of each path's part: its starting weights (colour walks)."""
        E = self.power[part, source - self.offset]  # (n,3)
        grey = channel_sum(E) / 3
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(grey > 0, E[:, :channels].T / grey, 0.0)


@dataclass(frozen=True, eq=False)
class WalkGroups:
    """What a walk reads of the groups: ``count`` S, ``source_group`` of its sources (None where
    they are a mix), and the ``mix`` (or None); ``whole`` the scene's SourceGroups."""

    count: int
    source_group: np.ndarray | None = None
    mix: Mix | None = None
    whole: SourceGroups | None = None  # (the scene's, with their names)
    world: int = -1  # the world's group (-1: no world)

    def with_mix(self, mix):
        return replace(self, source_group=None, mix=mix)


def draw_walk_sources(tables, sizes, rng):
    """Every path's source for chunks of ``sizes`` paths (sampling.draw_sources), as virtual
    chunks where results are per source: (source, chunk or None, first uniforms or None, part
    of a mix or None, the chunks' sizes)."""
    source, chunk, first = draw_sources(tables.sources, sizes, rng, tables.stratified)
    if tables.groups is None:
        return source, chunk, first, None, sizes
    return grouped_draw(tables, source, chunk, first, sizes, rng)


def grouped_draw(tables, source, chunk, first, sizes, rng):
    """The drawn sources of chunks of ``sizes`` paths as virtual chunks, chunk g's paths of
    group s chunk g S + s, in that order: (source, virtual chunk, first uniforms, part (or
    None), virtual sizes (G S,))."""
    groups = tables.groups
    S, G = groups.count, len(sizes)
    part = None
    if groups.mix is None:
        group = groups.source_group.take(source)
    else:
        group, part = groups.mix.draw(source, rng.random(source.size))
    virtual = group.astype(np.int32)
    if chunk is not None:
        virtual += chunk.astype(np.int32) * np.int32(S)
    order = np.argsort(virtual, kind="stable")
    take = lambda a: None if a is None else a.take(order, axis=-1)  # noqa: E731
    virtual_sizes = np.bincount(virtual, minlength=G * S)
    return take(source), take(virtual), take(first), take(part), [int(n) for n in virtual_sizes]


def fold(tallies, sizes, S):
    """The ChunkTally of each of ``sizes`` chunks from its S virtual chunks' ``tallies``, with
    ``incident_groups`` (S,C,P) each, and ``incident`` their sum (group by group, in order)."""
    folded = []
    for g, n in enumerate(sizes):
        parts = tallies[g * S:(g + 1) * S]
        groups = np.stack([t.incident for t in parts])
        total = lambda name: sum((getattr(t, name) for t in parts[1:]), getattr(parts[0], name))  # noqa: E731
        ended = {key: sum(t.ended.get(key, 0) for t in parts) for key in parts[0].ended}
        folded.append(ChunkTally(
            n, sum(t.rays for t in parts), _group_sum(groups), total("emitted"), total("absorbed"),
            total("escaped"), total("blocked"), total("undistributed"), ended, incident_groups=groups))
    return folded


def _group_sum(groups):
    """(C,P) the sum over the first axis of (S,C,P), group after group (what the per-source
    results add up to, to the bit)."""
    total = groups[0].copy()
    for row in groups[1:]:
        total += row
    return total


def with_groups(tally, groups):
    """``tally`` with its incident power (S,C,P) ``groups`` by group, its total their sum."""
    return replace(tally, incident=_group_sum(groups), incident_groups=groups)


class SampleParts:
    """Each gathering sample's estimate (first_shot.gather_direct) as two parts, its shadow
    ray's and its cosine ray's, each of one source group: ``value`` (2,3,n), ``group`` (2,n)
    (-1 where the part found nothing)."""

    def __init__(self, tables, patch):
        n, whole, P = patch.size, tables.groups.whole, tables.patch_count
        self.patch = patch
        self.value = np.zeros((2, 3, n))
        self.group = np.full((2, n), -1, dtype=np.int32)
        # The group of each source a shadow ray looks at: emitting patches, then the lights.
        self.shadow_group = np.concatenate([whole.patch_group(P), whole.light_group])

    def block(self, rows):
        """The parts of samples ``rows`` (a slice): (value, group, the shadow sources' groups)."""
        return self.value[:, :, rows], self.group[:, rows], self.shadow_group

    def irradiance(self, count, P, samples):
        """(S,3,P) each group's part of the direct irradiance (as gather_direct sums H)."""
        H = np.zeros((count, 3, P))
        for m in range(2):
            key = np.maximum(self.group[m], 0) * np.int64(P) + self.patch  # (a part that found nothing is 0)
            for c in range(3):
                H[:, c] += np.bincount(key, weights=self.value[m, c], minlength=count * P).reshape(count, P)
        H /= samples
        return H


def world_group(scene, groups):
    """The group of the scene's world light (-1: none); ValueError where worlds are in several
    (a gathering sample's cosine ray finds them all at once)."""
    found = {int(g) for light, g in zip(scene.lights.lights, groups.light_group) if isinstance(light, WorldLight)}
    if len(found) > 1:
        raise ValueError("per-source results take the world lights in one group; they are in several")
    return found.pop() if found else -1


def groups_for(scene, per_source, groups):
    """The SourceGroups a per-source solve tallies (None: no per-source results); ValueError in
    one line where they cannot be."""
    if not per_source:
        if groups is not None:
            raise ValueError("groups are for per-source results: give per_source=True with them")
        return None
    groups = source_groups(scene) if groups is None else groups
    check_per_source(scene, groups)
    return groups
