"""The latents' silhouette without an (n, n) distance matrix: the blocked sums equal the definition
computed whole, past the size limit it is the definition on a fixed sample, and 16,000 vectors
(two rollouts of 8,000) stay within tens of MB."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from inspector.analysis import latents
from inspector.analysis.latents import latents_summary, silhouette, silhouette_sample


def _by_definition(x: np.ndarray, labels: list[int]) -> float:
    """Rousseeuw's silhouette with the whole distance matrix, vector by vector."""
    d = np.sqrt(((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=2))
    lab = np.asarray(labels)
    scores = []
    for i in range(len(x)):
        same = (lab == lab[i]) & (np.arange(len(x)) != i)
        if not same.any():
            scores.append(0.0)
            continue
        a = d[i, same].mean()
        b = min(d[i, lab == g].mean() for g in set(labels) if g != lab[i])
        scores.append((b - a) / max(a, b))
    return float(np.mean(scores))


@pytest.mark.parametrize("block_values", [1, 7, 100, 10_000])
def test_the_blocked_silhouette_is_the_definition(monkeypatch, block_values):
    monkeypatch.setattr(latents, "BLOCK_VALUES", block_values)  # blocks of 1 row, uneven ones, one block
    rng = np.random.default_rng(block_values)
    labels = [int(v) for v in rng.integers(0, 4, 37)] + [9]  # a group of one among them
    x = rng.normal(0, 1, (38, 3)) + np.asarray(labels)[:, None]
    assert silhouette(x, labels) == pytest.approx(_by_definition(x, labels), abs=1e-12)


def test_past_the_limit_it_is_the_definition_on_a_fixed_sample(monkeypatch):
    monkeypatch.setattr(latents, "MAX_SILHOUETTE_VECTORS", 60)
    rng = np.random.default_rng(1)
    labels = [i % 3 for i in range(200)]
    x = rng.normal(0, 1, (200, 2)) + np.asarray(labels)[:, None]
    picked = silhouette_sample(200, 2)
    assert picked is not None and len(picked) == 60 and len(set(picked.tolist())) == 60
    expected = _by_definition(x[picked], [labels[i] for i in picked])
    assert silhouette(x, labels) == pytest.approx(expected, abs=1e-12)
    assert silhouette(x, labels) == silhouette(x, labels)  # the same sample every time
    summary = latents_summary([("a", 0, x[:100]), ("b", 1, x[100:])])
    assert summary is not None and (summary["n_vectors"], summary["silhouette_vectors"]) == (200, 60)


def test_wide_latents_get_a_smaller_sample(monkeypatch):
    monkeypatch.setattr(latents, "MAX_SILHOUETTE_WORK", 1e6)
    assert latents.sample_size(5000, 100) == 100  # sqrt(1e6 / 100)
    assert latents.sample_size(50, 100) == 50


@pytest.mark.slow
def test_two_rollouts_of_8000_latents_take_tens_of_mb_not_two_gb():
    rng = np.random.default_rng(0)
    entries = [(f"r{e}", e, rng.normal(4.0 * e, 1.0, (8000, 1))) for e in range(2)]
    tracemalloc.start()
    try:
        summary = latents_summary(entries)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 150 * 2**20, peak  # before: the (16000, 16000) distance matrix, 2 GB
    assert summary is not None and summary["n_vectors"] == 16_000
    assert 0.5 < summary["silhouette"] < 0.9  # two unit normals four apart
