"""Multi-spin coded heat-bath sweeps of binary MRFs on 2-D lattices, 64 replicas a word.

The model, per replica ``r``, on an ``(H, W)`` lattice with 4- or 8-neighbourhood
(free or periodic boundary, as :func:`mrfpe.models.graph.lattice` builds it) is

    ``log p_r(x) = sum_i f_ri x_i + sum_{e = (i, j)} (J_rt [x_i == x_j] + d_rt (x_i + x_j))``

with ``x_i`` in ``{0, 1}``, ``t`` the edge's type (one for all edges, or one per
direction), ``J`` the ``coupling``, ``d`` the ``edge_field`` and ``f`` the ``field``
(per replica, or per replica and node). Every symmetric 2 x 2 pair table is of this form
(:func:`lattice_parameters` converts a compiled :class:`~mrfpe.models.design.Design`).

Multi-spin coding (Jacobs & Rebbi 1981, J. Comput. Phys. 41; Zorn, Herrmann & Rebbi
1981) packs 64 replicas in one ``uint64`` word per site and counts all 64 replicas'
neighbours in state 1 at once with bit-sliced adders. The heat-bath (Gibbs; Geman &
Geman 1984) draw of each replica, ``[U_r < p_r]`` with ``p_r`` the conditional
probability of state 1 for its count, is exact: ``U_r``'s binary digits are independent
random bits (bit ``r`` of one random word per digit, so replicas never share them) and
the comparison runs over ``p_r``'s digits, most significant first, until every replica
differs from its ``p_r`` at some digit (about 7 words for 64 replicas). The
probabilities are taken to 64 binary digits (``floor(2^64 p) / 2^64``, an error below
``2^-64``; the scalar kernel's uniforms have 53). Replicas may run at one parameter
vector or each at its own (per-replica digit tables). With a per-node field the
tables would be per site, so each replica's probability is computed at the site and
compared with a 64-bit uniform word of its own: exact as well, but without the
speed of the shared tables. The sweeps are checkerboard (colour-class) sweeps in the
lattice colourings' order; random words come from a counter-based SplitMix64, so the
draws do not depend on the number of threads (:mod:`mrfpe.models.multispin_kernels`).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from mrfpe.budget import check_memory
from mrfpe.models.design import Design
from mrfpe.models.graph import NEIGHBOURHOODS, LatticeSpec, _check_shape
from mrfpe.models.multispin_kernels import sweeps
from mrfpe.threads import thread_budget
from mrfpe.validation import check_bool, check_positive_int, check_seed

__all__ = ["BinaryLattice", "applies", "lattice_parameters", "multispin_gibbs", "pack",
           "unpack", "why_not"]

_ALL = np.uint64(0xFFFFFFFFFFFFFFFF)


def pack(spins: Any) -> np.ndarray:
    """Pack ``(R, ...)`` spins in ``{0, 1}`` into ``(ceil(R / 64), ...)`` uint64 words.

    Bit ``r % 64`` of word ``r // 64`` is replica ``r``'s spin; the bits of missing
    replicas (``R`` not a multiple of 64) are 0.
    """
    x = np.asarray(spins)
    R, nw = x.shape[0], -(-x.shape[0] // 64)
    bits = np.zeros((nw * 64, *x.shape[1:]), dtype=np.uint8)
    bits[:R] = x != 0
    bits = np.moveaxis(bits.reshape(nw, 64, *x.shape[1:]), 1, -1)  # (nw, ..., 64)
    by = np.packbits(bits, axis=-1, bitorder="little")  # (nw, ..., 8): byte b holds r // 8 = b
    if sys.byteorder != "little":  # pragma: no cover - the words' bytes are little-endian
        by = by[..., ::-1]
    return np.ascontiguousarray(by).view(np.uint64)[..., 0]


def unpack(words: Any, n_replicas: int) -> np.ndarray:
    """Inverse of :func:`pack`: ``(n_words, ...)`` uint64 to ``(n_replicas, ...)`` int8."""
    w = np.ascontiguousarray(words, dtype=np.uint64)
    by = w[..., None].view(np.uint8)
    if sys.byteorder != "little":  # pragma: no cover
        by = by[..., ::-1]
    bits = np.unpackbits(by, axis=-1, bitorder="little")  # (nw, ..., 64)
    bits = np.moveaxis(bits, -1, 1).reshape(w.shape[0] * 64, *w.shape[1:])
    return bits[:n_replicas].view(np.int8)


def _finite(name: str, value: Any, shapes: tuple[tuple[int, ...], ...], what: str) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a float array of shape {what}; got "
                         f"{type(value).__name__}") from None
    if a.shape not in shapes:
        raise ValueError(f"{name} must have shape {what}; got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must hold finite numbers; got {int(np.sum(~np.isfinite(a)))} "
                         f"NaN or infinite entr{'y' if np.sum(~np.isfinite(a)) == 1 else 'ies'}")
    return a


def _check_lattice(shape: Any, neighbourhood: Any, periodic: Any) -> tuple[int, int, int, bool]:
    H, W = _check_shape(shape)
    if isinstance(neighbourhood, bool) or neighbourhood not in (4, 8):
        raise ValueError(f"neighbourhood must be 4 or 8; got {neighbourhood!r}")
    periodic = check_bool("periodic", periodic)
    if periodic and (H % 2 or W % 2 or min(H, W) < 4):
        raise ValueError(f"shape must be even and at least 4 on both axes on a periodic lattice "
                         f"(a proper checkerboard, no doubled edge); got {(H, W)}")
    return H, W, int(neighbourhood), periodic


def _degrees(offsets: np.ndarray, periodic: bool) -> np.ndarray:
    """Neighbours of each type present at each boundary class (16, or 1 if periodic), (K, T).

    Class ``((r == 0) + 2 (r == H - 1)) * 4 + (c == 0) + 2 (c == W - 1)``, as the kernel's.
    """
    if periodic:
        return np.full((1, offsets.shape[0]), 2.0)
    out = np.zeros((16, offsets.shape[0]))
    for k in range(16):
        top, bottom, left, right = k // 4 & 1, k // 4 & 2, k % 4 & 1, k % 4 & 2
        for t, (dr, dc) in enumerate(offsets):
            fwd = not ((dr == 1 and bottom) or (dc == 1 and right) or (dc == -1 and left))
            bwd = not ((dr == 1 and top) or (dc == 1 and left) or (dc == -1 and right))
            out[k, t] = fwd + bwd
    return out


def _logits(J: np.ndarray, d: np.ndarray, offsets: np.ndarray, periodic: bool,
            iso: bool) -> tuple[np.ndarray, int]:
    """Conditional logits of state 1 without the field, (R, classes, leaves), and the mode.

    ``logit = f_i + sum_t n_t (d_t - J_t) + 2 sum_t J_t m_t`` for ``n_t`` neighbours of
    type ``t`` present, ``m_t`` of them in state 1. Leaves: the total ``m`` (isotropic:
    mode 0 for 4 neighbours, 1 for 8) or the ``m_t`` in base 3 (mode 2).
    """
    T = offsets.shape[0]
    deg = _degrees(offsets, periodic)  # (K, T)
    base = (d - J) @ deg.T  # (R, K)
    if iso:
        m = np.arange(2 * T + 1, dtype=np.float64)
        return base[:, :, None] + 2.0 * J[:, :1, None] * m, 0 if T == 2 else 1
    leaves = np.stack(np.unravel_index(np.arange(3 ** T), (3,) * T)[::-1], axis=1)  # (L, T)
    return base[:, :, None] + 2.0 * (J @ leaves.T.astype(np.float64))[:, None, :], 2


def _fixed(logit: np.ndarray) -> np.ndarray:
    """``floor(2^64 p)`` (at most ``2^64 - 1``) of ``p = 1 / (1 + exp(-logit))``, as the
    kernel computes it."""
    with np.errstate(over="ignore"):
        p = 1.0 / (1.0 + np.exp(-logit))
    out = np.full(p.shape, _ALL)
    below = p < 1.0  # then 2^64 p <= 2^64 - 2^11: it fits
    out[below] = (p[below] * 2.0**64).astype(np.uint64)
    return out


def _digits(p_fix: np.ndarray) -> np.ndarray:
    """Digit words (n_words, K, 64, L): bit ``r`` of ``[w, k, j, l]`` is binary digit ``j``
    (most significant first) of replica ``64 w + r``'s ``p_fix[., k, l]``."""
    R, K, L = p_fix.shape
    nw = -(-R // 64)
    out = np.empty((nw, K, 64, L), dtype=np.uint64)
    shift = (63 - np.arange(64)).astype(np.uint64)
    for w in range(nw):  # one word at a time: the bit array is 64 x the table
        block = np.zeros((64, K, L), dtype=np.uint64)
        block[:min(64, R - 64 * w)] = p_fix[64 * w:64 * (w + 1)]
        bits = ((block[..., None] >> shift) & np.uint64(1)).astype(np.uint8)  # (64, K, L, 64)
        out[w] = pack(bits)[0].transpose(0, 2, 1)
    return out


def _check_init(init: Any, R: int, H: int, W: int, rng: np.random.Generator) -> np.ndarray:
    """Packed start: uniform random bits, or ``init`` (R, H, W) / (H, W) in {0, 1}."""
    nw = -(-R // 64)
    if init is None:
        x = rng.integers(0, 2**64, size=(nw, H, W), dtype=np.uint64, endpoint=False)
        x &= _active(R)[:, None, None]
        return x
    a = np.asarray(init)
    if a.shape == (H, W):
        a = np.broadcast_to(a, (R, H, W))
    if a.shape != (R, H, W):
        raise ValueError(f"init must be None or spins of shape {(R, H, W)} or {(H, W)}; got "
                         f"shape {np.shape(init)}")
    if a.dtype.kind not in "biuf" or not np.all((a == 0) | (a == 1)):
        raise ValueError("init must hold spins 0 and 1 (bool or integer)")
    return pack(a)


def _active(R: int) -> np.ndarray:
    """Per word, the mask of its replicas (all 64 bits but in a last partial word)."""
    nw = -(-R // 64)
    act = np.full(nw, _ALL)
    if R % 64:
        act[-1] = np.uint64((1 << (R % 64)) - 1)
    return act


def _kernel_tables(J: np.ndarray, d: np.ndarray, f: np.ndarray, offsets: Any,
                   periodic: bool, shape: tuple[int, int]):
    """The kernel's ``(D, G, field, mode)``: probability digits for a site-shared field,
    else the logits without it and the padded per-node field (the other arrays empty)."""
    offsets = np.asarray(offsets, dtype=np.int64)
    R, nw = J.shape[0], -(-J.shape[0] // 64)
    iso = bool(np.all(J == J[:, :1]) and np.all(d == d[:, :1]))  # one count suffices
    Jb = np.broadcast_to(J[:, :1] if iso else J, (R, len(offsets)))
    db = np.broadcast_to(d[:, :1] if iso else d, (R, len(offsets)))
    g, mode = _logits(Jb, db, offsets, periodic, iso)  # (R, K, L)
    if f.ndim == 1:
        return _digits(_fixed(g + f[:, None, None])), np.zeros((0, 1, 1, 1)), \
            np.zeros((0, 1, 1)), mode
    gp = np.zeros((nw * 64, *g.shape[1:]))
    gp[:R] = g
    fld = np.zeros((nw * 64, *shape))
    fld[:R] = f
    return np.zeros((0, 1, 1, 1), np.uint64), \
        np.ascontiguousarray(gp.reshape(nw, 64, *g.shape[1:]).transpose(0, 2, 3, 1)), fld, mode


def multispin_gibbs(coupling: Any, field: Any, shape: Any, n_sweeps: int = 200, *,
                    seed: int | None = None, init: Any = None, neighbourhood: int = 4,
                    periodic: bool = False, edge_field: Any = None, thin: int = 10,
                    n: int = 1) -> np.ndarray:
    """Heat-bath (Gibbs) draws of ``R`` replicas of a binary lattice MRF, multi-spin coded.

    Each replica ``r`` samples ``p_r(x) ∝ exp(sum_i f_ri x_i + sum_e (J_rt [x_i == x_j]
    + d_rt (x_i + x_j)))`` (module docstring) by checkerboard heat-bath sweeps (Geman &
    Geman 1984), 64 replicas per machine word (Jacobs & Rebbi 1981; Zorn, Herrmann &
    Rebbi 1981); the replicas' chains are independent.

    Parameters
    ----------
    coupling : (R, T) float
        ``J``: one coupling per replica and edge type; ``T = 1`` (every edge) or one per
        direction (``T = 2``: horizontal, vertical; ``T = 4`` with 8 neighbours: also the
        diagonal and antidiagonal), in :func:`mrfpe.models.graph.lattice`'s order.
    field : (R,) or (R, H, W) float
        ``f``: the log-odds of state 1 apart from the edges, per replica or per replica
        and node (per node is exact but much slower: no shared probability tables).
    shape : (H, W)
    n_sweeps : int >= 0
        Burn-in: the first draw is the state after ``n_sweeps`` sweeps.
    seed : int or None
        The start and the kernel's key derive from ``numpy.random.default_rng(seed)``.
    init : None, (R, H, W) or (H, W) spins in {0, 1}
        The start; None: every spin of every replica uniform at random.
    neighbourhood : 4 or 8
    periodic : bool
        A torus (then ``H`` and ``W`` even and at least 4), else a free boundary.
    edge_field : (R, T) float, optional
        ``d``: per edge type, added to both ends' log-odds (zero by default).
    thin : int >= 1
        Sweeps between successive draws.
    n : int >= 1
        Draws per replica.

    Returns
    -------
    (R, n, H, W) int8
        Draw ``k`` of replica ``r`` is its state after ``n_sweeps + k * thin`` sweeps.
    """
    H, W, nb, periodic = _check_lattice(shape, neighbourhood, periodic)
    offsets = np.array(NEIGHBOURHOODS[nb], dtype=np.int64)
    shp = np.shape(coupling) if np.ndim(coupling) == 2 else ()
    J = _finite("coupling", coupling, (shp,) if shp[1:] in ((1,), (len(offsets),)) else (),
                f"(R, 1) or (R, {len(offsets)})")
    R, T = J.shape
    if R < 1:
        raise ValueError("coupling must have at least one row (one replica); got shape "
                         f"{J.shape}")
    f = _finite("field", field, ((R,), (R, H, W)), f"({R},) or ({R}, {H}, {W})")
    d = np.zeros_like(J) if edge_field is None else _finite(
        "edge_field", edge_field, ((R, T),), f"({R}, {T}) (as coupling)")
    n_sweeps = check_positive_int("n_sweeps", n_sweeps, 0)
    thin, n = check_positive_int("thin", thin), check_positive_int("n", n)
    nw = -(-R // 64)
    check_memory(8.0 * nw * 64 * n * H * W * 2 + 16.0 * nw * H * W,
                 f"multispin_gibbs: {n} draw(s) of {R} replica(s) of {H} x {W}",
                 "draw fewer (n) or smaller (shape) configurations, or fewer replicas")
    rng = np.random.default_rng(check_seed(seed))
    x = _check_init(init, R, H, W, rng)
    key = rng.integers(2**64, dtype=np.uint64)
    D, G, fld, mode = _kernel_tables(J, d, f, NEIGHBOURHOODS[nb], periodic, (H, W))
    when = n_sweeps + thin * np.arange(n)  # draw k: the state after sweep when[k]
    slot = np.full(when[-1], -1, dtype=np.int64)
    slot[when[when > 0] - 1] = np.flatnonzero(when > 0)
    out = np.empty((n, nw, H, W), dtype=np.uint64)
    out[0] = x
    xp = np.zeros((nw, H + 2, W + 2), dtype=np.uint64)  # a ghost border (the kernel's)
    xp[:, 1:-1, 1:-1] = x
    with thread_budget(H * W * nw * 16):
        sweeps(xp, D, G, fld, _active(R), offsets, periodic, mode, key, slot, out)
    return unpack(out.transpose(1, 0, 2, 3), R)


@dataclass(frozen=True)
class BinaryLattice:
    """A binary lattice MRF at ``N`` parameter vectors, as :func:`multispin_gibbs` takes it.

    ``multispin_gibbs(**params.arguments(), n_sweeps=..., seed=...)`` runs replica ``k`` at
    parameter vector ``k``.
    """

    coupling: np.ndarray  # (N, T)
    field: np.ndarray  # (N,) or (N, H, W)
    edge_field: np.ndarray  # (N, T)
    shape: tuple[int, int]
    neighbourhood: int
    periodic: bool

    def arguments(self) -> dict[str, Any]:
        """Keyword arguments of :func:`multispin_gibbs` (all but the sweeps and seed)."""
        return {"coupling": self.coupling, "field": self.field, "edge_field": self.edge_field,
                "shape": self.shape, "neighbourhood": self.neighbourhood,
                "periodic": self.periodic}


def _lattice_rule(design: Design) -> LatticeSpec | str:
    """The 4- or 8-neighbour lattice rule ``design``'s graph was built by, else why not."""
    g = design.graph
    if g.shape is None or len(g.shape) != 2:
        return "its graph is not a 2-D lattice"
    for nb in (4, 8):
        for periodic in (False, True):
            spec = LatticeSpec(NEIGHBOURHOODS[nb], periodic, g.n_edge_types > 1)
            if g.n_edge_types not in (1, nb // 2):
                continue
            if spec.directional and g.edge_type_names != spec.edge_type_names:
                continue
            if _same_edges(g, spec):
                return spec
    return "its graph is not a 4- or 8-neighbour lattice (free or periodic boundary)"


def _same_edges(g: Any, spec: LatticeSpec) -> bool:
    H, W = g.shape
    per_node = len(spec.offsets) * H * W  # an upper bound on the lattice's edges
    if g.n_edges > per_node:
        return False
    built = spec.build(g.shape)
    return built.n_edges == g.n_edges and np.array_equal(built.edges, g.edges) and \
        np.array_equal(built.edge_type, g.edge_type)


def why_not(design: Any) -> str | None:
    """Why :func:`multispin_gibbs` cannot run ``design``; None if it can (:func:`applies`)."""
    if not isinstance(design, Design):
        return f"it is not a compiled Design ({type(design).__name__})"
    if design.q != 2:
        return f"it has {design.q} states, not 2"
    if design.pair_per_edge:
        return "its pair potentials differ from edge to edge (edge covariates)"
    spec = _lattice_rule(design)
    if isinstance(spec, str):
        return spec
    if spec.periodic:
        H, W = design.graph.shape
        if H % 2 or W % 2 or min(H, W) < 4:
            return f"its periodic lattice {(H, W)} is not even and at least 4 on both axes"
    return None


def applies(design: Any) -> bool:
    """Whether ``design`` is a binary 4- or 8-neighbour lattice MRF that
    :func:`multispin_gibbs` runs (per-type pair tables shared by all edges of a type;
    node potentials shared or per node)."""
    return why_not(design) is None


def lattice_parameters(design: Design, psi: Any) -> BinaryLattice:
    """``design`` at the feature vectors ``psi`` (N, P) or (P,), as :func:`multispin_gibbs`'s
    parameters: replica ``k`` samples ``design`` at ``psi[k]``.

    A symmetric pair table ``A`` of type ``t`` is ``J [a == b] + d (a + b) + c`` with
    ``J = (A00 + A11) / 2 - A01`` and ``d = (A11 - A00) / 2``; the field is
    ``node[i, 1] - node[i, 0]``.
    """
    if (reason := why_not(design)) is not None:
        raise ValueError(f"design cannot be run by multispin_gibbs: {reason}")
    psi = np.atleast_2d(np.asarray(psi, dtype=np.float64))
    if psi.ndim != 2 or psi.shape[1] != design.n_features:
        raise ValueError(f"psi must have shape (N, {design.n_features}) or "
                         f"({design.n_features},); got {np.shape(psi)}")
    if not np.all(np.isfinite(psi)):
        raise ValueError("psi must hold finite numbers (forbidden states, -inf, need the "
                         "scalar simulator)")
    node, pair = design.tables(psi)  # (N, n|1, 2), (N, T, 2, 2)
    spec = _lattice_rule(design)
    assert isinstance(spec, LatticeSpec)
    J = (pair[..., 0, 0] + pair[..., 1, 1]) / 2 - pair[..., 0, 1]
    d = (pair[..., 1, 1] - pair[..., 0, 0]) / 2
    f = node[..., 1] - node[..., 0]
    H, W = design.graph.shape
    f = f[:, 0] if f.shape[1] == 1 else f.reshape(-1, H, W)
    return BinaryLattice(J, f, d, (H, W), 2 * len(spec.offsets), spec.periodic)
