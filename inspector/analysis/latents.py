"""Latent stability: do a model's latents (one vector per chunk or sample) group by episode?

A rollout may carry ``latents.npy``, (n, D) float: the joint action + visual latent of each chunk
(or of its one sample). Over a set of rollouts, every latent vector is projected on the first two
principal components of them all (PCA by SVD of the centred vectors), and the episode clusters are
scored by their mean **silhouette** (Rousseeuw 1987, "Silhouettes: a graphical aid to the
interpretation and validation of cluster analysis", J. Comput. Appl. Math. 20: 53-65), Euclidean
in the latent space: for each vector, ``(b - a) / max(a, b)`` with ``a`` its mean distance to the
other vectors of its episode and ``b`` the smallest mean distance to another episode's (0 for a
vector alone in its episode). 1: tight, well-separated episodes; 0: overlapping; negative: mixed.

The silhouette needs every pairwise distance: they are summed a block of rows at a time, never
held as an (n, n) matrix, and past :data:`MAX_SILHOUETTE_VECTORS` vectors (fewer for wide ones:
:data:`MAX_SILHOUETTE_WORK`) the score is that of a fixed uniform sample of them
(``silhouette_vectors`` in the summary says how many), so its time stays bounded too.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


def pca_2d(x: npt.ArrayLike) -> tuple[Array, Array]:
    """((n, 2) projection on the first two principal components, (2,) explained variance ratios)."""
    a = np.asarray(x, np.float64)
    centred = a - a.mean(axis=0)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    k = min(2, vt.shape[0])
    proj = np.zeros((len(a), 2))
    proj[:, :k] = centred @ vt[:k].T
    var = s ** 2
    ratio = np.zeros(2)
    if var.sum() > 0:
        ratio[:k] = var[:k] / var.sum()
    return proj, ratio


def silhouette(x: npt.ArrayLike, labels: Sequence[Any]) -> float | None:
    """Mean silhouette of ``x`` (n, D) grouped by ``labels``; None with fewer than 2 groups or
    no group of 2 or more.

    The distances are taken :data:`BLOCK_VALUES` at a time (rows of the (n, n) matrix in blocks),
    so memory stays bounded whatever n. Past :func:`sample_size` vectors, the silhouette is that of
    a fixed sample of them (:func:`silhouette_sample`): an estimate, the same on every run.
    """
    a = np.asarray(x, np.float64)
    a = a.reshape(len(a), -1)
    lab = np.asarray([str(v) for v in labels])
    picked = silhouette_sample(len(a), a.shape[1])
    if picked is not None:
        a, lab = a[picked], lab[picked]
    groups = sorted(set(lab))
    if len(groups) < 2 or len(groups) >= len(a):
        return None
    own = np.searchsorted(groups, lab)
    member = np.zeros((len(a), len(groups)))
    member[np.arange(len(a)), own] = 1.0
    sizes = member.sum(axis=0)
    sums = _distance_sums(a, member)  # (n, G) summed distance to each group
    own_size = sizes[own]
    rows = np.arange(len(a))
    intra = np.where(own_size > 1, sums[rows, own] / np.maximum(own_size - 1, 1), 0.0)
    mean_to = sums / sizes
    mean_to[rows, own] = np.inf
    nearest = mean_to.min(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(own_size > 1, (nearest - intra) / np.maximum(np.maximum(intra, nearest), 1e-300), 0.0)
    return float(s.mean())


# Distances held at once while summing them (a block of rows of the (n, n) matrix) [values]: 32 MB.
BLOCK_VALUES = 4_000_000
# The most vectors whose silhouette is exact; past it, a sample of this many (distances grow with
# the square: 10,000 vectors take 10^8 distances, a few seconds of one core).
MAX_SILHOUETTE_VECTORS = 10_000
# The distances' arithmetic at most [distances x dimensions]: wide latents get a smaller sample.
MAX_SILHOUETTE_WORK = 2e10
SAMPLE_SEED = 0


def sample_size(n: int, width: int) -> int:
    """How many of ``n`` vectors of ``width`` values the silhouette is computed on: all of them up
    to :data:`MAX_SILHOUETTE_VECTORS` and :data:`MAX_SILHOUETTE_WORK`, else as many as those allow."""
    affordable = int(np.sqrt(MAX_SILHOUETTE_WORK / max(width, 1)))
    return min(n, MAX_SILHOUETTE_VECTORS, max(affordable, 2))


def silhouette_sample(n: int, width: int) -> npt.NDArray[np.intp] | None:
    """Sorted indexes of the vectors the silhouette uses when it cannot use all ``n`` (None: all):
    a uniform sample without replacement, drawn with :data:`SAMPLE_SEED` (the same every run)."""
    m = sample_size(n, width)
    if m >= n:
        return None
    return np.sort(np.random.default_rng(SAMPLE_SEED).choice(n, size=m, replace=False))


def _distance_sums(a: Array, member: Array) -> Array:
    """(n, G) ``sum_j |a_i - a_j|`` over each group's members j (``member`` (n, G) 0/1), the (n, n)
    distances computed a block of rows at a time."""
    from scipy.spatial.distance import cdist

    n = len(a)
    block = max(1, BLOCK_VALUES // max(n, 1))
    sums = np.empty((n, member.shape[1]))
    for start in range(0, n, block):
        sums[start:start + block] = cdist(a[start:start + block], a) @ member
    return sums


def latents_summary(entries: Sequence[tuple[str, Any, npt.ArrayLike]]) -> dict[str, Any] | None:
    """The report's ``latents`` aggregate from (tag, episode, (n, D) latents) of each rollout that
    has them: the 2-D PCA points per rollout, the explained variance and the episodes' silhouette.
    None when no rollout carries latents (or their widths differ: said in ``note``)."""
    if not entries:
        return None
    widths = {np.asarray(z).reshape(len(np.asarray(z)), -1).shape[1] for _, _, z in entries}
    if len(widths) > 1:
        return {"note": f"not measurable: latents of different widths {sorted(widths)}", "silhouette": None,
                "points": [], "explained_variance": None}
    stacked = [np.asarray(z, np.float64).reshape(len(np.asarray(z)), -1) for _, _, z in entries]
    x = np.concatenate(stacked)
    labels = [ep for (_, ep, _), z in zip(entries, stacked) for _ in range(len(z))]
    proj, ratio = pca_2d(x)
    points, i = [], 0
    for (tag, ep, _), z in zip(entries, stacked):
        points.append({"tag": tag, "episode": ep, "xy": [[round(float(a), 4), round(float(b), 4)]
                                                        for a, b in proj[i:i + len(z)]]})
        i += len(z)
    score = silhouette(x, labels)
    return {"silhouette": None if score is None else round(score, 4), "points": points,
            "explained_variance": [round(float(v), 4) for v in ratio], "n_vectors": int(len(x)),
            "silhouette_vectors": sample_size(len(x), x.shape[1]),
            "n_episodes": len(set(map(str, labels))),
            "note": None if score is not None else "not measurable: latents of fewer than 2 episodes"}
