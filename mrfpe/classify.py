"""Material classification from posteriors (thesis 8.2.4, Tables 8.3-8.11).

Each material's posterior is a feature; a registered distance compares every
pair into a similarity matrix S (higher = more alike), and the matrix is
scored with the thesis's error statistics or a leave-one-out k-NN classifier.

Similarity matrix convention -- ``S[i, j]`` compares ``posteriors[i]`` (first
argument) with ``posteriors[j]``; row i is "material i against the others":

* distances (``kind == "distance"``): ``S = −d`` (the thesis inverts the EMD
  and linearly rescales others for display; any strictly decreasing map gives
  the same rankings, hence the same statistics);
* ``agmmp``: ``S = log AGMMP`` (finite where AGMMP under/overflows);
* ``correlation``, ``inner_product``: ``S = r`` itself.

The diagonal is computed (self-similarity) but every statistic ignores it, and
it may be NaN in a matrix given to them.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

from mrfpe.validation import check_bool, check_n_jobs

__all__ = [
    "TIE_RTOL", "confusion_matrix", "error_stats", "knn_accuracy", "knn_predict", "merge_ties",
    "plot_similarity", "similarity_matrix",
]


def similarity_matrix(posteriors: Sequence[Any], name: str, *, n_jobs: int = 1,
                      progress: bool = False, **params: Any) -> np.ndarray:
    """Similarity matrix (n, n) between posteriors under the registered distance ``name``.

    Vectorised over all pairs where the distance allows it (Gaussian closed
    forms, grid measures, MAP distance); otherwise (AGMMP, EMD, sliced
    Wasserstein, plugins) the pairs run on ``n_jobs`` joblib workers (threads
    preferred; ``-1`` = all cores) with a tqdm bar when ``progress``. Each
    posterior's features are computed once. See the module docstring for the
    sign convention; ``params`` go to the distance.
    """
    from mrfpe.distances import get
    from mrfpe.distances.base import Distance, pair_loop

    if isinstance(posteriors, str) or not hasattr(posteriors, "__iter__"):
        raise ValueError(f"posteriors must be a sequence of posterior Datasets; got "
                         f"{type(posteriors).__name__}")
    if not isinstance(name, str):
        raise ValueError(f"name must be a registered distance name (str); got {name!r}")
    check_bool("progress", progress)
    posteriors = list(posteriors)
    if len(posteriors) < 1:
        raise ValueError("posteriors must hold at least one posterior")
    n_jobs = check_n_jobs("n_jobs", n_jobs)
    measure = get(name)()
    if isinstance(measure, Distance):
        d = measure.pairwise(posteriors, n_jobs=n_jobs, progress=progress, **params)
        return np.asarray(measure.score(d), dtype=np.float64)
    # a plugin that does not derive from the base class: its distance form, negated
    d = pair_loop(lambda i, j: float(measure(posteriors[i], posteriors[j], **params)),
                  len(posteriors), symmetric=bool(measure.symmetric), n_jobs=n_jobs,
                  progress=progress, desc=name)
    return -d


#: Off-diagonal similarities closer than this (relative) are one value. Pairs that are equal
#: in exact arithmetic come out of a floating-point product a few ulps apart (the
#: correlation of two one-hot weight vectors is −1/(n−1) whichever points carry the
#: weight), and which side of a tie the rounding falls on must not decide a Miss or a
#: neighbour. Measured on the correlations of the thesis-weighted Ward grid sets
#: (values ~1e-3): the gaps below 2e-12 relative (1e-17–2e-15) are rounding and the
#: last bits of the weights (a log-PL of −10⁴ is good to ~1e-12 relative); the next
#: is 7e-9. 1e-10 lies between them.
TIE_RTOL = 1e-10


def merge_ties(S: np.ndarray) -> np.ndarray:
    """``S`` with every run of off-diagonal values within :data:`TIE_RTOL` set to its least.

    The finite off-diagonal entries are sorted and cut where consecutive values differ by
    more than ``TIE_RTOL`` times the larger magnitude (or the median magnitude, so that
    values around 0 merge too); each run takes its first value. The diagonal and
    ±inf entries are left as they are.
    """
    out = np.array(S, dtype=np.float64)
    mask = ~np.eye(out.shape[0], dtype=bool) & np.isfinite(out)
    vals = out[mask]
    if vals.size < 2:
        return out
    order = np.argsort(vals, kind="stable")
    v = vals[order]
    scale = np.maximum(np.maximum(np.abs(v[1:]), np.abs(v[:-1])), np.median(np.abs(v)))
    starts = np.concatenate([[True], np.diff(v) > TIE_RTOL * scale])
    first = v[np.maximum.accumulate(np.where(starts, np.arange(v.size), 0))]
    merged = np.empty_like(vals)
    merged[order] = first
    out[mask] = merged
    return out


def _check_matrix(S: Any, classes: Any) -> tuple[np.ndarray, np.ndarray]:
    try:
        S = np.asarray(S, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"S must be a square matrix of numbers; got {type(S).__name__}") \
            from None
    if S.ndim != 2 or S.shape[0] != S.shape[1]:
        raise ValueError(f"S must be a square similarity matrix; got shape {S.shape}")
    labels = np.asarray(classes)
    if labels.ndim != 1 or labels.shape[0] != S.shape[0]:
        raise ValueError(f"classes must hold one label per row of S ({S.shape[0]}); "
                         f"got shape {labels.shape}")
    off = ~np.eye(S.shape[0], dtype=bool)
    if np.isnan(S[off]).any():
        i, j = np.argwhere(np.isnan(S) & off)[0]
        raise ValueError(f"S has NaN off the diagonal, e.g. at ({i}, {j})")
    return merge_ties(S), labels


def error_stats(S: Any, classes: Any) -> dict[str, int]:
    """The Miss, WNN and NN1 error counts of a similarity matrix (text under Table 8.5).

    For each material i (row i of S, diagonal ignored), with "intra-class" the
    other members of its class and "extra-class" the members of other classes:

    * Miss: the number of extra-class entries S[i, j] *higher* than the
      lowest intra-class similarity of row i, summed over all rows;
    * WNN ("worst nearest neighbour"): the number of materials with at least
      one extra-class similarity higher than the lowest intra-class one (the
      rows that contribute to Miss);
    * NN1: the number of materials whose best match is extra-class and *better*
      than every intra-class match (1-NN misclassifications).

    Comparisons are strict, so ties count as no error; values within
    :data:`TIE_RTOL` (relative) are ties (:func:`merge_ties`). Every class needs at
    least two members (otherwise the intra-class similarities do not exist).
    Returns ``{"miss": int, "wnn": int, "nn1": int}``.
    """
    S, labels = _check_matrix(S, classes)
    n = S.shape[0]
    same = labels[:, None] == labels[None, :]
    intra = same & ~np.eye(n, dtype=bool)
    extra = ~same
    lonely = ~intra.any(axis=1)
    if lonely.any():
        raise ValueError(f"every class needs at least two members; class "
                         f"{labels[np.argmax(lonely)]!r} has one (row {int(np.argmax(lonely))})")
    intra_min = np.where(intra, S, np.inf).min(axis=1)
    intra_max = np.where(intra, S, -np.inf).max(axis=1)
    extra_max = np.where(extra, S, -np.inf).max(axis=1)
    miss = int((extra & (S > intra_min[:, None])).sum())
    wnn = int((extra_max > intra_min).sum())
    nn1 = int((extra_max > intra_max).sum())
    return {"miss": miss, "wnn": wnn, "nn1": nn1}


def _distance_for_knn(S: np.ndarray) -> np.ndarray:
    """A non-negative dissimilarity with the same per-row ranking as S (diagonal 0)."""
    off = ~np.eye(S.shape[0], dtype=bool)
    finite = S[off][np.isfinite(S[off])]
    top = finite.max() if finite.size else 0.0
    low = finite.min() if finite.size else 0.0
    # ±inf similarities map to the ends of a finite range (scikit-learn rejects inf)
    span = max(top - low, 1.0)
    s = np.clip(S, low - span, top + span)
    d = (top + span) - s
    np.fill_diagonal(d, 0.0)
    return d


def knn_predict(S: Any, classes: Any, k: int = 1) -> np.ndarray:
    """Leave-one-out k-NN predicted class of each material, from similarity matrix S.

    scikit-learn's ``KNeighborsClassifier(metric="precomputed")`` under
    ``LeaveOneOut`` cross-validation: material i is classified from row i of S
    against all the others. S is turned into the dissimilarity ``max(S) − S``
    (same ranking), after :func:`merge_ties`; ties between neighbours are broken by
    scikit-learn (in index order).
    """
    from sklearn.model_selection import LeaveOneOut, cross_val_predict
    from sklearn.neighbors import KNeighborsClassifier

    S, labels = _check_matrix(S, classes)
    n = S.shape[0]
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or not 1 <= k <= n - 1:
        raise ValueError(f"k must be an integer in [1, {n - 1}]; got {k!r}")
    clf = KNeighborsClassifier(n_neighbors=int(k), metric="precomputed")
    return cross_val_predict(clf, _distance_for_knn(S), labels, cv=LeaveOneOut())


def knn_accuracy(S: Any, classes: Any, k: int = 1) -> float:
    """Leave-one-out k-NN accuracy (fraction of materials classified correctly)."""
    pred = knn_predict(S, classes, k)
    return float(np.mean(pred == np.asarray(classes)))


def confusion_matrix(S: Any, classes: Any, k: int = 1) -> xr.DataArray:
    """Leave-one-out k-NN confusion matrix, dims ``(true, predicted)`` labelled by class.

    Entry (c, c') counts the materials of class c classified as c'; the
    classes appear in order of first appearance in ``classes``.
    """
    from sklearn.metrics import confusion_matrix as _cm

    labels = np.asarray(classes)
    pred = knn_predict(S, labels, k)
    order = labels[np.sort(np.unique(labels, return_index=True)[1])]
    cm = _cm(labels, pred, labels=order)
    return xr.DataArray(cm, dims=("true", "predicted"),
                        coords={"true": order, "predicted": order}, name="count",
                        attrs={"k": int(k), "method": "leave-one-out k-NN"})


def _class_runs(labels: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of each run of equal consecutive labels."""
    edges = np.flatnonzero(labels[1:] != labels[:-1]) + 1
    bounds = np.concatenate([[0], edges, [labels.size]])
    return [(int(a), int(b)) for a, b in itertools.pairwise(bounds)]


def plot_similarity(S: Any, classes: Any, ax: Any = None, *, cmap: str = "viridis",
                    title: str | None = None, colorbar: bool = True) -> Any:
    """Heat-map of a similarity matrix with each class block outlined (Tables 8.3-8.5).

    Rows and columns are grouped by class (stable, classes in order of first
    appearance; the tick labels give the original 1-based indices, as the
    thesis numbers its materials). Within-class blocks on the diagonal are
    outlined and class boundaries drawn as lines across the matrix, as the
    thesis separates classes in its tables. NaN entries (e.g. the diagonal)
    are left blank. Returns the matplotlib Axes.
    """
    from matplotlib.patches import Rectangle

    S, labels = _check_matrix_for_plot(S, classes)
    first = {c: i for i, c in reversed(list(enumerate(labels.tolist())))}
    order = np.array(sorted(range(labels.size), key=lambda i: first[labels[i]]), dtype=int)
    S, labels = S[np.ix_(order, order)], labels[order]
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6, 5))
    image = ax.imshow(np.ma.masked_invalid(S), cmap=cmap, interpolation="nearest")
    for a, b in _class_runs(labels):
        ax.add_patch(Rectangle((a - 0.5, a - 0.5), b - a, b - a, fill=False, edgecolor="red",
                               linewidth=1.5, label="_class_block"))
        if a > 0:
            ax.axhline(a - 0.5, color="white", linewidth=0.6)
            ax.axvline(a - 0.5, color="white", linewidth=0.6)
    n = labels.size
    step = max(1, n // 24)
    ticks = np.arange(0, n, step)
    ax.set_xticks(ticks, [str(order[t] + 1) for t in ticks], fontsize=7)
    ax.set_yticks(ticks, [str(order[t] + 1) for t in ticks], fontsize=7)
    ax.set_xlabel("posterior (outlined: its class)")
    ax.set_ylabel("posterior (outlined: its class)")
    if title:
        ax.set_title(title)
    if colorbar:
        ax.figure.colorbar(image, ax=ax, label="similarity")
    return ax


def _check_matrix_for_plot(S: Any, classes: Any) -> tuple[np.ndarray, np.ndarray]:
    S = np.asarray(S, dtype=np.float64)
    if S.ndim != 2 or S.shape[0] != S.shape[1]:
        raise ValueError(f"S must be a square similarity matrix; got shape {S.shape}")
    labels = np.asarray(classes)
    if labels.ndim != 1 or labels.shape[0] != S.shape[0]:
        raise ValueError(f"classes must hold one label per row of S ({S.shape[0]}); "
                         f"got shape {labels.shape}")
    return S, labels
