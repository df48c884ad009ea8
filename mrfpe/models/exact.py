"""Exact log partition functions of discrete pairwise MRFs.

``LogPartition(design, method)(psi)`` gives ``log Z(psi)`` (N,) for a batch of
feature vectors ``psi`` (N, P), with the log-potential tables of
:meth:`mrfpe.models.design.Design.tables`:

    ``log Z = logsumexp_x [sum_i node[i, x_i] + sum_e pair[e, x_i, x_j]]``.

Methods
-------
``"enumerate"``
    All ``q^n`` configurations, grouped by their sufficient statistics ``S(x)``
    (distinct rows and their multiplicities), so that ``log Z = logsumexp_s
    (s . psi + log mult_s)`` is one matrix product. Limit ``q^n <=
    MAX_ENUMERATION``; cost ``O(q^n)`` once (a Python pass per configuration),
    then ``O(N U P)`` per call for ``U`` distinct statistics.
``"eliminate"``
    Variable (bucket) elimination (Koller & Friedman 2009, ch. 9), batched over
    the rows of ``psi`` and in log space: factors are arrays ``(q, ..., q, N)``
    (one axis per node, the batch axis last so that numpy's inner loops are
    long), combined by broadcasting sums and summed out by max-shifted
    logsumexp. The order, the scopes and every factor's broadcast plan are fixed
    at construction; a call only runs the numeric passes. On a
    lattice ``(H, W)`` it is the row-major sweep across the shorter side (the
    cheaper of the two sweeps), so the factor carried from site to site is the
    *frontier* of ``min(H, W)`` sites (one more with the diagonals of the
    8-neighbourhood, about twice as many on a torus): the transfer-matrix method
    (Baxter 1982, *Exactly Solved Models in Statistical Mechanics*; Reeves &
    Pettitt 2004, "Efficient recursions for general factorisable models",
    Biometrika 91, 751-757; Friel & Rue 2007, Biometrika 94, 661-672). On other
    graphs it is the greedy min-fill order (ties: min degree; K&F 2009, Sec.
    9.4.3). With induced width ``w`` the largest factor has ``q^(w+1)`` entries
    per psi row and a call costs ``O(N sum_steps q^|scope|) <= O(N n q^(w+1))``.
    Refused (ValueError) above :data:`MAX_FACTOR_ENTRIES` entries, or
    (:class:`~mrfpe.budget.MemoryBudgetError`) when one psi row's working
    memory exceeds :func:`~mrfpe.budget.memory_budget`; batches are
    evaluated in chunks of at most ``WORKING_CHUNK_BYTES``.
``"auto"``
    Enumeration when ``q^n <= MAX_ENUMERATION`` and ``q^n`` is at most the
    elimination's total factor entries, else elimination within its limit, else a
    ValueError giving both sizes.

Feasible, for instance: a 10 x 10 Ising model (``w = 10``, ``2^11`` entries;
about 0.6 ms per psi row), a 4 x 30 Potts model with ``q = 3`` (``3^5``), an
8-neighbour 20 x 20 Ising model (``2^22``, the limit). A 64 x 64 lattice is
refused (``2^65``).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from itertools import combinations, pairwise

import numpy as np
from scipy.special import logsumexp

from mrfpe.budget import check_memory, chunk_rows
from mrfpe.models.design import Design, allowed_dot, unique_rows
from mrfpe.models.graph import Graph

__all__ = ["MAX_ENUMERATION", "MAX_FACTOR_ENTRIES", "LogPartition"]

#: Largest number of configurations enumerated.
MAX_ENUMERATION = 1 << 20
#: Largest intermediate factor of variable elimination, in entries per psi row.
MAX_FACTOR_ENTRIES = 1 << 22
#: Symbolic work (scope sizes summed) after which planning stops an order already over the limit.
_PLAN_WORK = 500_000
_HINT = ("use a smaller (narrower) lattice or graph, enumeration for tiny graphs, or the "
         "pseudolikelihood estimators 'pl' / 'block'")


def _power(q: int, k: int) -> str:
    """``'2^65 (3.7e+19)'``: a power that may be too large for a float."""
    e = k * math.log10(q)
    return f"{q}^{k} ({10 ** (e - math.floor(e)):.2g}e+{math.floor(e):02d})"


@dataclass
class _Schedule:
    """A symbolic elimination: per step its input factor ids, its scope and ``vi``.

    ``axes[f]``: the nodes along factor ``f``'s axes (terms, then intermediates in
    order of creation). A scope keeps its largest input's axis order, with the nodes
    it lacks inserted after the eliminated node ``scope[vi]``: on a lattice a new site
    takes the frontier slot of the site it replaces, so other axes stay in long blocks.
    """

    name: str
    order: np.ndarray
    axes: list[tuple[int, ...]]
    steps: list[tuple[list[int], tuple[int, ...], int]]
    width: int  # largest scope - 1: the induced width (a lower bound if not complete)
    complete: bool
    total: int  # sum over steps of q^|scope|
    peak: int  # factor entries alive at once, per psi row

    def entries(self, q: int) -> int:
        return q ** (self.width + 1)


def _schedule(q: int, terms: list[tuple[int, ...]], order: np.ndarray, name: str,
              kmax: int) -> _Schedule:
    """Bucket elimination of ``terms`` in ``order``, stopped early if hopeless."""
    pos = [0] * len(order)
    for s, v in enumerate(order.tolist()):
        pos[v] = s
    key = pos.__getitem__
    axes = list(terms)
    buckets: list[list[int]] = [[] for _ in order]
    for f, ax in enumerate(axes):
        buckets[min(map(key, ax))].append(f)
    steps: list[tuple[list[int], tuple[int, ...], int]] = []
    widest = total = live = peak = work = 0
    for s, v in enumerate(order.tolist()):
        ins = buckets[s]
        base = max((axes[f] for f in ins), key=len)
        vi = base.index(v) + 1
        extra = sorted(set().union(*(axes[f] for f in ins)) - set(base), key=key)
        scope = (*base[:vi], *extra, *base[vi:])
        vi -= 1
        k = len(scope)
        widest, work = max(widest, k), work + k
        if widest > kmax and work > _PLAN_WORK:  # hopeless: stop (the width is a lower bound)
            return _Schedule(name, order, axes, steps, widest - 1, False, total, peak)
        size = q ** k
        peak = max(peak, live + 3 * size)  # inputs alive, the sum and its exp
        live -= sum(q ** len(axes[f]) for f in ins if f >= len(terms))
        total += size
        if k > 1:
            rest = scope[:vi] + scope[vi + 1:]
            buckets[min(map(key, rest))].append(len(axes))
            axes.append(rest)
            live += size // q
        steps.append((ins, scope, vi))
    return _Schedule(name, order, axes, steps, widest - 1, True, total, peak)


def _min_fill(graph: Graph, kmax: int) -> np.ndarray | int:
    """Greedy min-fill order (ties: min degree), or the degree at which it gave up."""
    adj: list[set[int]] = [set() for _ in range(graph.n_nodes)]  # the induced graph so far
    for i, j in graph.edges.tolist():
        adj[i].add(j)
        adj[j].add(i)

    def score(u: int) -> tuple[float, int]:
        nb = adj[u]
        if len(nb) + 1 > kmax:  # its factor would be over the limit: eliminate last, if ever
            return math.inf, len(nb)
        return sum(b not in adj[a] for a, b in combinations(nb, 2)), len(nb)

    cur = {u: score(u) for u in range(graph.n_nodes)}
    heap = [(*sc, u) for u, sc in cur.items()]
    heapq.heapify(heap)
    order: list[int] = []
    while heap:
        f, d, u = heapq.heappop(heap)
        if cur.get(u) != (f, d):
            continue  # a stale entry
        if f == math.inf:
            return d
        del cur[u]
        order.append(u)
        nb = adj[u]
        for a in nb:
            adj[a].discard(u)
        touched = set(nb)  # whose fill may change: u's neighbours, common ones of a new edge
        for a, b in combinations(nb, 2):
            if b not in adj[a]:
                adj[a].add(b)
                adj[b].add(a)
                touched |= adj[a] & adj[b]
        for t in touched:
            cur[t] = score(t)
            heapq.heappush(heap, (*cur[t], t))
    return np.array(order, dtype=np.int64)


def _best_schedule(graph: Graph, q: int, terms: list[tuple[int, ...]], kmax: int) -> _Schedule:
    """The lattice sweeps (the cheaper one) or the min-fill order on other graphs."""
    n = graph.n_nodes
    if graph.shape is not None and math.prod(graph.shape) == n:
        H, W = graph.shape
        grid = np.arange(n, dtype=np.int64).reshape(H, W)
        cands = [_schedule(q, terms, grid.ravel(), f"row-major sweep, rows of {W}", kmax),
                 _schedule(q, terms, grid.T.ravel(), f"column-major sweep, columns of {H}",
                           kmax)]
        return min(cands, key=lambda s: (not s.complete, s.width, s.total))
    order = _min_fill(graph, kmax)
    if isinstance(order, int):
        return _Schedule("greedy min-fill order", order=np.zeros(0, np.int64), axes=[],
                         steps=[], width=order, complete=False, total=0, peak=0)
    return _schedule(q, terms, order, "greedy min-fill order", kmax)


class LogPartition:
    """``log Z(psi)`` of a design by enumeration or variable elimination.

    Parameters
    ----------
    design : Design
    method : {"auto", "enumerate", "eliminate"}

    Attributes
    ----------
    method : str
        The method used, ``"enumerate"`` or ``"eliminate"``.
    order : ndarray or None
        The elimination order (node ids); ``width`` its induced width and
        ``max_factor_entries`` the largest factor's entries per psi row.
    """

    order: np.ndarray | None
    width: int | None
    max_factor_entries: int | None

    def __init__(self, design: Design, method: str = "auto") -> None:
        if method not in ("auto", "enumerate", "eliminate"):
            raise ValueError(f"method must be 'auto', 'enumerate' or 'eliminate'; got {method!r}")
        self.design = design
        g, q = design.graph, design.q
        n, size = g.n_nodes, q ** g.n_nodes
        self.order, self.width, self.max_factor_entries = None, None, None
        sched = None
        if method != "enumerate":
            kmax = math.floor(math.log(MAX_FACTOR_ENTRIES) / math.log(q) + 1e-9)
            terms = [(i,) for i in range(n)] + [tuple(e) for e in g.edges.tolist()]
            sched = _best_schedule(g, q, terms, kmax)
            ok = sched.complete and sched.entries(q) <= MAX_FACTOR_ENTRIES
            if method == "auto" and size <= MAX_ENUMERATION and (not ok or size <= sched.total):
                method = "enumerate"
            elif ok:
                method = "eliminate"
            else:
                factor = (f"{_power(q, sched.width + 1)} entries per psi row (induced width "
                          f"{sched.width}{'' if sched.complete else ' or more'}, {sched.name})")
                limit = f"MAX_FACTOR_ENTRIES = {MAX_FACTOR_ENTRIES} = {q}^{kmax}"
                if method == "auto":
                    raise ValueError(
                        f"exact log Z is intractable on {n} nodes with {q} states: enumeration "
                        f"needs {_power(q, n)} configurations (limit MAX_ENUMERATION = "
                        f"{MAX_ENUMERATION}) and variable elimination a factor of {factor}, "
                        f"over {limit}; {_HINT}")
                raise ValueError(f"exact log Z by variable elimination on {n} nodes with {q} "
                                 f"states needs a factor of {factor}, over {limit}; {_HINT}")
        self.method = method
        if method == "enumerate" or sched is None:
            self._init_enumerate(size)
        else:
            self._init_eliminate(sched)

    def _init_enumerate(self, size: int) -> None:
        d, n, q = self.design, self.design.graph.n_nodes, self.design.q
        if size > MAX_ENUMERATION:
            raise ValueError(f"the exact likelihood needs log Z over {q}^{n} configurations; "
                             f"enumeration is limited to {MAX_ENUMERATION} (n_nodes={n}, "
                             f"n_states={q}); use method='eliminate' (or 'auto')")
        stats = []
        for a in range(0, size, 1 << 14):
            codes = np.arange(a, min(size, a + (1 << 14)))
            stats.append(d.statistics(np.stack(np.unravel_index(codes, (q,) * n), axis=1)))
        s = np.concatenate(stats)
        first, counts, _ = unique_rows(s)
        self._stats, self._log_mult = s[first], np.log(counts)

    def _init_eliminate(self, sched: _Schedule) -> None:
        """Fix everything but the numbers: term sources and each factor's broadcast plan."""
        d, g, n = self.design, self.design.graph, self.design.graph.n_nodes
        self.order, self.width = sched.order, sched.width
        self.max_factor_entries = sched.entries(d.q)
        node_rows = np.arange(n) if d.node.shape[0] == n else np.zeros(n, np.int64)
        pair_rows = np.arange(g.n_edges) if d.pair_per_edge else g.edge_type
        self._rows = [int(r) for r in np.concatenate([node_rows, pair_rows])]
        self._n_terms = len(self._rows)
        # per step: inputs (id, None or (full shape, transpose), broadcast shape), the axis
        # summed out and the id of the new factor (-1: a constant, added to log Z)
        self._plan: list[tuple[list[tuple[int, tuple | None, tuple[int, ...]]], int, int]] = []
        new = self._n_terms
        for ins, scope, vi in sched.steps:
            ins = sorted(ins, key=lambda f: len(sched.axes[f]))  # small factors first
            have = [[v in sched.axes[f] for v in scope] for f in ins]
            # merge consecutive scope axes that every input has or lacks alike (never the
            # eliminated node's), so that numpy loops over few long axes
            cuts = [0, *(k for k in range(1, len(scope)) if k in (vi, vi + 1)
                         or any(h[k] != h[k - 1] for h in have)), len(scope)]
            parts = []
            for f, h in zip(ins, have):
                src = sched.axes[f]
                perm = sorted(range(len(src)), key=lambda a: scope.index(src[a]))
                tr = None if perm == sorted(perm) else ((d.q,) * len(src), (*perm, len(perm)))
                shape = tuple(d.q ** (b - a) if h[a] else 1 for a, b in pairwise(cuts))
                parts.append((f, tr, shape))
            self._plan.append((parts, cuts.index(vi), new if len(scope) > 1 else -1))
            new += len(scope) > 1
        table = d.node.shape[0] * d.q + d.pair.shape[0] * d.q * d.q
        self._row_bytes = 8.0 * (sched.peak + table + 1)
        check_memory(self._row_bytes, "exact log Z by variable elimination (one psi row)",
                     f"induced width {sched.width}, {sched.name}; {_HINT}")

    def __call__(self, psi: np.ndarray) -> np.ndarray:
        """``log Z`` (N,) at each row of ``psi`` (N, P)."""
        psi = np.atleast_2d(np.asarray(psi, dtype=np.float64))
        out = np.empty(N := psi.shape[0])
        if self.method == "enumerate":
            for sl in chunk_rows(N, 16.0 * self._stats.shape[0], minimum=1):
                s = allowed_dot(psi[sl], self._stats)  # -inf: a forbidden configuration
                with np.errstate(divide="ignore"):  # log 0 = -inf: every one forbidden
                    out[sl] = logsumexp(s + self._log_mult[None, :], axis=1)
            return out
        slices = chunk_rows(N, self._row_bytes, minimum=1)
        check_memory(self._row_bytes * (slices[0].stop - slices[0].start) + 8.0 * N,
                     "exact log Z by variable elimination", _HINT)
        for sl in slices:
            out[sl] = self._eliminate(psi[sl])
        return out

    def _eliminate(self, psi: np.ndarray) -> np.ndarray:
        """One numeric pass of the planned elimination over a chunk of psi rows.

        Factors are ``(q, ..., q, N)`` arrays: the batch axis is *last*, so that
        numpy's inner loops run over it (contiguous) rather than over size-``q``
        state axes, and a step is a few broadcast passes with long inner loops.
        """
        node, pair = self.design.tables(psi)  # (N, n|1, q), (N, T|E, q, q)
        node = np.ascontiguousarray(np.moveaxis(node, 0, -1))  # (n|1, q, N)
        pair = np.ascontiguousarray(np.moveaxis(pair, 0, -1))  # (T|E, q, q, N)
        n, nt, rows, N = self.design.graph.n_nodes, self._n_terms, self._rows, psi.shape[0]
        vals: dict[int, np.ndarray] = {}
        total = np.zeros(N)
        for parts, ax, new in self._plan:
            acc = None
            for f, tr, shape in parts:
                a = vals.pop(f) if f >= nt else (node[rows[f]] if f < n else pair[rows[f]])
                if tr is not None:  # intermediates are stored with merged axes
                    a = a.reshape((*tr[0], N)).transpose(tr[1])
                a = a.reshape((*shape, N))
                acc = a if acc is None else acc + a
            assert acc is not None
            m = acc.max(axis=ax, keepdims=True)  # ax: the eliminated node's axis
            m[~np.isfinite(m)] = 0.0
            x = np.subtract(acc, m, out=acc if len(parts) > 1 else None)  # acc is ours if a sum
            lse = np.exp(x, out=x).sum(axis=ax)
            with np.errstate(divide="ignore"):
                lse = np.log(lse, out=lse) + m.squeeze(ax)
            if new < 0:
                total += lse
            else:
                vals[new] = lse
        return total
