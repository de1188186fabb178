"""Latent stability: do a model's latents (one vector per chunk or sample) group by episode?

A rollout may carry ``latents.npy``, (n, D) float: the joint action + visual latent of each chunk
(or of its one sample). Over a set of rollouts, every latent vector is projected on the first two
principal components of them all (PCA by SVD of the centred vectors), and the episode clusters are
scored by their mean **silhouette** (Rousseeuw 1987, "Silhouettes: a graphical aid to the
interpretation and validation of cluster analysis", J. Comput. Appl. Math. 20: 53-65), Euclidean
in the latent space: for each vector, ``(b - a) / max(a, b)`` with ``a`` its mean distance to the
other vectors of its episode and ``b`` the smallest mean distance to another episode's (0 for a
vector alone in its episode). 1: tight, well-separated episodes; 0: overlapping; negative: mixed.
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
    no group of 2 or more."""
    from scipy.spatial.distance import cdist

    a = np.asarray(x, np.float64)
    lab = np.asarray([str(v) for v in labels])
    groups = sorted(set(lab))
    if len(groups) < 2 or len(groups) >= len(a):
        return None
    d = cdist(a, a)
    member = np.stack([lab == g for g in groups], axis=1)  # (n, G)
    sizes = member.sum(axis=0)
    sums = d @ member  # (n, G) summed distance to each group
    own = np.array([groups.index(v) for v in lab])
    own_size = sizes[own]
    intra = np.where(own_size > 1, sums[np.arange(len(a)), own] / np.maximum(own_size - 1, 1), 0.0)
    mean_to = sums / sizes
    mean_to[np.arange(len(a)), own] = np.inf
    nearest = mean_to.min(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(own_size > 1, (nearest - intra) / np.maximum(np.maximum(intra, nearest), 1e-300), 0.0)
    return float(s.mean())


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
            "n_episodes": len(set(map(str, labels))),
            "note": None if score is not None else "not measurable: latents of fewer than 2 episodes"}
