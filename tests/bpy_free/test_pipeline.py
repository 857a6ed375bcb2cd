"""Every run says where its light went, and whether it kept its error target: the shares of the emitted power absorbed by surfaces
(on the back of faces among them), left the scene and left undistributed, from the run's own
power accounts (pipeline.light_account_text, shown after a run by the panel and the command line)."""
import re

import numpy as np
from boxes import box_scene, open_box_with_card

from addon.core import solve
from addon.bpy_free.pipeline import light_account_text


def _shares(text):
    return {name: float(value) / 100 for value, name in re.findall(r"([\d.]+)% (absorbed|on the back|left the scene)", text)}


def test_an_open_box_says_how_much_light_left_it_and_met_back_faces():
    result = solve(open_box_with_card(), method="walk", paths=20_000, seed=0)
    energy = result.energy
    emitted = float(np.sum(energy["emitted"]))
    shares = _shares(light_account_text(energy))
    # the text rounds to 0.1%: each share within half of that of the accounts
    assert abs(shares["left the scene"] - float(np.sum(energy["escaped"])) / emitted) <= 5e-4
    assert abs(shares["on the back"] - float(np.sum(energy["blocked"])) / emitted) <= 5e-4
    assert abs(shares["absorbed"] - float(np.sum(energy["absorbed"])) / emitted) <= 5e-4
    assert shares["left the scene"] > 0.1  # an open box: a good part of its light leaves it


def test_a_closed_box_loses_nothing_and_says_so():
    scene, _, _ = box_scene([0.5] * 6, [1.0, 0, 0, 0, 0, 0], n=2)
    text = light_account_text(solve(scene, method="walk", paths=8_000, seed=1).energy)
    assert text == "light: 100.0% absorbed by surfaces, 0.0% left the scene", text
    # the two-way iteration's accounts are estimates: its escaped share is 0 within its seeds' spread
    escaped = []
    for seed in range(8):
        energy = solve(scene, method="two_way", paths=8_000, seed=seed).energy
        escaped.append(float(np.sum(energy["escaped"]) / np.sum(energy["emitted"])))
    mean, error = np.mean(escaped), np.std(escaped, ddof=1) / np.sqrt(len(escaped))
    assert abs(mean) <= 4.0 * error, (mean, error)
    text = light_account_text(energy)
    assert re.fullmatch(r"light: \d+\.\d% absorbed by surfaces, \d+\.\d% left the scene", text), text


def test_no_account_without_light():
    assert light_account_text({}) == ""
    assert light_account_text({"emitted": np.zeros(3)}) == ""


def test_a_target_missed_at_the_path_cap_is_said():
    from addon.bpy_free.pipeline import target_missed_text

    text = target_missed_text("paths", 9.5, 5.0)
    assert "5% error target was not reached" in text and "9.50%" in text and "1.9x" in text, text
    # kept, or ended for another reason, or no target (a path count), or no measured error: quiet
    assert target_missed_text("paths", 4.9, 5.0) == ""
    assert target_missed_text("target", 9.5, 5.0) == ""
    assert target_missed_text("time_limit", 9.5, 5.0) == ""  # (the time limit has its own warning)
    assert target_missed_text("paths", 9.5, 0.0) == ""
    assert target_missed_text("paths", -1.0, 5.0) == ""
