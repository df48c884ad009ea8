"""Many chains in one compiled call: each at its own feature vector (:func:`simulate_batch`).

``simulate_batch(design, psi_rows, n)`` runs ``B`` chains of :func:`mrfpe.models.simulate.
simulate` at once, chain ``b`` at ``psi_rows[b]``: single-site Gibbs sweeps over colour
classes (Geman & Geman 1984) or Swendsen-Wang cluster sweeps (Swendsen & Wang 1987), the
method chosen per chain as ``simulate`` chooses it. With at least as many chains as
threads, each chain runs whole on one thread (no barrier between sweeps); with fewer, the
chains' colour classes are split into blocks of nodes shared among the threads. Work is
handed out dynamically (numba's chunk size 1), so a thread the machine has descheduled
holds back at most one chain or block.

Identity of the draws: chain ``b`` draws from the seed ``chain_seeds(seed, B)[b]`` (words
of ``numpy.random.SeedSequence(seed)``, the same for every ``B`` larger than ``b``) and is
*identical* to ``simulate(design, psi_rows[b], n, seed=chain_seeds(seed, B)[b], ...)`` with
its own start: the uniform of node ``i`` at sweep ``s`` is output ``s * n_nodes + i`` of
the chain's counter-based SplitMix64 stream (Steele, Lea & Flood 2014), so the draws
depend neither on the number of threads, nor on the other chains of the batch, nor on
which of the two parallel layouts ran.

Multi-spin kernel. Gibbs chains of a binary 4- or 8-neighbour lattice model
(:func:`mrfpe.models.multispin.applies`) run, from :data:`MULTISPIN_MIN_ROWS` of them on,
as replicas of the multi-spin coded heat-bath kernel (Jacobs & Rebbi 1981; 64 replicas a
machine word, each at its own parameters, :mod:`mrfpe.models.multispin`). Its draws have
the distribution of the scalar kernel's -- the same checkerboard heat-bath chain from
the same start -- but other random numbers, so they are *not* identical to the
single-chain calls: ``kernel="scalar"`` keeps the identity above, ``kernel="multispin"``
asks for the multi-spin kernel at any number of rows. Measured at 64² (Ising, coupling
0.3, one call per batch, benchmarks/RESULTS.md): one multi-spin sweep costs about as much
for 1 replica as for 64, so it matches the scalar kernel's time at about 8 chains and is
2x faster at 16, 13x at 64; hence the threshold 16. ``method="auto"`` keeps choosing
Swendsen-Wang where it applies (ferromagnetic Potts), as ``simulate`` does; only the
chains it resolves to Gibbs (and ``method="gibbs"``) use the multi-spin kernel.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import numba
import numpy as np
from numba import njit, prange

from mrfpe.budget import check_memory
from mrfpe.models.design import Design, check_configurations
from mrfpe.models.gibbs_sites import _site, _uniform
from mrfpe.models.lattice_gibbs import lattice_stencil, run_lattice
from mrfpe.models.multispin import lattice_parameters, multispin_gibbs, why_not
from mrfpe.models.simulate import (
    _BLOCK,
    _check_support,
    _exp_rows,
    _init,
    _swendsen_wang,
    check_run,
    graph_size,
    swendsen_wang_form,
)
from mrfpe.threads import limit_threads, thread_budget
from mrfpe.validation import check_positive_int, check_seed

__all__ = ["KERNELS", "MULTISPIN_MIN_ROWS", "chain_seeds", "check_batch_size",
           "check_theta_rows", "simulate_batch", "spare_cores"]

KERNELS = ("auto", "scalar", "multispin")
#: Gibbs chains from which ``kernel="auto"`` runs the multi-spin kernel (module docstring).
MULTISPIN_MIN_ROWS = 16


def chain_seeds(seed: int | None, n_chains: int) -> np.ndarray:
    """The seed (in [0, 2**63 - 1]) of each of ``n_chains`` chains drawn from ``seed``.

    Words of ``numpy.random.SeedSequence(seed)``: chain ``b``'s seed does not depend on
    ``n_chains`` (a longer batch extends a shorter one).
    """
    words = np.random.SeedSequence(check_seed(seed)).generate_state(n_chains, np.uint64)
    return (words >> np.uint64(1)).astype(np.int64)


@njit(cache=True, parallel=True)
def _gibbs_chains(X, order, node, pair, enode, epair, indptr, nbr, ntab, keys, slot, out):
    """One chain per thread: chain ``b`` sweeps ``order`` (its colour classes in turn, as
    the class-parallel sweep does) ``slot.size`` times; after sweep ``s`` it stores its
    state in ``out[b, slot[s]]`` (if ``>= 0``)."""
    n, q = X.shape[1], pair.shape[-1]
    for b in prange(X.shape[0]):
        x, w, key = X[b], np.empty(q), keys[b]
        nd, pr, en, ep = node[b], pair[b], enode[b], epair[b]  # hoisted: one view per chain
        for s in range(slot.size):
            for k in range(order.size):
                i = order[k]
                _site(i, x, nd, pr, en, ep, indptr, nbr, ntab, _uniform(key, s * n + i), w)
            if slot[s] >= 0:
                out[b, slot[s]] = x


@njit(cache=True, parallel=True)
def _gibbs_blocks(X, order, cptr, node, pair, enode, epair, indptr, nbr, ntab, keys, slot, out):
    """Blocks of ``_BLOCK`` nodes of one colour class of every chain shared among the
    threads (few chains: one barrier per colour class for all of them)."""
    B, n, q = X.shape[0], X.shape[1], pair.shape[-1]
    for s in range(slot.size):
        for c in range(cptr.size - 1):
            lo, hi = cptr[c], cptr[c + 1]
            nb = (hi - lo + _BLOCK - 1) // _BLOCK
            for t in prange(B * nb):
                b, blk = t // nb, t % nb
                x, w, key = X[b], np.empty(q), keys[b]
                nd, pr, en, ep = node[b], pair[b], enode[b], epair[b]
                for k in range(lo + blk * _BLOCK, min(hi, lo + (blk + 1) * _BLOCK)):
                    i = order[k]
                    _site(i, x, nd, pr, en, ep, indptr, nbr, ntab, _uniform(key, s * n + i), w)
        if slot[s] >= 0:
            for b in range(B):
                out[b, slot[s]] = X[b]


@njit(cache=True, parallel=True)
def _sw_chains(X, node, edges, etab, p_bond, keys, slot, out):
    """Swendsen-Wang, one chain per thread (a sweep's union-find is serial)."""
    for b in prange(X.shape[0]):
        _swendsen_wang(X[b], node[b], edges, etab, p_bond[b], keys[b], slot, out[b])


#: Seconds a reading of :func:`spare_cores` is reused: reading ``/proc`` costs about a
#: millisecond, as much as a small batch's sweeps (the exchange algorithm calls once a step).
SPARE_CORES_TTL = 0.25
_spare_reading = [-np.inf, 1]  # (monotonic time, cores)


def spare_cores() -> int:
    """Cores of this process's affinity not taken by other processes' runnable threads now
    (a reading at most :data:`SPARE_CORES_TTL` seconds old).

    The block layout meets a barrier per colour class, and every parallel call one at its
    end: a thread that shares its core with another process arrives late, and two threads
    on one free core ran 2-3x slower than one. Runnable threads of the whole system
    (``/proc/loadavg``) less this process's own (``/proc/self/task``); all cores where
    ``/proc`` is missing.
    """
    now = time.monotonic()
    if now - _spare_reading[0] > SPARE_CORES_TTL:
        _spare_reading[:] = [now, _read_spare_cores()]
    return int(_spare_reading[1])


def _read_spare_cores() -> int:
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    try:
        running = int(Path("/proc/loadavg").read_text().split()[3].split("/")[0])
        ours = sum(Path(t, "stat").read_text().rsplit(")", 1)[1].split()[0] == "R"
                   for t in Path("/proc/self/task").iterdir())
    except (OSError, ValueError, IndexError):
        return max(1, cores or 1)
    return max(1, (cores or 1) - max(0, running - ours))


def check_theta_rows(theta: Any, names: tuple[str, ...] | list[str]) -> np.ndarray:
    """``theta`` as a finite ``(B, d)`` float array, else a one-line ValueError naming the
    argument (and the first row holding NaN or inf)."""
    try:
        th = np.asarray(theta, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"theta must be a (B, {len(names)}) array of numbers; got "
                         f"{type(theta).__name__}") from None
    if th.ndim != 2 or th.shape[0] < 1 or th.shape[1] != len(names):
        raise ValueError(f"theta rows must have {len(names)} entries {tuple(names)}; got "
                         f"shape {th.shape}")
    if (bad := np.flatnonzero(~np.isfinite(th).all(axis=1))).size:
        raise ValueError(f"theta row {bad[0]} must be finite; got {th[bad[0]].tolist()}")
    return th


def _check_psi_rows(design: Design, psi_rows: Any) -> np.ndarray:
    """``(B, P)`` rows: finite, or ``-inf`` (forbidden) where no feature is negative."""
    psi = np.asarray(psi_rows, dtype=np.float64)
    if psi.ndim != 2 or psi.shape[0] < 1 or psi.shape[1] != design.n_features:
        raise ValueError(f"psi_rows must be (B, {design.n_features}) feature vectors; got "
                         f"shape {psi.shape}")
    neg = np.zeros(psi.shape, dtype=bool)  # features whose -inf would meet a negative one
    for f in (design.node, design.pair):
        neg |= (f < 0).reshape(-1, f.shape[-1]).any(axis=0)
    bad = np.isnan(psi) | (psi == np.inf) | (np.isneginf(psi) & neg)
    if (rows := np.flatnonzero(bad.any(axis=1))).size:
        raise ValueError(f"psi_rows row {rows[0]} must hold finite numbers, or -inf "
                         f"(forbidden) where no feature is negative")
    return psi


def _check_batch_memory(n_nodes: int, n_edges: int, shape: tuple[int, ...], B: int, n: int,
                        n_sweeps: int, thin: int, table_entries: int = 0) -> None:
    """Refuse, before any work, a batch whose draws, tables and graph exceed the budget."""
    nbytes = (64.0 * n_nodes + 256.0 * n_edges + 8.0 * (n_sweeps + (thin + 1) * n)
              + B * (8.0 * n * n_nodes + 24.0 * n_nodes + 24.0 * table_entries))
    check_memory(nbytes, f"simulate(B={B} chains, n={n}, shape={tuple(shape)}): {B} x {n} "
                         f"draw(s) of {n_nodes} nodes", "simulate fewer chains (theta rows) or "
                         "draws (n) at a time, or smaller configurations (shape)")


def check_batch_size(spec: Any, shape: Any, B: int, n: Any, n_sweeps: Any, thin: Any) -> None:
    """:func:`simulate_batch`'s memory check for ``B`` chains, from a model's graph rule
    before its graph is built (as :func:`~mrfpe.models.simulate.check_simulation_size`)."""
    n, n_sweeps = check_positive_int("n", n), check_positive_int("n_sweeps", n_sweeps, 0)
    thin = check_positive_int("thin", thin)
    if (size := graph_size(spec, shape)) is not None:
        n_nodes, n_edges, node_shape = size
        _check_batch_memory(n_nodes, n_edges, node_shape, B, n, n_sweeps, thin)


def _starts(init: Any, design: Design, B: int) -> list[Any]:
    """Each chain's ``init``: ``"random"``, or its row of one or ``B`` configurations."""
    g = design.graph
    if isinstance(init, str):
        return [init] * B
    arr = np.asarray(init)
    if arr.shape in ((g.n_nodes,), g.shape):
        return [arr] * B
    if arr.shape in ((B, g.n_nodes), (B, *(g.shape or (-1,)))):
        return list(check_configurations(arr, design.q, arr.shape[1:], "init"))
    lattice = f", {g.shape} or (B, {', '.join(map(str, g.shape))})" if g.shape else ""
    raise ValueError(f"init must be 'random', one configuration ({g.n_nodes},){lattice} or "
                     f"one per chain ({B}, {g.n_nodes}); got shape {arr.shape}")


def _plan(design: Design, psi: np.ndarray, method: str) -> tuple:
    """Tables of every chain, and each chain's Swendsen-Wang form (None: Gibbs)."""
    # row by row, as simulate computes them (a batched einsum may sum in another order)
    node, pair = (np.concatenate(t) for t in zip(*(design.tables(r[None]) for r in psi)))
    etab = np.arange(design.graph.n_edges) if design.pair_per_edge else design.graph.edge_type
    forms: list[Any] = []
    for b in range(psi.shape[0]):
        try:
            _check_support(design, node[b], pair[b], etab)
        except ValueError as err:
            raise ValueError(f"psi_rows row {b}: {err}") from None
        form = None if method == "gibbs" else swendsen_wang_form(pair[b])
        if method == "swendsen_wang" and isinstance(form, str):
            raise ValueError(f"method='swendsen_wang' needs ferromagnetic Potts pair tables "
                             f"(J [a == b] + per-state terms, J >= 0): psi_rows row {b}: {form}")
        forms.append(form if isinstance(form, tuple) else None)
    return node, pair, etab, forms


def _schedule(n: int, n_sweeps: int, thin: int) -> np.ndarray:
    """``slot[s]``: the draw taken after sweep ``s + 1`` (-1: none); draw ``k`` is the state
    after sweep ``n_sweeps + thin * k`` (draw 0 is the start if ``n_sweeps == 0``)."""
    when = n_sweeps + thin * np.arange(n)
    slot = np.full(when[-1], -1, dtype=np.int64)
    slot[when[when > 0] - 1] = np.flatnonzero(when > 0)
    return slot


def simulate_batch(design: Design, psi_rows: np.ndarray, n: int = 1, *,
                   seed: int | None = None, method: str = "auto", n_sweeps: int = 200,
                   thin: int = 10, init: Any = "random", kernel: str = "auto") -> np.ndarray:
    """Draw ``n`` configurations from each of ``B`` chains, chain ``b`` at ``psi_rows[b]``.

    Parameters
    ----------
    design : Design
    psi_rows : (B, P)
        One feature vector per chain (``design.psi(theta)`` of a ``(B, d)`` theta);
        ``-inf`` entries forbid states.
    n : int >= 1
        Draws per chain.
    seed : int or None
        Chain ``b`` uses the seed ``chain_seeds(seed, B)[b]``: its draws equal
        :func:`~mrfpe.models.simulate.simulate` at ``psi_rows[b]`` with that seed (module
        docstring), whatever the number of threads and the rest of the batch -- unless
        the multi-spin kernel runs it (``kernel``).
    method : "auto", "gibbs" or "swendsen_wang"
        As in ``simulate``, per chain: Gibbs over colour classes (Geman & Geman 1984),
        Swendsen-Wang (Swendsen & Wang 1987) where the chain's tables allow it.
    n_sweeps, thin : int
        Burn-in sweeps before the first draw; sweeps between draws.
    init : "random", one configuration, or ``B`` configurations
        ``(n_nodes,)`` or the lattice's shape, shared; ``(B, n_nodes)`` or ``(B, H, W)``,
        one per chain (say the data, or each chain's own labels).
    kernel : "auto", "scalar" or "multispin"
        Which kernel runs the Gibbs chains: ``"auto"`` the multi-spin coded one (Jacobs &
        Rebbi 1981) for at least :data:`MULTISPIN_MIN_ROWS` chains of a binary lattice
        model with finite parameters, else the scalar one; ``"scalar"`` always the scalar
        one (draws identical to single-chain calls); ``"multispin"`` always the multi-spin
        one (a ValueError if it cannot run the design). Equal in distribution, not in the
        draws (module docstring).

    Returns
    -------
    (B, n, n_nodes) int64
    """
    n, n_sweeps, thin = check_run(design, n, n_sweeps, thin, method)
    if not isinstance(kernel, str) or kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {', '.join(KERNELS)}; got {kernel!r}")
    psi = _check_psi_rows(design, psi_rows)
    B, g, q = psi.shape[0], design.graph, design.q
    tables = design.node.shape[0] * q + design.pair.shape[0] * q * q  # node, pair, exp
    _check_batch_memory(g.n_nodes, g.n_edges, g.shape or (g.n_nodes,), B, n, n_sweeps, thin,
                        tables)
    starts = _starts(init, design, B)
    node, pair, etab, forms = _plan(design, psi, method)
    X = np.empty((B, g.n_nodes), dtype=np.int64)
    keys = np.empty(B, dtype=np.uint64)
    for b, s in enumerate(chain_seeds(seed, B)):  # as simulate draws its start, then its key
        rng = np.random.default_rng(int(s))
        X[b] = _init(starts[b], design, node[b], rng)
        keys[b] = rng.integers(2**64, dtype=np.uint64)
    slot = _schedule(n, n_sweeps, thin)
    out = np.empty((B, n, g.n_nodes), dtype=np.int64)
    out[:, 0] = X  # kept if n_sweeps == 0
    gibbs = np.array([f is None for f in forms])
    if _use_multispin(design, psi[gibbs], kernel):
        _run_multispin(design, np.flatnonzero(gibbs), psi, X, keys, n_sweeps, thin, out)
    elif gibbs.any():
        _run_gibbs(design, np.flatnonzero(gibbs), X, node, pair, etab, keys, slot, out)
    if not gibbs.all():
        _run_sw(design, np.flatnonzero(~gibbs), X, node, forms, etab, keys, slot, out)
    _check_draws(design, out, pair, etab, n_sweeps, thin)
    return out


def _run_gibbs(design: Design, rows: np.ndarray, X: np.ndarray, node: np.ndarray,
               pair: np.ndarray, etab: np.ndarray, keys: np.ndarray, slot: np.ndarray,
               out: np.ndarray) -> None:
    """Gibbs chains ``rows``: one per thread if there are enough, else blocks of nodes."""
    g, q, B = design.graph, design.q, rows.size
    classes = g.colour_classes()
    order, cptr = np.concatenate(classes).astype(np.uint32), np.cumsum([0, *map(len, classes)])
    indptr, nbr, eidx = (a.astype(np.uint32) for a in g.neighbours())  # unsigned: no wraparound
    nd, pr = np.ascontiguousarray(node[rows]), np.ascontiguousarray(pair[rows])
    tables = (nd, pr, _exp_rows(nd), _exp_rows(pr).reshape(B, -1, q))
    Xs, outs = X[rows].astype(np.uint32), np.empty((B, *out.shape[1:]), dtype=np.int64)
    outs[:] = out[rows]
    common = (indptr, nbr, etab[eidx].astype(np.uint32), keys[rows], slot, outs)
    threads, stencil = numba.get_num_threads(), lattice_stencil(design)
    with numba.parallel_chunksize(1):  # dynamic: a descheduled thread holds one piece
        if B >= threads:  # a thread sharing its core with another process holds all back
            with limit_threads(spare_cores()):
                if stencil is None:
                    _gibbs_chains(Xs, order, *tables, *common)
                else:  # the same draws by stencil arithmetic (mrfpe.models.lattice_gibbs)
                    run_lattice(stencil, Xs, *tables, *common, chains=True)
        else:  # threads from ~1.6e6 site-states a sweep (as simulate), on idle cores only
            with limit_threads(spare_cores()), thread_budget(B * g.n_nodes * q // 4):
                if stencil is None:
                    _gibbs_blocks(Xs, order, cptr, *tables, *common)
                else:
                    run_lattice(stencil, Xs, *tables, *common, chains=False)
    out[rows] = outs


def _use_multispin(design: Design, psi: np.ndarray, kernel: str) -> bool:
    """Whether the Gibbs chains at ``psi`` run on the multi-spin kernel (``kernel``)."""
    if kernel == "scalar" or (kernel == "auto" and psi.shape[0] < MULTISPIN_MIN_ROWS):
        return False  # before the lattice check: it rebuilds the graph
    reason = why_not(design) or (None if np.isfinite(psi).all() else
                                 "its parameters forbid states (-inf)")
    if kernel == "multispin" and reason is not None:
        raise ValueError(f"kernel='multispin' cannot run this design: {reason}")
    return reason is None and psi.shape[0] > 0 and (kernel == "multispin"
                                                    or psi.shape[0] >= MULTISPIN_MIN_ROWS)


def _run_multispin(design: Design, rows: np.ndarray, psi: np.ndarray, X: np.ndarray,
                   keys: np.ndarray, n_sweeps: int, thin: int, out: np.ndarray) -> None:
    """Gibbs chains ``rows`` as replicas of the multi-spin kernel, from their starts ``X``
    (drawn as the scalar route draws them); its key derives from the first chain's."""
    H, W = design.graph.shape
    draws = multispin_gibbs(**lattice_parameters(design, psi[rows]).arguments(),
                            n_sweeps=n_sweeps, thin=thin, n=out.shape[1],
                            seed=int(keys[rows[0]] >> np.uint64(1)),
                            init=X[rows].reshape(rows.size, H, W))
    out[rows] = draws.reshape(rows.size, out.shape[1], H * W)


def _run_sw(design: Design, rows: np.ndarray, X: np.ndarray, node: np.ndarray, forms: list,
            etab: np.ndarray, keys: np.ndarray, slot: np.ndarray, out: np.ndarray) -> None:
    """Swendsen-Wang chains ``rows``, grouped by the shape of their node tables (per-state
    edge terms moved onto the nodes make them per node), one chain per thread."""
    g, q, e = design.graph, design.q, design.graph.edges
    groups: dict[int, list[tuple[int, np.ndarray, np.ndarray]]] = {}
    for b in rows:
        J, f = forms[b]
        nd = node[b]
        if np.any(f != 0):  # as simulate: per-state edge terms become node potentials
            nd = nd + np.stack([np.bincount(e[:, 0], f[etab, a], g.n_nodes)
                                + np.bincount(e[:, 1], f[etab, a], g.n_nodes)
                                for a in range(q)], axis=1)
        groups.setdefault(nd.shape[0], []).append((int(b), nd, -np.expm1(-J)))
    for members in groups.values():
        idx = np.array([b for b, _, _ in members])
        Xs, outs = X[idx].copy(), out[idx].copy()
        # on idle cores only: at 16² four chains took 12 ms on two threads, one of them
        # shared with another process, and 2 ms on one
        with numba.parallel_chunksize(1), limit_threads(min(numba.get_num_threads(), idx.size,
                                                            spare_cores())):
            _sw_chains(Xs, np.stack([nd for _, nd, _ in members]), e, etab,
                       np.stack([p for _, _, p in members]), keys[idx], slot, outs)
        out[idx] = outs


def _check_draws(design: Design, out: np.ndarray, pair: np.ndarray, etab: np.ndarray,
                 n_sweeps: int, thin: int) -> None:
    """Refuse a draw holding a forbidden pair (as simulate), naming its chain."""
    e = design.graph.edges
    for b in np.flatnonzero(~np.isfinite(pair).reshape(pair.shape[0], -1).all(axis=1)):
        bad = [k for k, xk in enumerate(out[b])
               if np.isneginf(pair[b][etab, xk[e[:, 0]], xk[e[:, 1]]]).any()]
        if bad:
            raise ValueError(f"chain {b}, draw {bad[0]} holds a forbidden pair of states (-inf) "
                             f"after {n_sweeps + thin * bad[0]} sweeps: either the chain has not "
                             f"reached the support (raise n_sweeps, or give an init in it) or "
                             f"the pair constraints admit no configuration at all")
