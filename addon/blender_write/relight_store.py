"""Per-source results kept in the .blend (bpy): each result object holds its groups' values as
hidden float-vector attributes (``.radiosity <kind> <s>``, FACE, CORNER or POINT), the scene's
results collection the rest as JSON (names, members with their solved strengths and colours and
signatures, the error's covariance, which values make which output). Save and reopen, undo and
the command line keep them; an in-memory copy of the arrays, keyed by the results' token, spares
reading them back on every relight."""

from __future__ import annotations

import json
import uuid

import numpy as np

from ..blender_read.objects import is_result_object
from .results import result_collection

META_PROPERTY = "radiosity_relight"
DOMAINS = {"flat": "FACE", "irradiance": "FACE", "smooth": "CORNER", "light": "CORNER", "irradiance_point": "POINT",
           "bounced": "CORNER", "bounced_irradiance": "FACE", "lampless": "CORNER", "lampless_irradiance": "FACE"}
_CACHE = {}  # token -> Stored


def attribute_name(kind, s):
    return f".radiosity {kind} {s}"


def store(scene, created, results, snapshot, solved):
    """Keeps ``results`` (relit.SourceResults, or None: forget any earlier ones) on the new
    result objects ``created`` (in the order of the receiving objects) and the collection;
    ``snapshot``: blender_read.sources.snapshot when the solve started; ``solved``: (the
    selected objects' names, every solved object's names, their geometry_signature)."""
    collection = result_collection(scene, create=False)
    if collection is None:
        return None
    if META_PROPERTY in collection.keys():
        del collection[META_PROPERTY]
    if results is None:
        return None
    receiving = [values for values in results.arrays if values is not None]
    objects = []
    for obj, values in zip(created, receiving):
        mesh = obj.data
        for kind, array in values.items():
            for s in range(array.shape[0]):
                attribute = mesh.attributes.new(attribute_name(kind, s), "FLOAT_VECTOR", DOMAINS[kind])
                attribute.data.foreach_set("vector", np.ascontiguousarray(array[s], np.float32).ravel())
        objects.append(obj.name)
    meta = results.meta()
    members = meta["members"]
    for group in members:
        for member in group:
            emission, signature = snapshot.get((member[0], member[1]), (np.zeros(3), None))
            member.append([float(x) for x in (emission if emission is not None else np.zeros(3))])
            member.append(signature)
    token = uuid.uuid4().hex
    meta.update(token=token, objects=objects, targets=[list(t) for t in results.targets],
                kinds=sorted({k for v in receiving for k in v}), selected=list(solved[0]), solved=list(solved[1]),
                geometry=solved[2],
                relit=[[1.0] * 3 for _ in members])
    collection[META_PROPERTY] = json.dumps(meta)
    _CACHE.clear()
    _CACHE[token] = Stored(meta, {obj: values for obj, values in zip(objects, receiving)})
    return meta


def meta_of(scene):
    """The stored per-source results' JSON of ``scene`` (a dict), or None."""
    collection = result_collection(scene, create=False)
    if collection is None or META_PROPERTY not in collection.keys():
        return None
    try:
        return json.loads(collection[META_PROPERTY])
    except (TypeError, ValueError):
        return None


def save_meta(scene, meta):
    result_collection(scene, create=False)[META_PROPERTY] = json.dumps(meta)


