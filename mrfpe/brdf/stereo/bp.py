"""Max-product loopy belief propagation on a 4-connected lattice (thesis 6.3.2-6.3.4).

Everything is in the log domain: with energies ``E = -log(potential)`` the
max-product updates become min-sum, the normaliser ``kappa`` becomes an
additive constant (each message is shifted to have minimum 0), and the
beliefs are exponentiated and normalised per node at the end.

Model (6.25-6.30): data energy ``E_s(x_s)`` (the local evidence ``psi_d``)
and a pairwise energy ``V(x_s, x_t)`` (``psi_p``) on every edge of the
4-neighbourhood. ``V`` depends only on the two disparities (6.16); the robust
choices of 6.2.1 are offered by :class:`Smoothness`:

* ``"linear"``: truncated linear ``lambda * min(|d_s - d_t|, tau)``
* ``"quadratic"``: truncated quadratic ``lambda * min((d_s - d_t)^2, tau)``
* ``"robust"``: the thesis's 6.24, ``-lambda ln((1 - e_p) exp(-|d_s - d_t| / sigma_p) + e_p)``

Schedules
---------
``"parallel"`` (6.33): every message of iteration ``i + 1`` is computed from
the messages of iteration ``i``. ``"accelerated"`` (6.38-6.41, Tappen &
Freeman): four sequential sweeps per iteration -- right-to-left updating the
messages from the right, top-to-bottom (from above), left-to-right (from the
left), bottom-to-top (from below) -- each message used as soon as it is
computed, so information crosses the lattice in one iteration.

Final beliefs (6.34) ``b_s ∝ exp(-(E_s + sum_k m_ks))``, the MAP label 6.35
is their argmax. ``damping`` ``g`` replaces each new message ``m`` by
``(1 - g) m + g m_old`` (in energies, i.e. a geometric mixture of
probabilities, Murphy et al. [83]).

Kernels are numba-compiled: one call per sweep (accelerated) or per
iteration (parallel). Sweeps are sequential on purpose -- a sweep front is a
dependency chain, and parallelising across it (``prange``) was measured ~50x
slower in the prototype. Truncated-linear messages on evenly spaced labels use
Felzenszwalb & Huttenlocher's O(L) distance transform; everything else the
O(L^2) minimisation over a precomputed ``V`` table.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from mrfpe.threads import configure_vector_width

# numba fixes its vector width at the first @njit of the process (mrfpe.threads)
configure_vector_width()

__all__ = ["SCHEDULES", "SMOOTHNESS_KINDS", "BPResult", "Smoothness", "labelling_energy",
           "loopy_bp"]

SCHEDULES = ("accelerated", "parallel")
SMOOTHNESS_KINDS = ("linear", "quadratic", "robust")


@dataclass(frozen=True)
class Smoothness:
    """Robust pairwise potential ``psi_p`` on disparity differences in pixels (6.2.1, 6.24).

    Parameters
    ----------
    kind : {"linear", "quadratic", "robust"}
    weight : float
        ``lambda`` (>= 0).
    truncation : float
        ``tau`` (> 0; ``inf`` for no truncation) for "linear" / "quadratic".
    e_p, sigma_p : float
        Parameters of 6.24 for "robust".
    """

    kind: str = "linear"
    weight: float = 1.0
    truncation: float = 2.0
    e_p: float = 0.01
    sigma_p: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in SMOOTHNESS_KINDS:
            raise ValueError(f"smoothness kind must be one of {SMOOTHNESS_KINDS}; "
                             f"got {self.kind!r}")
        w = float(self.weight)
        if not np.isfinite(w) or w < 0:
            raise ValueError(f"smoothness must be finite and >= 0; got {self.weight!r}")
        t = float(self.truncation)
        if np.isnan(t) or t <= 0:
            raise ValueError(f"truncation must be > 0 (inf allowed); got {self.truncation!r}")
        if not 0.0 <= float(self.e_p) < 1.0:
            raise ValueError(f"e_p must be in [0, 1); got {self.e_p!r}")
        if not float(self.sigma_p) > 0:
            raise ValueError(f"sigma_p must be > 0; got {self.sigma_p!r}")

    def table(self, disparities: Any) -> np.ndarray:
        """``V[a, b] = psi_p(d_a, d_b)`` for all label pairs, (L, L)."""
        d = np.asarray(disparities, dtype=np.float64)
        diff = np.abs(d[:, None] - d[None, :])
        if self.kind == "linear":
            return self.weight * np.minimum(diff, self.truncation)
        if self.kind == "quadratic":
            return self.weight * np.minimum(diff * diff, self.truncation)
        with np.errstate(divide="ignore"):
            return -self.weight * np.log((1 - self.e_p) * np.exp(-diff / self.sigma_p) + self.e_p)

    def distance_transform(self, disparities: Any) -> tuple[float, float] | None:
        """``(slope per label step, cap)`` for the O(L) linear kernel, or None if not applicable."""
        d = np.asarray(disparities, dtype=np.float64)
        if self.kind != "linear" or d.size < 2:
            return None
        step = np.diff(d)
        if not np.allclose(step, step[0], rtol=1e-9, atol=0.0) or step[0] <= 0:
            return None
        return float(self.weight * step[0]), float(self.weight * self.truncation)


@dataclass
class BPResult:
    """Result of :func:`loopy_bp`.

    Attributes
    ----------
    labels : ndarray (R, C) of int
        MAP label index per node (6.35).
    beliefs : ndarray (R, C, L)
        Max-product beliefs (6.34), normalised to sum to 1 per node.
    energy : ndarray (T + 1,)
        Energy of the MAP labelling before BP (``energy[0]``, the data-only
        winner-take-all labelling) and after each iteration.
    """

    labels: np.ndarray
    beliefs: np.ndarray
    energy: np.ndarray


# ------------------------------------------------------------------------------ kernels
@njit(cache=True, nogil=True)
def _send(h, V, dt, slope, cap, out):  # pragma: no cover - numba
    """out[b] = min_a h[a] + V[a, b], shifted to minimum 0 (kappa of 6.33)."""
    L = h.shape[0]
    if dt:
        hmin = h[0]
        for a in range(L):
            out[a] = h[a]
            if h[a] < hmin:
                hmin = h[a]
        for b in range(1, L):
            v = out[b - 1] + slope
            if v < out[b]:
                out[b] = v
        for b in range(L - 2, -1, -1):
            v = out[b + 1] + slope
            if v < out[b]:
                out[b] = v
        c = hmin + cap
        for b in range(L):
            if out[b] > c:
                out[b] = c
    else:
        for b in range(L):
            best = np.inf
            for a in range(L):
                v = h[a] + V[a, b]
                if v < best:
                    best = v
            out[b] = best
    m = out[0]
    for b in range(1, L):
        if out[b] < m:
            m = out[b]
    for b in range(L):
        out[b] -= m


@njit(cache=True, nogil=True)
def _store(dst, out, damping):  # pragma: no cover - numba
    """dst <- (1 - g) out + g dst, renormalised to minimum 0."""
    L = out.shape[0]
    if damping > 0.0:
        m = np.inf
        for b in range(L):
            v = (1.0 - damping) * out[b] + damping * dst[b]
            out[b] = v
            if v < m:
                m = v
        for b in range(L):
            dst[b] = out[b] - m
    else:
        for b in range(L):
            dst[b] = out[b]


@njit(cache=True, nogil=True)
def _sweep(E, M, A, B, reverse, lines_outer, V, dt, slope, cap,
           damping):  # pragma: no cover - numba
    """One accelerated sweep along axis 1 (6.38-6.41).

    Updates ``M[:, c]`` -- the message node ``(i, c)`` receives from its
    neighbour ``(i, s)``, ``s = c - 1`` (forward) or ``c + 1`` (reverse) --
    column after column, from ``E + M + A + B`` at the sender: its evidence,
    the message it got from further back along the sweep (already updated)
    and the two messages across the sweep. Vertical sweeps pass transposed views.

    Within a sweep the lines ``i`` are independent (``A`` and ``B`` are not
    written), so ``lines_outer`` only chooses the memory-friendly loop order;
    the result is identical.
    """
    R, C, L = E.shape
    h = np.empty(L)
    out = np.empty(L)
    if lines_outer:
        for i in range(R):
            for n in range(C - 1):
                c = C - 2 - n if reverse else n + 1
                s = c + 1 if reverse else c - 1
                for k in range(L):
                    h[k] = E[i, s, k] + M[i, s, k] + A[i, s, k] + B[i, s, k]
                _send(h, V, dt, slope, cap, out)
                _store(M[i, c], out, damping)
    else:
        for n in range(C - 1):
            c = C - 2 - n if reverse else n + 1
            s = c + 1 if reverse else c - 1
            for i in range(R):
                for k in range(L):
                    h[k] = E[i, s, k] + M[i, s, k] + A[i, s, k] + B[i, s, k]
                _send(h, V, dt, slope, cap, out)
                _store(M[i, c], out, damping)


@njit(cache=True, nogil=True)
def _map_labels(E, Ml, Mr, Mu, Md, labels):  # pragma: no cover - numba
    """labels[i, j] = argmin_k E + Ml + Mr + Mu + Md (the MAP of 6.35)."""
    R, C, L = E.shape
    for i in range(R):
        for j in range(C):
            best = np.inf
            arg = 0
            for k in range(L):
                v = E[i, j, k] + Ml[i, j, k] + Mr[i, j, k] + Mu[i, j, k] + Md[i, j, k]
                if v < best:
                    best = v
                    arg = k
            labels[i, j] = arg


@njit(cache=True, nogil=True)
def _parallel_step(E, Ml, Mr, Mu, Md, nMl, nMr, nMu, nMd, V, dt, slope, cap,
                   damping):  # pragma: no cover - numba
    """All messages of iteration i+1 from those of iteration i (6.33).

    ``Ml[i, j]`` is the message node (i, j) receives from its left neighbour,
    ``Mr`` from the right, ``Mu`` from above, ``Md`` from below. Node (i, j)'s
    message to a neighbour excludes what that neighbour sent it.
    """
    R, C, L = E.shape
    h = np.empty(L)
    out = np.empty(L)
    for i in range(R):
        for j in range(C):
            if j + 1 < C:  # to the right neighbour: arrives there "from the left"
                for k in range(L):
                    h[k] = E[i, j, k] + Ml[i, j, k] + Mu[i, j, k] + Md[i, j, k]
                _send(h, V, dt, slope, cap, out)
                nMl[i, j + 1] = Ml[i, j + 1]
                _store(nMl[i, j + 1], out, damping)
            if j > 0:
                for k in range(L):
                    h[k] = E[i, j, k] + Mr[i, j, k] + Mu[i, j, k] + Md[i, j, k]
                _send(h, V, dt, slope, cap, out)
                nMr[i, j - 1] = Mr[i, j - 1]
                _store(nMr[i, j - 1], out, damping)
            if i + 1 < R:
                for k in range(L):
                    h[k] = E[i, j, k] + Ml[i, j, k] + Mr[i, j, k] + Mu[i, j, k]
                _send(h, V, dt, slope, cap, out)
                nMu[i + 1, j] = Mu[i + 1, j]
                _store(nMu[i + 1, j], out, damping)
            if i > 0:
                for k in range(L):
                    h[k] = E[i, j, k] + Ml[i, j, k] + Mr[i, j, k] + Md[i, j, k]
                _send(h, V, dt, slope, cap, out)
                nMd[i - 1, j] = Md[i - 1, j]
                _store(nMd[i - 1, j], out, damping)


# ------------------------------------------------------------------------------ driver
def labelling_energy(costs: np.ndarray, V: np.ndarray, labels: np.ndarray) -> float:
    """``sum_s E_s(x_s) + sum_{edges} V(x_s, x_t)`` of a labelling (the MRF energy of 6.25)."""
    data = np.take_along_axis(costs, labels[:, :, None], axis=2).sum()
    pair = V[labels[:, :-1], labels[:, 1:]].sum() + V[labels[:-1, :], labels[1:, :]].sum()
    return float(data + pair)


def _beliefs(costs: np.ndarray, msgs: list[np.ndarray]) -> np.ndarray:
    """Total energy ``E_s + sum_k m_ks`` per node and label (the negative log of 6.34)."""
    tot = costs.copy()
    for m in msgs:
        tot += m
    return tot


def loopy_bp(costs: Any, V: Any, *, schedule: str = "accelerated", iterations: int = 10,
             damping: float = 0.0, linear: tuple[float, float] | None = None) -> BPResult:
    """Max-product (min-sum) loopy BP on a 4-connected lattice.

    Parameters
    ----------
    costs : (R, C, L)
        Data energy of every node and label (finite).
    V : (L, L)
        Pairwise energy table, ``V[a, b]`` for sender label ``a``, receiver ``b``.
    schedule : {"accelerated", "parallel"}
    iterations : int >= 0
    damping : float in [0, 1)
    linear : (slope, cap) or None
        If given, ``V`` is the truncated linear ``min(slope |a - b|, cap)`` on
        label indices and the O(L) distance transform is used instead of the table.

    Returns
    -------
    BPResult
    """
    E = np.ascontiguousarray(costs, dtype=np.float64)
    if E.ndim != 3 or min(E.shape) < 1:
        raise ValueError(f"costs must have shape (R, C, L) with R, C, L >= 1; got {E.shape}")
    if not np.all(np.isfinite(E)):
        raise ValueError("costs must be finite")
    L = E.shape[2]
    V = np.ascontiguousarray(V, dtype=np.float64)
    if V.shape != (L, L) or not np.all(np.isfinite(V)):
        raise ValueError(f"V must be a finite ({L}, {L}) table; got shape {V.shape}")
    if schedule not in SCHEDULES:
        raise ValueError(f"schedule must be one of {SCHEDULES}; got {schedule!r}")
    if isinstance(iterations, bool) or not isinstance(iterations, int | np.integer) \
            or iterations < 0:
        raise ValueError(f"iterations must be an integer >= 0; got {iterations!r}")
    damping = float(damping)
    if not 0.0 <= damping < 1.0:
        raise ValueError(f"damping must be in [0, 1); got {damping!r}")
    dt, slope, cap = (False, 0.0, 0.0) if linear is None else (True, *map(float, linear))

    Ml, Mr, Mu, Md = (np.zeros_like(E) for _ in range(4))
    labels = np.argmin(E, axis=2)
    energy = [labelling_energy(E, V, labels)]
    for _ in range(int(iterations)):
        if schedule == "accelerated":
            T = (lambda a: a.transpose(1, 0, 2))  # noqa: E731 - vertical sweeps on views
            args = (V, dt, slope, cap, damping)
            _sweep(E, Mr, Mu, Md, True, True, *args)             # 6.38 right to left
            _sweep(T(E), T(Mu), T(Ml), T(Mr), False, False, *args)  # 6.39 top to bottom
            _sweep(E, Ml, Mu, Md, False, True, *args)            # 6.40 left to right
            _sweep(T(E), T(Md), T(Ml), T(Mr), True, False, *args)  # 6.41 bottom to top
        else:
            new = [np.zeros_like(E) for _ in range(4)]
            _parallel_step(E, Ml, Mr, Mu, Md, *new, V, dt, slope, cap, damping)
            Ml, Mr, Mu, Md = new
        _map_labels(E, Ml, Mr, Mu, Md, labels)
        energy.append(labelling_energy(E, V, labels))
    tot = _beliefs(E, [Ml, Mr, Mu, Md])
    labels = np.argmin(tot, axis=2)
    logp = -(tot - tot.min(axis=2, keepdims=True))
    p = np.exp(logp)
    p /= p.sum(axis=2, keepdims=True)
    return BPResult(labels=labels, beliefs=p, energy=np.asarray(energy))
