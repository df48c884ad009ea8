"""Draw configurations of a compiled discrete MRF by Gibbs or Swendsen-Wang sweeps.

``simulate(design, psi, n)`` samples ``p(x) ∝ exp(sum_i node[i, x_i] + sum_e pair[e,
x_i, x_j])``, the tables of :meth:`Design.tables` at one ``psi``. ``"gibbs"``: single-site
Gibbs sampling (Geman & Geman 1984), one colour class at a time in parallel (the
checkerboard sweep, generalised). ``"swendsen_wang"``: cluster updates (Swendsen & Wang
1987) for pair tables ``J_e [a == b] + f_e(a) + f_e(b) + c_e`` with ``J_e >= 0``
(ferromagnetic Potts; any ferromagnetic table if q = 2), ``f_e`` moved to the node
potentials: bonds join equal neighbours with probability ``1 - exp(-J_e)``, each cluster
takes state ``a`` with probability ``∝ exp(sum_{i in cluster} node[i, a])``. ``"auto"``:
Swendsen-Wang where the tables allow it, else Gibbs.

``-inf`` log-potentials forbid states, and are counted apart from the finite ones (never
stood in for by a large negative number); tables that arc consistency shows to forbid every
configuration are refused before the run, and every draw is checked to hold none (from a
random start under hard pair constraints a Gibbs site takes a state with the fewest
forbidden pairs). The memory of the draws and the graph is checked before any work.
``numpy.random.default_rng(seed)`` draws the start and a key; the kernels compute
uniform ``s * n + i`` (node ``i``, sweep ``s``) from it with the counter-based SplitMix64
(Steele, Lea & Flood 2014), so the draws do not depend on the number of threads.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, prange

from mrfpe.budget import check_memory
from mrfpe.models.design import Design, check_configurations
from mrfpe.models.gibbs_sites import _draw, _site, _uniform
from mrfpe.models.graph import LatticeSpec, _check_shape
from mrfpe.models.lattice_gibbs import lattice_stencil, run_lattice
from mrfpe.threads import configure_vector_width, thread_budget
from mrfpe.validation import check_positive_int, check_seed

configure_vector_width()  # before our first @njit, as mrfpe.brdf.engine does

__all__ = ["METHODS", "check_run", "check_simulation_size", "graph_size", "simulate",
           "swendsen_wang_form"]

METHODS = ("auto", "gibbs", "swendsen_wang")
_BLOCK = 4096  # nodes per parallel chunk of a colour class
@njit(cache=True, parallel=True)
def _gibbs(x, order, cptr, node, pair, enode, epair, indptr, nbr, ntab, key, slot, out) -> None:
    """``slot.size`` sweeps over the colour classes ``order[cptr[c]:cptr[c + 1]]``; after
    sweep ``s`` store ``x`` in ``out[slot[s]]`` (if ``>= 0``)."""
    n, q = x.size, pair.shape[2]
    for s in range(slot.size):
        for c in range(cptr.size - 1):
            lo, hi = cptr[c], cptr[c + 1]
            for b in prange((hi - lo + _BLOCK - 1) // _BLOCK):
                w = np.empty(q)
                for k in range(lo + b * _BLOCK, min(hi, lo + (b + 1) * _BLOCK)):
                    i = order[k]
                    _site(i, x, node, pair, enode, epair, indptr, nbr, ntab,
                          _uniform(key, s * n + i), w)
        if slot[s] >= 0:
            out[slot[s]] = x


@njit(inline="always", cache=True)
def _find(parent: np.ndarray, i: int) -> int:
    while parent[i] != i:
        parent[i] = parent[parent[i]]  # path halving
        i = parent[i]
    return i


@njit(cache=True)
def _swendsen_wang(x, node, edges, etab, p_bond, key, slot, out) -> None:
    """``slot.size`` Swendsen-Wang sweeps: union-find clusters rooted at their least node."""
    n, q, m, shared = x.size, node.shape[1], x.size + edges.shape[0], node.shape[0] == 1
    parent, size, new = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
    W, w = np.empty((1 if shared else n, q)), np.empty(q)  # W[root]: the cluster's sum
    for s in range(slot.size):
        parent[:] = np.arange(n)
        for e in range(edges.shape[0]):  # bonds between equal neighbours
            i, j = edges[e, 0], edges[e, 1]
            if x[i] == x[j] and _uniform(key, s * m + e) < p_bond[etab[e]]:
                ri, rj = _find(parent, i), _find(parent, j)
                parent[max(ri, rj)] = min(ri, rj)
        size[:], W[:] = 0, 0.0
        for i in range(n):
            parent[i] = _find(parent, i)
            size[parent[i]] += 1
            for a in range(0 if shared else q):
                W[parent[i], a] += node[i, a]
        for r in range(n):  # each cluster's new state; always found from a start in the support
            if size[r] > 0:
                for a in range(q):
                    w[a] = size[r] * node[0, a] if shared else W[r, a]
                new[r] = _draw(w, _uniform(key, s * m + edges.shape[0] + r))
        for i in range(n):
            x[i] = new[parent[i]]
        if slot[s] >= 0:
            out[slot[s]] = x


def _tables(design: Design, psi: Any) -> tuple[np.ndarray, np.ndarray]:
    """Node ``(n|1, q)`` and pair ``(T|E, q, q)`` log-potentials at one ``psi``: ``-inf``
    where a positive feature meets a ``-inf`` entry of ``psi`` (:meth:`Design.tables`)."""
    psi = np.asarray(psi, dtype=np.float64)
    if psi.shape != (design.n_features,):
        raise ValueError(f"psi must be one feature vector ({design.n_features},); got "
                         f"shape {psi.shape}")
    fin = np.isfinite(psi)
    if np.any(np.isnan(psi) | (psi == np.inf)) or any(np.any(f[..., ~fin] < 0) for f in (
            design.node, design.pair)):
        raise ValueError("psi must hold finite numbers, or -inf (forbidden) where no feature "
                         "is negative")
    node, pair = design.tables(psi[None])
    return node[0], pair[0]


def swendsen_wang_form(pair: np.ndarray, tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray] | str:
    """``(J (K,), f (K, q))`` with ``pair[k] = J_k [a == b] + f_k(a) + f_k(b) + c_k``, ``J >= 0``;
    else a string saying why not."""
    if not np.all(np.isfinite(pair)):
        return "it needs finite pair log-potentials (the tables hold -inf)"
    d = np.diagonal(pair, axis1=1, axis2=2)
    f = (d - d[:, :1]) / 2
    off = (pair - f[:, :, None] - f[:, None, :])[:, ~np.eye(pair.shape[1], dtype=bool)]
    scale = tol * (1.0 + np.abs(pair).max(initial=0.0))
    if (bad := np.flatnonzero(np.any(np.abs(off - off[:, :1]) > scale, axis=1))).size:
        return f"pair table {bad[0]} is not J [a == b] plus per-state terms"
    J = d[:, 0] - off[:, 0]
    if np.any(J < -scale):
        return f"pair table {J.argmin()} has J = {J.min():.3g} < 0 (antiferromagnetic)"
    return np.maximum(J, 0.0), f


def _init(init: Any, design: Design, node: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    g, q = design.graph, design.q
    allowed = np.broadcast_to(node > -np.inf, (g.n_nodes, q))
    if isinstance(init, str):
        if init != "random":
            raise ValueError(f"init must be 'random' or an array of states; got {init!r}")
        cum = np.cumsum(allowed, axis=1)  # uniform over each node's allowed states
        return (cum <= np.floor(rng.random((g.n_nodes, 1)) * cum[:, -1:])).sum(1).astype(np.int64)
    arr = np.asarray(init)
    if arr.shape not in ((g.n_nodes,), g.shape):
        raise ValueError(f"init must be 'random' or one configuration of shape ({g.n_nodes},)"
                         + (f" or {g.shape}" if g.shape else "") + f"; got shape {arr.shape}")
    x = check_configurations(arr.reshape(-1), q, (g.n_nodes,), "init")[0].copy()
    if (bad := np.flatnonzero(~allowed[np.arange(g.n_nodes), x])).size:
        raise ValueError(f"init puts node {bad[0]} in state {x[bad[0]]}, which its node "
                         f"potential forbids (-inf)")
    return x


def simulate(design: Design, psi: np.ndarray, n: int = 1, *, seed: int | None = None,
             method: str = "auto", n_sweeps: int = 200, thin: int = 10,
             init: Any = "random") -> np.ndarray:
    """Draw ``n`` configurations of ``design`` at the feature vector ``psi``.

    Parameters
    ----------
    design : Design
    psi : (P,)
        One feature vector (``design.psi(theta)[0]``); ``-inf`` entries forbid states.
    n : int >= 1
    seed : int or None
        Every random number derives from ``numpy.random.default_rng(seed)``.
    method : "auto", "gibbs" or "swendsen_wang"
        Colour-parallel Gibbs sweeps (Geman & Geman 1984) or Swendsen-Wang
        cluster sweeps (Swendsen & Wang 1987; ferromagnetic Potts pair tables
        only, else ValueError); ``"auto"`` takes Swendsen-Wang where it applies.
    n_sweeps : int >= 0
        Burn-in: the first draw is the state after ``n_sweeps`` sweeps.
    thin : int >= 1
        Sweeps between successive draws (one chain).
    init : "random" or (n_nodes,) / lattice-shaped int array
        The start (``"random"``: uniform over each node's allowed states).

    Returns
    -------
    (n, n_nodes) int64
    """
    n, n_sweeps, thin = check_run(design, n, n_sweeps, thin, method)
    rng = np.random.default_rng(check_seed(seed))
    g, q = design.graph, design.q
    _check_memory(g.n_nodes, g.n_edges, n, n_sweeps, thin, g.shape or (g.n_nodes,))
    node, pair = _tables(design, psi)
    etab = np.arange(g.n_edges) if design.pair_per_edge else g.edge_type
    _check_support(design, node, pair, etab)
    form = None if method == "gibbs" else swendsen_wang_form(pair)
    if method == "swendsen_wang" and isinstance(form, str):
        raise ValueError(f"method='swendsen_wang' needs ferromagnetic Potts pair tables "
                         f"(J [a == b] + per-state terms, J >= 0): {form}")
    x = _init(init, design, node, rng)
    key = rng.integers(2**64, dtype=np.uint64)  # seeds the kernels' SplitMix64
    out = np.empty((n, g.n_nodes), dtype=np.int64)
    when = n_sweeps + thin * np.arange(n)  # draw k: the state after sweep when[k]
    slot = np.full(when[-1], -1, dtype=np.int64)  # slot[s]: the draw taken after sweep s + 1
    slot[when[when > 0] - 1] = np.flatnonzero(when > 0)
    out[0], e = x, g.edges  # out[0] kept if when[0] == 0
    if isinstance(form, tuple):
        J, f = form
        if np.any(f != 0):  # per-state edge terms become node potentials
            node = node + np.stack([np.bincount(e[:, 0], f[etab, a], g.n_nodes)
                                    + np.bincount(e[:, 1], f[etab, a], g.n_nodes)
                                    for a in range(q)], axis=1)
        _swendsen_wang(x, np.ascontiguousarray(node), e, etab, -np.expm1(-J), key, slot, out)
    else:
        classes = g.colour_classes()  # node ids of colour c: order[cptr[c]:cptr[c + 1]]
        order, cptr = np.concatenate(classes).astype(np.uint32), np.cumsum([0, *map(len, classes)])
        # unsigned states and indices: numba skips its negative-index wraparound (~1.8x faster)
        indptr, nbr, eidx = (a.astype(np.uint32) for a in g.neighbours())
        # symmetric tables: row t * q + x_j of the exponentiated pair tables weighs x_i
        tables = (np.ascontiguousarray(node), np.ascontiguousarray(pair), _exp_rows(node),
                  _exp_rows(pair).reshape(-1, q), indptr, nbr, etab[eidx].astype(np.uint32))
        with thread_budget(g.n_nodes * q // 4):  # threads from ~1.6e6 site-states a sweep
            if (stencil := lattice_stencil(design)) is None:
                _gibbs(x.astype(np.uint32), order, cptr, *tables, key, slot, out)
            else:  # the same draws by stencil arithmetic (mrfpe.models.lattice_gibbs)
                run_lattice(stencil, x, *tables, key, slot, out)
    hard = not np.all(np.isfinite(pair))  # then check that every draw is in the support
    if bad := [k for k, xk in enumerate(out)
               if hard and np.isneginf(pair[etab, xk[e[:, 0]], xk[e[:, 1]]]).any()]:
        raise ValueError(f"draw {bad[0]} holds a forbidden pair of states (-inf) after "
                         f"{n_sweeps + thin * bad[0]} sweeps: either the chain has not reached "
                         f"the support (raise n_sweeps, or give an init in it) or the pair "
                         f"constraints admit no configuration at all (e.g. too few states to "
                         f"colour the graph): check the potential's -inf entries")
    return out


#: Bytes of simulation work per node and per edge beyond the draws: the graph, its colouring
#: and neighbour lists, the tables' indices (measured on 4- and 8-neighbour lattices with
#: tracemalloc: about 50 a node and 110 an edge), with a margin.
_BYTES_PER_NODE, _BYTES_PER_EDGE = 64.0, 256.0


def _check_memory(n_nodes: int, n_edges: int, n: int, n_sweeps: int, thin: int,
                  shape: tuple[int, ...]) -> None:
    """Refuse, before any work, a simulation whose draws, sweep schedule and graph exceed
    the memory budget, naming ``n`` and ``shape``."""
    nbytes = (_BYTES_PER_NODE * n_nodes + _BYTES_PER_EDGE * n_edges + 8.0 * n * n_nodes
              + 8.0 * (n_sweeps + (thin + 1) * n))
    check_memory(nbytes, f"simulate(n={n}, shape={tuple(shape)}): {n} draw(s) of {n_nodes} "
                         f"nodes and {n_edges} edges", "draw fewer (n) or smaller (shape) "
                         "configurations")


def check_simulation_size(spec: Any, shape: Any, n: Any, n_sweeps: Any, thin: Any) -> None:
    """:func:`simulate`'s memory check, from a model's graph rule before its graph is built.

    ``spec`` is a :class:`~mrfpe.models.graph.LatticeSpec` (its edges bounded by one per
    node and offset) or a :class:`~mrfpe.models.graph.Graph`; a lattice without a
    ``shape`` is left to the model's own error.
    """
    n, n_sweeps = check_positive_int("n", n), check_positive_int("n_sweeps", n_sweeps, 0)
    thin = check_positive_int("thin", thin)
    if (size := graph_size(spec, shape)) is not None:
        n_nodes, n_edges, node_shape = size
        _check_memory(n_nodes, n_edges, n, n_sweeps, thin, node_shape)


def check_run(design: Any, n: Any, n_sweeps: Any, thin: Any, method: Any
              ) -> tuple[int, int, int]:
    """``(n, n_sweeps, thin)`` checked, and the design and method, for a simulator's call;
    ValueError naming the argument."""
    if not isinstance(design, Design):
        raise ValueError(f"design must be an mrfpe.models Design; got {type(design).__name__}")
    n, n_sweeps = check_positive_int("n", n), check_positive_int("n_sweeps", n_sweeps, 0)
    thin = check_positive_int("thin", thin)
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    return n, n_sweeps, thin


def graph_size(spec: Any, shape: Any) -> tuple[int, int, tuple[int, ...]] | None:
    """``(nodes, edges at most, node shape)`` of a model's graph rule before the graph is
    built (``None``: a lattice without a ``shape``, left to the model's own error)."""
    if isinstance(spec, LatticeSpec):
        if shape is None:
            return None
        H, W = _check_shape(shape)
        return H * W, H * W * len(spec.offsets), (H, W)
    return spec.n_nodes, spec.n_edges, (spec.n_nodes,)


def _check_support(design: Design, node: np.ndarray, pair: np.ndarray,
                   etab: np.ndarray, rounds: int = 20) -> None:
    """Refuse tables that forbid every configuration, where arc consistency shows it.

    A node's state survives a round if its node potential allows it and every
    neighbour keeps an allowed state that the joining pair table allows with it (AC-3;
    Mackworth 1977, in vectorised rounds). A node left with no state proves the support
    empty; rounds that remove nothing, or ``rounds`` of them, end the check (a support it
    does not refute may still be empty: the draws are checked after the run).
    """
    g, q = design.graph, design.q
    allowed = np.array(np.broadcast_to(node > -np.inf, (g.n_nodes, q)))
    if (dead := np.flatnonzero(~allowed.any(axis=1))).size:
        raise ValueError(f"every state of node {dead[0]} has log-potential -inf: the model "
                         f"has no configuration of positive probability")
    if np.all(np.isfinite(pair)):
        return
    ok, e = (pair > -np.inf).astype(np.float64), g.edges  # symmetric, as the tables are
    for _ in range(rounds):
        keep = allowed.copy()
        for s, d in ((0, 1), (1, 0)):  # the states of e[:, s] that e[:, d] can meet
            met = np.empty((g.n_edges, q), dtype=bool)
            if design.pair_per_edge:
                met[:] = np.einsum("eab,eb->ea", ok, allowed[e[:, d]]) > 0
            else:
                for t in range(ok.shape[0]):
                    on = etab == t
                    met[on] = allowed[e[on, d]] @ ok[t] > 0
            for a in range(q):
                keep[:, a] &= np.bincount(e[:, s], ~met[:, a], g.n_nodes) == 0
        if (dead := np.flatnonzero(~keep.any(axis=1))).size:
            raise ValueError(f"the potentials forbid every configuration: no state of node "
                             f"{dead[0]} is allowed by its node potential together with its "
                             f"neighbours' pair potentials (-inf entries), so the model has "
                             f"no configuration of positive probability")
        if np.array_equal(keep, allowed):
            return
        allowed = keep


def _exp_rows(t: np.ndarray) -> np.ndarray:
    """``exp(t - max of its last axis)`` (rows of -inf give zeros), C-contiguous."""
    m = t.max(axis=-1, keepdims=True)
    return np.ascontiguousarray(np.exp(t - np.where(np.isfinite(m), m, 0.0)))
