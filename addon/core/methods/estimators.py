"""The two shooting random walk estimators of Sbert & Brusi: what a path does at each hit.

A path starts at a source chosen in proportion to its power, carrying Phi_T / N, and scores
the power it carries on every patch it hits (the walk's stages: ``walk``). Then:

- ``finite`` (the paper's Phi_T estimator): the carried power never changes; the path survives
  the hit with probability R_bar_j, the hit patch's (grey) reflectivity. In colour, survivors
  multiply each channel by R_jc / R_bar_j, so that every channel stays unbiased.
- ``biased_infinite``: the carried power is multiplied by R_jc at every hit and the path never
  dies, until the product of (grey) reflectivities along it falls below the threshold t. The
  power still carried then is "undistributed".
"""
from __future__ import annotations


def finite_survives(u, grey_reflectivity):
    """The finite estimator's die-or-survive test: a path survives a hit with probability
    R_bar of the hit patch (``u`` uniform in [0, 1), float64)."""
    return u < grey_reflectivity


def biased_carry(accumulated, grey_reflectivity):
    """The biased estimator's power after a hit: the accumulated reflectivity times the hit
    patch's R_bar (a new array)."""
    return accumulated * grey_reflectivity


def biased_cut(accumulated, threshold):
    """The biased estimator's end: the accumulated reflectivity is below the threshold t."""
    return accumulated < threshold
