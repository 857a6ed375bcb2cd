"""Every walk gives bit for bit the results it gave before the walk was split into named stages
(pins made on commit 4187daa: see pinned_cases), with the speed-ups on and off as each case says.

A few solves come out differently, bit for bit, on another CPU with the same code
(``pinned_variants.json`` says where they were recorded): a result must be one of its case's
recorded fingerprints. A change to the walk changes it on every CPU, so it matches none.
A CPU that gives a third result fails here: record its fingerprints the same way, after
checking on a recorded CPU that the code still gives the pins."""
import json
from pathlib import Path

import pytest
from pinned_cases import CASES, METHOD_CASES, SCENES, fingerprint, method_fingerprint, solve_arguments

from addon.core import Speedups, solve

PINS = json.loads((Path(__file__).parent / "pinned_results.json").read_text())
METHOD_PINS = json.loads((Path(__file__).parent / "pinned_methods.json").read_text())
VARIANTS = json.loads((Path(__file__).parent / "pinned_variants.json").read_text())["cases"]
_scenes = {}


def _scene(name):
    if name not in _scenes:
        _scenes[name] = SCENES[name]()
    return _scenes[name]


@pytest.mark.parametrize("case", CASES, ids=[c["id"] for c in CASES])
def test_results_are_the_pinned_ones(case):
    scene = _scene(case["scene"])
    result = solve(scene, speedups=Speedups(**case["speedups"]), **solve_arguments(scene, case))
    assert fingerprint(result) in [PINS[case["id"]], *VARIANTS.get(case["id"], [])]


@pytest.mark.parametrize("case", METHOD_CASES, ids=[c["id"] for c in METHOD_CASES])
def test_methods_give_the_pinned_results(case):
    """The gathered walk, Jacobi, the two-way iteration and Automatic, under every stop rule,
    give the results recorded with benchmarks/hash_solves.py (on c085628, before each method
    owned its policy; the two-way iteration's runs to an error target again when their chunks
    grew to the stop rule's balance, two_way_sizes.balanced_chunk, and the Cornell box's two-way runs again
    when a patch's gathering samples were let past 256, first_shot.MAX_GATHER_SAMPLES)."""
    scene = _scene(case["scene"])
    assert method_fingerprint(solve(scene, **solve_arguments(scene, case))) == METHOD_PINS[case["id"]]


def test_a_planted_change_fails_the_pins():
    """The fingerprint sees a change in the last bit of one patch's radiosity."""
    case = CASES[0]
    scene = _scene(case["scene"])
    result = solve(scene, **solve_arguments(scene, case))
    result.radiosity[7, 1] = float.fromhex(result.radiosity[7, 1].hex()) * (1 + 2**-52)
    assert fingerprint(result) not in [PINS[case["id"]], *VARIANTS.get(case["id"], [])]
