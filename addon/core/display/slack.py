"""How far a shown patch's mean may stay from its solved value (``smoothing.Surface.corner_values``'
``slack``): the solve's values are estimates, and a patch whose value is its neighbours' plus
noise, held to it exactly, shows a square of its own (its corners scaled apart from theirs at
its edges). No bpy.
"""
import numpy as np

# The standard errors of its solved light a patch's shown mean may stay from it (``slack_of``):
# within them the value is its neighbours' plus noise (two, as the stop rule's MEASURED_STOP_Z: a
# difference the solve cannot tell from its noise), and the last step's scale of its own would
# draw it as a square (the skylight hall's dim walls: a patch in four scaled 10% or more).
# The walkthrough's baked display at 1, 2 and 3: the hall 8.1%, 7.9%, 7.9%; the flat's RMS 17.3%,
# 16.9%, 16.7% (docs/picture.md).
SLACK_ERRORS = 2.0


def slack_of(variance, indirect=None):
    """(P,k) the ``slack`` of ``Surface.corner_values`` for values of the given variances (P,k)
    (of their estimates): SLACK_ERRORS standard errors, NaN where none was measured; with
    ``indirect`` (P,k), the values' part gathered after a bounce where their direct part is known
    apart, at most that: the direct light a solve kept apart keeps its means, as the noise filter
    leaves it (a heavy-tailed direct estimate's spread is not its neighbours' light)."""
    variance = np.asarray(variance, np.float64)
    with np.errstate(invalid="ignore"):
        slack = SLACK_ERRORS * np.sqrt(np.where(np.isfinite(variance) & (variance >= 0), variance, np.nan))
    if indirect is not None:
        slack = np.minimum(slack, np.maximum(indirect, 0.0))
    with np.errstate(over="ignore"):  # (float32: a bound need not be exact, and it is held through the colours)
        return slack.astype(np.float32)


def light_slack(result):
    """(P,3) the slack of a SolveResult's light arriving (``slack_of`` of its variance; its direct
    light, where known apart, keeping its means)."""
    return slack_of(result.irradiance_variance, _bounced(result))


def reflected_slack(result, reflectivity):
    """(P,3) the slack of a SolveResult's reflected light (as ``light_slack``)."""
    bounced = _bounced(result)
    return slack_of(result.reflected_variance, None if bounced is None else reflectivity * bounced)


def _bounced(result):
    """(P,3) a SolveResult's light arriving less its direct light, where that is known apart (else None)."""
    return None if result.direct_irradiance is None else result.irradiance - result.direct_irradiance


def beyond(missing, slack):
    """(P,) the share of each patch's ``missing`` light that lies beyond its ``slack`` (0 within
    it): |missing| - slack over |missing|, at least 0."""
    size = np.abs(missing)
    return np.divide(np.maximum(size - slack, 0.0), size, out=np.zeros_like(size), where=size > 0)