class Stored:
    """The arrays of one set of per-source results: per result object {kind: (3,S,n) float32},
    and each object's polygon sizes (for FACE_CORNERS outputs)."""

    # Full recombinations between two of the updates by the changed sources alone (float error
    # accumulates in those updates; a full one starts afresh).
    FULL_EVERY = 64

    def __init__(self, meta, arrays):
        # channel-major (3,S,n): a full recombination is one BLAS product a channel (2.5x an einsum)
        arrays = {name: {kind: np.ascontiguousarray(np.moveaxis(v, 2, 0)) for kind, v in kinds.items()}
                  for name, kinds in arrays.items()}
        self.meta, self.arrays, self.sizes = meta, arrays, {}
        self.last = {}  # (object, kind) -> (weights (S,3), the unclipped sum (n,3) float32, updates since full)
        self.buffers, self.corner_patch = {}, {}

    def combined(self, name, kind, w):
        """(n,3) float32 (not to be changed): the object's ``kind`` values recombined with ``w`` (S,3): by
        the sources whose weights changed since the last recombination alone where they are
        few (a lamp turned: one source's values read, not S)."""
        values = self.arrays[name][kind]  # (3,S,n)
        last = self.last.get((name, kind))
        changed = None if last is None else np.flatnonzero((w != last[0]).any(axis=1))
        if changed is not None and len(changed) <= len(w) // 2 and last[2] < self.FULL_EVERY:
            total = last[1]
            delta = (w[changed] - last[0][changed]).astype(np.float32)
            for s, d in zip(changed, delta):  # (no copy of the changed sources' values)
                for c in range(3):
                    total[:, c] += values[c, s] * d[c]
            count = last[2] + 1
        else:
            w32 = w.astype(np.float32)
            total = np.empty((values.shape[2], 3), np.float32)
            for c in range(3):
                total[:, c] = w32[:, c] @ values[c]
            count = 0
        self.last[(name, kind)] = (w.copy(), total, count)
        return total

    def write(self, name, attribute, kind, domain, w):
        """Writes the recombination of ``kind`` into the colour ``attribute`` of object ``name``
        (at least 0; FACE_CORNERS: each patch's value on its polygon's corners), through an RGBA
        buffer kept for the next time."""
        total = self.combined(name, kind, w)
        key = (name, attribute.name)
        buffer = self.buffers.get(key)
        if buffer is None or len(buffer) != len(attribute.data):
            buffer = self.buffers[key] = np.ones((len(attribute.data), 4), np.float32)
        if domain == "FACE_CORNERS":
            if name not in self.corner_patch:
                self.corner_patch[name] = np.repeat(np.arange(len(self.sizes[name])), self.sizes[name])
            total = total[self.corner_patch[name]]
        np.maximum(total, 0.0, out=buffer[:, :3])
        attribute.data.foreach_set("color", buffer.ravel())


def load(scene, meta):
    """The Stored arrays of ``meta`` (from the cache, else read from the result objects); a
    ValueError in one line where the result objects or their values are gone."""
    stored = _CACHE.get(meta["token"])
    collection = result_collection(scene, create=False)
    objects = {o.name: o for o in collection.objects if is_result_object(o)} if collection is not None else {}
    missing = [name for name in meta["objects"] if name not in objects]
    if missing:
        raise ValueError(f"the result object '{missing[0]}' is gone: solve again to relight")
    if stored is None:
        stored = Stored(meta, {name: _read(objects[name], meta) for name in meta["objects"]})
        _CACHE.clear()
        _CACHE[meta["token"]] = stored
    for name in meta["objects"]:
        if name not in stored.sizes:
            polygons = objects[name].data.polygons
            sizes = np.empty(len(polygons), np.int32)
            polygons.foreach_get("loop_total", sizes)
            stored.sizes[name] = sizes
    return stored, objects


def _read(obj, meta):
    mesh = obj.data
    S = len(meta["names"])
    values = {}
    for kind in meta["kinds"]:
        parts = []
        for s in range(S):
            attribute = mesh.attributes.get(attribute_name(kind, s))
            if attribute is None or attribute.data_type != "FLOAT_VECTOR":
                raise ValueError(f"'{obj.name}' lost its per-source values ({kind}): solve again to relight")
            array = np.empty(len(attribute.data) * 3, np.float32)
            attribute.data.foreach_get("vector", array)
            parts.append(array.reshape(-1, 3))
        values[kind] = np.stack(parts)
    return values


def forget():
    _CACHE.clear()
