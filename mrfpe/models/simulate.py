"""Draw configurations of a compiled discrete MRF: Gibbs and Swendsen-Wang sweeps.

``simulate(design, psi, n)`` samples ``p(x) ∝ exp(sum_i node[i, x_i] + sum_e
pair[e, x_i, x_j])`` with the tables of :meth:`Design.tables` at one feature
vector ``psi``:

* ``"gibbs"``: single-site Gibbs sampling (Geman & Geman 1984), one colour
  class of the graph's proper colouring at a time (the checkerboard sweep of a
  4-neighbour lattice, generalised): nodes of one colour are conditionally
  independent, so each class is updated in parallel, and since node ``i``
  always uses the ``i``-th uniform of the sweep the draws do not depend on the
  number of threads;
* ``"swendsen_wang"``: cluster updates (Swendsen & Wang 1987) for ferromagnetic
  Potts pair tables ``J_e [a == b] + f_e(a) + f_e(b) + c_e`` with ``J_e >= 0``
  (every symmetric ferromagnetic table when ``q = 2``); ``f_e`` moves into the
  node potentials. Bonds join equal neighbours with probability
  ``1 - exp(-J_e)``; each cluster then takes state ``a`` with probability
  ``∝ exp(sum_{i in cluster} node[i, a])``;
* ``"auto"``: Swendsen-Wang where the tables allow it, else Gibbs.

``-inf`` log-potentials forbid states. A Gibbs site whose every state is
forbidden by its neighbours (only outside the support, e.g. from a random
start) takes the state with the fewest forbidden pairs; every returned draw is
checked to have positive probability.

Every random number comes from ``numpy.random.default_rng(seed)``: uniforms
are drawn per sweep (one per node; for Swendsen-Wang also one per edge) and
passed to the numba kernels.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, prange

from mrfpe.models.design import Design, check_configurations
from mrfpe.threads import configure_vector_width, thread_budget
from mrfpe.validation import check_seed

configure_vector_width()  # before our first @njit, as mrfpe.targets.kernels does

__all__ = ["METHODS", "simulate", "swendsen_wang_form"]

METHODS = ("auto", "gibbs", "swendsen_wang")
#: Uniforms drawn (and passed to a kernel) at a time; bounds the memory of one call.
_CHUNK = 1 << 22
#: Nodes per parallel chunk of a colour class.
_BLOCK = 4096


@njit(inline="always", cache=True)
def _pick(w: np.ndarray, u: float) -> int:
    """Inverse-CDF draw from weights ``w >= 0``; ``-1`` if they (nearly) underflow."""
    total = 0.0
    for a in range(w.size):
        total += w[a]
    if not total > 1e-280:
        return -1
    target, acc, last = u * total, 0.0, 0
    for a in range(w.size):
        acc += w[a]
        if target < acc:
            return a
        if w[a] > 0.0:
            last = a
    return last  # u * total rounded up to total


@njit(inline="always", cache=True)
def _draw(w: np.ndarray, u: float) -> int:
    """Inverse-CDF draw from log-weights ``w`` (overwritten); ``-1`` if every one is -inf."""
    m = w.max()
    if m == -np.inf:
        return -1
    for a in range(w.size):
        w[a] = np.exp(w[a] - m)
    return _pick(w, u)


@njit(inline="always", cache=True)
def _site(i, x, node, pair, enode, epair, indptr, nbr, ntab, u, w, viol) -> None:
    """Gibbs update of node ``i`` from its full conditional.

    Fast path: weights as products of the exponentiated tables (no ``exp`` per
    site); on underflow, log-weights; outside the support, fewest -inf pairs.
    """
    q = w.size
    r = i if node.shape[0] > 1 else 0
    for a in range(q):
        w[a] = enode[r, a]
    for k in range(indptr[i], indptr[i + 1]):
        t, c = ntab[k], x[nbr[k]]
        for a in range(q):
            w[a] *= epair[t, c, a]
    a = _pick(w, u)
    if a < 0:
        for b in range(q):
            w[b] = node[r, b]
            viol[b] = 0.0 if node[r, b] > -np.inf else np.inf
        for k in range(indptr[i], indptr[i + 1]):
            t, c = ntab[k], x[nbr[k]]
            for b in range(q):
                if pair[t, c, b] == -np.inf:
                    viol[b] += 1.0
                else:
                    w[b] += pair[t, c, b]
        least = viol.min()
        for b in range(q):
            if viol[b] > least:
                w[b] = -np.inf
        a = _draw(w, u)
    x[i] = a


@njit(cache=True, parallel=True)
def _gibbs(x, order, cptr, node, pair, enode, epair, indptr, nbr, ntab, u, slot, out) -> None:
    """``u.shape[0]`` colour-class sweeps; after sweep ``s`` store ``x`` in ``out[slot[s]]``."""
    q = pair.shape[2]
    for s in range(u.shape[0]):
        for c in range(cptr.size - 1):
            lo, hi = cptr[c], cptr[c + 1]
            for b in prange((hi - lo + _BLOCK - 1) // _BLOCK):
                w, viol = np.empty(q), np.empty(q)
                for k in range(lo + b * _BLOCK, min(hi, lo + (b + 1) * _BLOCK)):
                    i = order[k]
                    _site(i, x, node, pair, enode, epair, indptr, nbr, ntab, u[s, i], w, viol)
        if slot[s] >= 0:
            out[slot[s]] = x


@njit(inline="always", cache=True)
def _find(parent: np.ndarray, i: int) -> int:
    while parent[i] != i:
        parent[i] = parent[parent[i]]  # path halving
        i = parent[i]
    return i


@njit(cache=True)
def _swendsen_wang(x, node, edges, etab, p_bond, u_bond, u_node, slot, out) -> None:
    """``u_bond.shape[0]`` Swendsen-Wang sweeps (union-find clusters, rooted at their min node)."""
    n, q = x.size, node.shape[1]
    parent, size = np.empty(n, np.int64), np.empty(n, np.int64)
    start, members, w = np.empty(n + 1, np.int64), np.empty(n, np.int64), np.empty(q)
    for s in range(u_bond.shape[0]):
        for i in range(n):
            parent[i] = i
        for e in range(edges.shape[0]):
            i, j = edges[e, 0], edges[e, 1]
            if x[i] == x[j] and u_bond[s, e] < p_bond[etab[e]]:
                ri, rj = _find(parent, i), _find(parent, j)
                parent[max(ri, rj)] = min(ri, rj)
        size[:] = 0
        for i in range(n):
            parent[i] = _find(parent, i)
            size[parent[i]] += 1
        start[0] = 0
        for r in range(n):
            start[r + 1] = start[r] + size[r]
        size[:] = 0
        for i in range(n):  # members of each cluster, contiguous
            members[start[parent[i]] + size[parent[i]]] = i
            size[parent[i]] += 1
        for r in range(n):
            if size[r] == 0:
                continue
            w[:] = 0.0
            for k in range(start[r], start[r + 1]):
                w += node[members[k] if node.shape[0] > 1 else 0]
            a = _draw(w, u_node[s, r])
            if a >= 0:  # always, from a start in the node support
                for k in range(start[r], start[r + 1]):
                    x[members[k]] = a
        if slot[s] >= 0:
            out[slot[s]] = x


def _tables(design: Design, psi: Any) -> tuple[np.ndarray, np.ndarray]:
    """Node ``(n|1, q)`` and pair ``(T|E, q, q)`` log-potentials; ``-inf`` psi entries kept.

    ``Design.tables`` multiplies zero features by ``-inf`` (NaN); here a ``-inf``
    entry of ``psi`` forbids exactly the states whose feature is positive.
    """
    psi = np.asarray(psi, dtype=np.float64)
    if psi.shape != (design.n_features,):
        raise ValueError(f"psi must be one feature vector ({design.n_features},); got "
                         f"{psi.shape}")
    if np.any(np.isnan(psi) | (psi == np.inf)):
        raise ValueError("psi must hold finite numbers or -inf (a forbidden state); got NaN "
                         "or +inf")
    fin = np.isfinite(psi)
    node, pair = (t[0] for t in design.tables(np.where(fin, psi, 0.0)))
    if not fin.all():
        for tab, feat in ((node, design.node), (pair, design.pair)):
            f = feat[..., ~fin]
            if np.any(f < 0):
                raise ValueError("psi is -inf where a feature is negative (a +inf "
                                 "log-potential); -inf must meet nonnegative features")
            tab[(f > 0).any(axis=-1)] = -np.inf
    return node, pair


def swendsen_wang_form(pair: np.ndarray, tol: float = 1e-9
                       ) -> tuple[np.ndarray, np.ndarray] | str:
    """``(J (K,), f (K, q))`` with ``pair[k] = J_k [a == b] + f_k(a) + f_k(b) + c_k``, ``J >= 0``.

    Returns a string saying why not when a table is not of that form.
    """
    if not np.all(np.isfinite(pair)):
        return "it needs finite pair log-potentials (the tables hold -inf)"
    q = pair.shape[1]
    d = np.diagonal(pair, axis1=1, axis2=2)
    f = (d - d[:, :1]) / 2
    off = (pair - f[:, :, None] - f[:, None, :])[:, ~np.eye(q, dtype=bool)]
    c = off[:, 0]
    scale = tol * (1.0 + np.abs(pair).max(initial=0.0))
    bad = np.flatnonzero(np.any(np.abs(off - c[:, None]) > scale, axis=1))
    if bad.size:
        return (f"pair table {bad[0]} is not J [a == b] plus per-state terms "
                f"(off-diagonal entries differ)")
    J = d[:, 0] - c
    if np.any(J < -scale):
        k = int(np.argmin(J))
        return f"pair table {k} has J = {J[k]:.3g} < 0 (antiferromagnetic)"
    return np.maximum(J, 0.0), f


def _init(init: Any, design: Design, node: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    g, q = design.graph, design.q
    allowed = np.broadcast_to(node > -np.inf, (g.n_nodes, q))
    if isinstance(init, str):
        if init != "random":
            raise ValueError(f"init must be 'random' or an array of states; got {init!r}")
        cum = np.cumsum(allowed, axis=1)  # uniform over each node's allowed states
        k = np.floor(rng.random(g.n_nodes) * cum[:, -1])
        return (cum <= k[:, None]).sum(axis=1).astype(np.int64)
    arr = np.asarray(init)
    if arr.shape not in ((g.n_nodes,), g.shape):
        raise ValueError(f"init must be 'random' or one configuration of shape ({g.n_nodes},)"
                         + (f" or {g.shape}" if g.shape is not None else "")
                         + f"; got shape {arr.shape}")
    x = check_configurations(arr.reshape(-1), q, (g.n_nodes,), "init")[0].copy()
    bad = np.flatnonzero(~allowed[np.arange(g.n_nodes), x])
    if bad.size:
        raise ValueError(f"init puts node {bad[0]} in state {x[bad[0]]}, which its node "
                         f"potential forbids (-inf)")
    return x


def _int(name: str, value: Any, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
        raise ValueError(f"{name} must be an integer >= {low}; got {value!r}")
    return int(value)


def simulate(design: Design, psi: np.ndarray, n: int = 1, *, seed: int | None = None,
             method: str = "auto", n_sweeps: int = 200, thin: int = 10,
             init: Any = "random") -> np.ndarray:
    """Draw ``n`` configurations of ``design`` at feature vector ``psi``.

    Parameters
    ----------
    design : Design
    psi : (P,)
        One feature vector (``design.psi(theta)[0]``); ``-inf`` entries forbid states.
    n : int >= 1
    seed : int or None
        Every random number comes from ``numpy.random.default_rng(seed)``.
    method : "auto", "gibbs" or "swendsen_wang"
        Colour-parallel Gibbs sweeps (Geman & Geman 1984) or Swendsen-Wang
        cluster sweeps (Swendsen & Wang 1987; ferromagnetic Potts pair tables
        only); ``"auto"`` takes Swendsen-Wang where it applies.
    n_sweeps : int >= 0
        Burn-in: the first draw is the state after ``n_sweeps`` sweeps.
    thin : int >= 1
        Sweeps between successive draws.
    init : "random" or (n_nodes,) / lattice-shaped int array
        Starting states (``"random"``: uniform over each node's allowed states).

    Returns
    -------
    (n, n_nodes) int64
    """
    if not isinstance(design, Design):
        raise ValueError(f"design must be an mrfpe.models.design.Design; got "
                         f"{type(design).__name__}")
    n, n_sweeps, thin = _int("n", n, 1), _int("n_sweeps", n_sweeps, 0), _int("thin", thin, 1)
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    rng = np.random.default_rng(check_seed(seed))
    g, q = design.graph, design.q
    node, pair = _tables(design, psi)
    dead = np.flatnonzero(np.all(node == -np.inf, axis=1))
    if dead.size:
        raise ValueError(f"every state of node {dead[0]} has log-potential -inf: the model "
                         f"has no configuration of positive probability")
    form = None if method == "gibbs" else swendsen_wang_form(pair)
    if method == "swendsen_wang" and isinstance(form, str):
        raise ValueError(f"method='swendsen_wang' needs ferromagnetic Potts pair tables "
                         f"(J [a == b] + per-state terms, J >= 0): {form}")
    x = _init(init, design, node, rng)
    etab = (np.arange(g.n_edges) if design.pair_per_edge else g.edge_type).astype(np.int64)
    out = np.empty((n, g.n_nodes), dtype=np.int64)
    total = n_sweeps + (n - 1) * thin
    when = n_sweeps + thin * np.arange(n)  # draw k: the state after sweep when[k]
    slot = np.full(total, -1, dtype=np.int64)  # slot[s]: the draw taken after sweep s + 1
    slot[when[when > 0] - 1] = np.flatnonzero(when > 0)
    if when[0] == 0:
        out[0] = x
    if isinstance(form, tuple):
        J, f = form
        if np.any(f != 0):  # per-state edge terms become node potentials
            e = g.edges
            node = np.broadcast_to(node, (g.n_nodes, q)) + np.stack(
                [np.bincount(e[:, 0], f[etab, a], g.n_nodes)
                 + np.bincount(e[:, 1], f[etab, a], g.n_nodes) for a in range(q)], axis=1)
        node = np.ascontiguousarray(node)
        p_bond = -np.expm1(-J)
        per = max(1, _CHUNK // (g.n_nodes + g.n_edges))
        for s in range(0, total, per):
            k = min(per, total - s)
            _swendsen_wang(x, node, g.edges, etab, p_bond, rng.random((k, g.n_edges)),
                           rng.random((k, g.n_nodes)), slot[s:s + k], out)
    else:
        indptr, nbr, eidx = g.neighbours()
        classes = g.colour_classes()
        order = np.concatenate(classes).astype(np.int64)
        cptr = np.concatenate([[0], np.cumsum([c.size for c in classes])]).astype(np.int64)
        # symmetric tables: pair[t, x_j] is the row of node i's states, contiguous
        args = (order, cptr, np.ascontiguousarray(node), np.ascontiguousarray(pair),
                _exp_rows(node), _exp_rows(pair), indptr, nbr, etab[eidx])
        per = max(1, _CHUNK // g.n_nodes)
        with thread_budget(g.n_nodes * q * 8):
            for s in range(0, total, per):
                k = min(per, total - s)
                _gibbs(x, *args, rng.random((k, g.n_nodes)), slot[s:s + k], out)
    _check_support(out, g.edges, etab, pair)
    return out


def _exp_rows(t: np.ndarray) -> np.ndarray:
    """``exp(t - max of its row)`` (rows of all -inf give zeros), C-contiguous."""
    m = t.max(axis=-1, keepdims=True)
    return np.ascontiguousarray(np.exp(t - np.where(np.isfinite(m), m, 0.0)))


def _check_support(out: np.ndarray, edges: np.ndarray, etab: np.ndarray,
                   pair: np.ndarray) -> None:
    """Raise if a draw has a forbidden (``-inf``) pair: the chain never reached the support."""
    if np.all(np.isfinite(pair)):
        return
    for k, x in enumerate(out):
        bad = np.flatnonzero(pair[etab, x[edges[:, 0]], x[edges[:, 1]]] == -np.inf)
        if bad.size:
            i, j = edges[bad[0]]
            raise ValueError(f"draw {k} still joins nodes {i} and {j} in a forbidden pair of "
                             f"states (-inf): the chain has not reached a configuration of "
                             f"positive probability; raise n_sweeps or start from such an init")
