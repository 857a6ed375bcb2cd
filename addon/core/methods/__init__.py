"""The methods a solve runs, each with its algorithm and its policy in one module (``base.Method``):

    walk.py        the paper's shooting random walk, a wavefront of named stages; direct light
                   shot or gathered (path_walk.py, interchangeable.py: the stages' two states;
                   estimators.py: the paper's two estimators)
    jacobi.py      stochastic Jacobi iteration
    two_way.py     the two-way iteration (every ray shooting and gathering; generations.py)
    automatic.py   method="auto": which of the two-way iteration and the walk runs
    first_shot.py  the direct light gathered by shadow rays (gathered_walk.py: the walk from it)
    tables.py      what every chunk reads, the speed-ups, the numpy turns

Each method declares its knobs at its top, plans its chunks and predicts what it can of its
time and error; the solver, the forecast, the panel's words and a cluster's workers read them
through ``create`` and the interface of ``base``.
"""
from __future__ import annotations

from ..names import AUTO, GATHERED, METHODS, SHOT
from .base import GatheringSpec, Integrator, Method
from .jacobi import Jacobi
from .two_way import TwoWay
from .walk import Walk

KINDS = {kind.name: kind for kind in (Walk, Jacobi, TwoWay)}

__all__ = ["AUTO", "GatheringSpec", "Integrator", "Method", "create", "direct_light_for"]


def create(name, direct_light=None):
    """The method ``name`` (names.METHODS) with ``direct_light`` (None: the method's own: the
    two-way iteration gathers it, the walks shoot it, as the paper does); ValueError naming
    what is accepted."""
    if name not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS + (AUTO,))}; got {name!r}")
    return KINDS[name](direct_light)


def direct_light_for(name, asked, lights):
    """The direct light a solve of method ``name`` runs with when ``asked`` is wanted: the
    method's own where it has only one, and gathered where a light's cannot be shot
    (``lights.gathered_only``: no shadow, soft falloff)."""
    kind = KINDS[name]
    if len(kind.direct_lights) == 1:
        return kind.direct_lights[0]
    return GATHERED if lights.gathered_only() else (asked or SHOT)
