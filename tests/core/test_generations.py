"""The two-way generations' per-source rows (generations), counted a row at a time or sparsely, give
the sums of the dense rows counted at once, to the bit (what the pins of per-source solves rest on)."""
import numpy as np
import pytest

from addon.core.methods import generations


def _ends(seed, P=257, n=5000, rows=12):
    rng = np.random.default_rng(seed)
    i = np.sort(rng.integers(0, P, n)).astype(np.int32)  # (a generation's rays leave in patch order)
    j = rng.integers(0, P, n).astype(np.int32)
    return i, j, rng.random(n), rng.normal(size=(rows, P)), rng.normal(size=(rows, P))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_generation_s_rows_score_both_ends_as_one_count_over_them(seed):
    """Each row gets s value[j] at i and s value[i] at j, summed as one count over the i ends
    then the j ends (the order the single count of both ends added them in), onto what H held."""
    i, j, s, value, H = _ends(seed)
    expected = H.copy()
    to, source = np.concatenate((i, j)), np.concatenate((j, i))
    for row, v in zip(expected, value):
        row += np.bincount(to, weights=v.take(source) * np.concatenate((s, s)), minlength=row.size)
    generations._score_rows(i, j, s, value, H)
    assert np.array_equal(H, expected)


def _lobe(seed, S=4, C=3, G=3000, P=97):
    rng = np.random.default_rng(seed)
    group = rng.integers(-1, S, G).astype(np.int32)  # (-1: a part that found nothing)
    power = rng.random((C, G)) * (rng.random(G) < 0.8)  # (some rows carry nothing)
    dense = np.zeros((S * C, G))  # each glossy row's light in its group's channels, zeros elsewhere
    for g in range(S):
        dense[g * C:(g + 1) * C] = np.where(group == g, power, 0.0)
    return group, power, dense, rng.integers(0, P, G), rng.random(G) < 0.7, P, S


@pytest.mark.parametrize("seed", [0, 1])
def test_glossy_rows_kept_by_group_sum_as_their_dense_rows(seed):
    """A glossy row's light is one group's: counted by (group, patch) and summed by group, the
    sums are the dense (S C,G) rows', to the bit; its allotment weight is theirs too."""
    group, power, dense, patch, mask, P, S = _lobe(seed)
    lobe = generations._Lobe(power, group, S, P)
    expected = np.stack([np.bincount(patch.compress(mask), weights=w.compress(mask), minlength=P) for w in dense])
    assert np.array_equal(lobe.sums(patch, mask, lobe.power), expected)
    assert np.array_equal(lobe.power.mean(axis=0), dense.reshape(S, 3, -1).sum(axis=0).mean(axis=0))
    rows = np.sort(np.random.default_rng(seed).integers(0, group.size, 800))  # (rays allotted to rows)
    w = lobe.power.take(rows, axis=1) * 0.37
    expected = np.stack([np.bincount(patch.take(rows).compress(mask[:800]), weights=(d.take(rows) * 0.37).compress(mask[:800]),
                                     minlength=P) for d in dense])
    assert np.array_equal(lobe.sums(patch.take(rows), mask[:800], w, rows), expected)
    lost = np.array([(d.take(rows) * 0.37).compress(mask[:800]).sum() for d in dense])
    assert np.array_equal(lobe.lost(mask[:800], w, rows), lost)


def test_glossy_rows_without_groups_sum_by_patch():
    """Without per-source results the lobe's rows are the channels' own."""
    _, power, _, patch, mask, P, _ = _lobe(3)
    lobe = generations._Lobe(power, None, 1, P)
    expected = np.stack([np.bincount(patch.compress(mask), weights=w.compress(mask), minlength=P) for w in power])
    assert np.array_equal(lobe.sums(patch, mask, power), expected)
    assert np.array_equal(lobe.lost(mask, power, np.arange(power.shape[1])), power.compress(mask, axis=1).sum(axis=1))
