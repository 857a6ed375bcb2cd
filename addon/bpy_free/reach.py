"""What the estimate says before a run that its path cap will end above its error target."""
from __future__ import annotations

from ..core.names import WALK


def out_of_reach(short_of_target, scene, settings) -> str | None:
    """A warning where a pilot says the run ends at its path cap above the error target
    (``short_of_target``: the relative error there over the target's, core Forecast), naming
    the lights whose direct light every method gathers: a narrow spot's light, gathered from
    each patch, is rarely found, and only a shooting walk brings it where it lands."""
    if settings.paths or not short_of_target > 1.0:
        return None
    target = settings.relative_rms * 100
    reached = short_of_target * target
    reached = "far above it" if short_of_target > 100 else f"near {reached:.2g}%" if reached < 10 else f"near {reached:.0f}%"
    text = f"The {target:g}% error target is out of reach: a pilot says the run ends at its path cap {reached}"
    gathered = scene.lights.gathered_only()
    if gathered:
        names = ", ".join(f"'{name}' {why}" for name, why in gathered)
        return (f"{text}. Light that lands on a few patches (a narrow spot) is gathered from every patch here, which "
                f"rarely finds it: {names}; with Soft Falloff off and shadows on, the walk shoots it from the lamp")
    if settings.method != WALK:
        return f"{text}. The paper's walk shoots the light from the sources, which finds where a narrow cone lands"
    return f"{text}; a looser target or larger patches need fewer paths"
