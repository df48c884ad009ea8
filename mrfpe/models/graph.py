"""The graph of an MRF: nodes, undirected edges with a type, and a proper colouring.

A :class:`Graph` is fixed (``n_nodes`` known); a :class:`LatticeSpec` is a
lattice *rule* (neighbourhood offsets, boundary) that becomes a :class:`Graph`
once the data's shape is known, so a model declared on a lattice applies to
data of any size.

Edges are stored once, ``i < j``, with an integer ``edge_type`` in
``[0, n_edge_types)``: on a lattice the type is the direction (horizontal,
vertical, the two diagonals, or any offset), so that a model may give each
direction its own parameter. Neighbour lists are kept in CSR form.

The colouring is proper (no edge joins two nodes of one colour): Besag's
codings (Besag 1974, Sec. 6.1) are its colour classes, and colour-parallel
Gibbs sweeps update one class at a time. Lattices use the periodic colourings
``(r + c) % 2`` (4-neighbourhood) and ``2 (r % 2) + c % 2`` (8-neighbourhood)
when they are proper, and general graphs a greedy largest-first colouring.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

__all__ = ["Graph", "LatticeSpec", "as_graph_spec", "from_adjacency", "from_networkx",
           "lattice"]

#: Offsets (dr, dc) of the 4- and 8-neighbourhoods; each undirected offset once.
NEIGHBOURHOODS = {
    4: ((0, 1), (1, 0)),
    8: ((0, 1), (1, 0), (1, 1), (1, -1)),
}
_OFFSET_NAMES = {(0, 1): "horizontal", (1, 0): "vertical", (1, 1): "diagonal",
                 (1, -1): "antidiagonal"}


class Graph:
    """An undirected simple graph with typed edges (immutable).

    Parameters
    ----------
    n_nodes : int
    edges : ndarray (E, 2) int64
        Each edge once, ``i < j``, sorted (given in any order and orientation).
    edge_type : ndarray (E,) int64
        In ``[0, len(edge_type_names))``.
    edge_type_names : tuple of str
    shape : tuple of int or None
        ``(H, W)`` for a lattice (node ``r * W + c``), else None.
    colours : ndarray (n_nodes,), optional
        A proper colouring to use instead of the greedy one (checked).
    """

    def __init__(self, n_nodes: int, edges: Any, edge_type: Any = None,
                 edge_type_names: tuple[str, ...] = ("edge",),
                 shape: tuple[int, ...] | None = None, colours: Any = None) -> None:
        if isinstance(n_nodes, bool) or not isinstance(n_nodes, int | np.integer) \
                or n_nodes < 1:
            raise ValueError(f"n_nodes must be a positive integer; got {n_nodes!r}")
        self.n_nodes = int(n_nodes)
        self.edge_type_names = tuple(str(t) for t in edge_type_names)
        self.shape = None if shape is None else tuple(int(s) for s in shape)
        edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        etype = (np.zeros(edges.shape[0], np.int64) if edge_type is None
                 else np.asarray(edge_type, dtype=np.int64).reshape(-1))
        if etype.shape[0] != edges.shape[0]:
            raise ValueError(f"edge_type must have one entry per edge ({edges.shape[0]}); "
                             f"got {etype.shape[0]}")
        if edges.size and (edges.min() < 0 or edges.max() >= self.n_nodes):
            raise ValueError(f"edges must join nodes in [0, {self.n_nodes - 1}]; got "
                             f"[{edges.min()}, {edges.max()}]")
        if np.any(edges[:, 0] == edges[:, 1]):
            i = int(edges[edges[:, 0] == edges[:, 1]][0, 0])
            raise ValueError(f"graph must have no self-loops; node {i} is joined to itself")
        lo, hi = np.minimum(edges[:, 0], edges[:, 1]), np.maximum(edges[:, 0], edges[:, 1])
        order = np.lexsort((hi, lo))
        edges = np.stack([lo, hi], axis=1)[order]
        etype = etype[order]
        if edges.shape[0] > 1 and np.any(np.all(edges[1:] == edges[:-1], axis=1)):
            raise ValueError("graph must not list an edge twice")
        if etype.size and (etype.min() < 0 or etype.max() >= len(self.edge_type_names)):
            raise ValueError(f"edge_type must lie in [0, {len(self.edge_type_names) - 1}]")
        edges.setflags(write=False)
        etype.setflags(write=False)
        self.edges, self.edge_type = edges, etype
        self._colours = None
        self._neighbours: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        if colours is not None:
            c = np.asarray(colours, dtype=np.int64).reshape(-1)
            if c.shape != (self.n_nodes,) or np.any(c[edges[:, 0]] == c[edges[:, 1]]):
                raise ValueError("colours must be a proper colouring, one per node")
            c.setflags(write=False)
            self._colours = c

    # -- derived structure -----------------------------------------------------------------------
    @property
    def n_edges(self) -> int:
        return int(self.edges.shape[0])

    @property
    def n_edge_types(self) -> int:
        return len(self.edge_type_names)

    def neighbours(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """CSR ``(indptr, neighbour, edge_index)``: every node's neighbours and the joining edge."""
        if self._neighbours is None:  # a cache of a pure function of the (immutable) graph
            self._neighbours = self._build_neighbours()
        return self._neighbours

    def _build_neighbours(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        e = self.edges
        src = np.concatenate([e[:, 0], e[:, 1]])
        dst = np.concatenate([e[:, 1], e[:, 0]])
        eid = np.concatenate([np.arange(self.n_edges)] * 2)
        order = np.lexsort((dst, src))
        indptr = np.zeros(self.n_nodes + 1, dtype=np.int64)
        np.cumsum(np.bincount(src, minlength=self.n_nodes), out=indptr[1:])
        return indptr, dst[order].astype(np.int64), eid[order].astype(np.int64)

    def degree(self) -> np.ndarray:
        """Number of neighbours of each node."""
        return np.bincount(self.edges.ravel(), minlength=self.n_nodes)

    def adjacency(self, edge_type: int | None = None) -> sp.csr_matrix:
        """Symmetric 0/1 adjacency (of one edge type, or all) as a sparse matrix."""
        keep = slice(None) if edge_type is None else self.edge_type == edge_type
        e = self.edges[keep]
        ones = np.ones(2 * e.shape[0])
        rows = np.concatenate([e[:, 0], e[:, 1]])
        cols = np.concatenate([e[:, 1], e[:, 0]])
        return sp.csr_matrix((ones, (rows, cols)), shape=(self.n_nodes, self.n_nodes))

    def colouring(self) -> np.ndarray:
        """A proper colouring (n_nodes,) int64: colours from 0 to ``n_colours - 1``."""
        if self._colours is None:
            colours = _greedy_colouring(self)
            colours.setflags(write=False)
            self._colours = colours  # a cache of a pure function of the (immutable) graph
        return self._colours

    @property
    def n_colours(self) -> int:
        c = self.colouring()
        return int(c.max()) + 1 if c.size else 0

    def colour_classes(self) -> list[np.ndarray]:
        """Node ids of each colour, in colour order: Besag's codings."""
        c = self.colouring()
        return [np.flatnonzero(c == k) for k in range(self.n_colours)]

    def describe(self) -> dict:
        return {"n_nodes": self.n_nodes, "n_edges": self.n_edges,
                "edge_types": list(self.edge_type_names),
                "shape": None if self.shape is None else list(self.shape)}

    def __repr__(self) -> str:
        where = f", shape={self.shape}" if self.shape is not None else ""
        return (f"Graph(n_nodes={self.n_nodes}, n_edges={self.n_edges}, "
                f"edge_types={self.edge_type_names}{where})")


def _greedy_colouring(g: Graph) -> np.ndarray:
    """Greedy colouring in largest-degree-first order (Welsh & Powell 1967), balanced.

    Greedy alone ends in small classes (a scale-free graph's hub alone in its colour): a
    coding over a handful of nodes estimates nothing, and spoils the codings' mean. So a
    class whose every node has another colour free of its neighbours is emptied into
    them, then nodes move from the largest class to the smallest (where no neighbour has
    that colour) until the sizes differ by at most one or none can move. Colours are
    renumbered in order of first appearance; the colouring stays proper.
    """
    indptr, nbr, _ = g.neighbours()
    n, colours = g.n_nodes, np.full(g.n_nodes, -1, dtype=np.int64)
    for v in np.argsort(-g.degree(), kind="stable"):
        used = set(colours[nbr[indptr[v]:indptr[v + 1]]].tolist())
        colours[v] = next(c for c in range(len(used) + 1) if c not in used)
    k = int(colours.max()) + 1 if n else 1
    counts = np.zeros((n, k), dtype=np.int64)  # neighbours of each colour, per node
    np.add.at(counts, (np.repeat(np.arange(n), np.diff(indptr)), colours[nbr]), 1)

    def move(v: int, c: int) -> None:
        ns = nbr[indptr[v]:indptr[v + 1]]
        np.add.at(counts[:, colours[v]], ns, -1)
        np.add.at(counts[:, c], ns, 1)
        colours[v] = c

    for c in np.argsort(np.bincount(colours, minlength=k), kind="stable"):
        size = np.bincount(colours, minlength=k)
        members = np.flatnonzero(colours == c)
        free = (counts[members] == 0) & (size > 0) & (np.arange(k) != c)
        if members.size and np.count_nonzero(size) > 1 and free.any(axis=1).all():
            for v, row in zip(members, free, strict=True):
                move(int(v), int(np.argmax(row)))
    for _ in range(n):
        size = np.where(np.bincount(colours, minlength=k) > 0, np.bincount(colours, minlength=k),
                        np.nan)
        small, large = int(np.nanargmin(size)), int(np.nanargmax(size))
        cand = np.flatnonzero((colours == large) & (counts[:, small] == 0))
        if size[large] - size[small] <= 1 or cand.size == 0:
            break
        move(int(cand[0]), small)
    _, first = np.unique(colours, return_index=True)
    relabel = np.zeros(k, dtype=np.int64)
    relabel[colours[np.sort(first)]] = np.arange(first.size)
    return relabel[colours]


@dataclass(frozen=True)
class LatticeSpec:
    """A rectangular lattice rule: offsets, boundary and per-direction edge types.

    Use :func:`lattice` to build one. ``build((H, W))`` gives the :class:`Graph`.
    """

    offsets: tuple[tuple[int, int], ...]
    periodic: bool = False
    directional: bool = False

    @property
    def edge_type_names(self) -> tuple[str, ...]:
        if not self.directional:
            return ("edge",)
        return tuple(_OFFSET_NAMES.get(o, f"offset_{o[0]}_{o[1]}") for o in self.offsets)

    def build(self, shape: Any) -> Graph:
        """The lattice graph of an ``(H, W)`` array of nodes."""
        H, W = _check_shape(shape)
        r, c = np.divmod(np.arange(H * W, dtype=np.int64), W)
        edges, types = [], []
        for t, (dr, dc) in enumerate(self.offsets):
            r2, c2 = r + dr, c + dc
            if self.periodic:
                r2, c2 = r2 % H, c2 % W
                keep = np.ones(H * W, dtype=bool)
            else:
                keep = (r2 >= 0) & (r2 < H) & (c2 >= 0) & (c2 < W)
            i, j = r[keep] * W + c[keep], r2[keep] * W + c2[keep]
            ok = i != j  # a periodic offset that wraps onto itself (H or W of 1) adds nothing
            pair = np.stack([np.minimum(i, j), np.maximum(i, j)], axis=1)[ok]
            edges.append(pair)
            types.append(np.full(pair.shape[0], t if self.directional else 0))
        e = np.concatenate(edges) if edges else np.zeros((0, 2), np.int64)
        t = np.concatenate(types) if types else np.zeros(0, np.int64)
        if self.periodic and min(H, W) <= 2 * max(max(abs(a), abs(b)) for a, b in self.offsets):
            # a wrap on a narrow torus can meet the same pair twice: keep one
            e, first = np.unique(e, axis=0, return_index=True)
            t = t[first]
        colours = self._colouring(H, W)
        if colours is not None and np.any(colours[e[:, 0]] == colours[e[:, 1]]):
            colours = None  # e.g. a periodic lattice of odd size: fall back to greedy
        return Graph(H * W, e, t, self.edge_type_names, (H, W), colours)

    def _colouring(self, H: int, W: int) -> np.ndarray | None:
        r, c = np.divmod(np.arange(H * W, dtype=np.int64), W)
        if set(self.offsets) <= {(0, 1), (1, 0)}:
            return (r + c) % 2
        if set(self.offsets) <= set(NEIGHBOURHOODS[8]):
            return 2 * (r % 2) + c % 2
        return None

    def n_codings(self, shape: Any) -> int:
        """Number of Besag codings (colours) of the lattice of ``shape``."""
        return self.build(shape).n_colours

    def describe(self) -> dict:
        return {"lattice": [list(o) for o in self.offsets], "periodic": self.periodic,
                "edge_types": list(self.edge_type_names)}


def _check_shape(shape: Any) -> tuple[int, int]:
    try:
        H, W = (int(s) for s in shape)
    except (TypeError, ValueError):
        raise ValueError(f"shape must be (H, W) with positive integers; got {shape!r}") from None
    if H < 1 or W < 1:
        raise ValueError(f"shape must be (H, W) with positive integers; got {shape!r}")
    return H, W


def lattice(neighbourhood: Any = 4, *, periodic: bool = False,
            directional: bool = False) -> LatticeSpec:
    """A lattice rule for :class:`mrfpe.models.MRF`.

    Parameters
    ----------
    neighbourhood : 4, 8 or sequence of (dr, dc)
        First-order (4) or second-order (8) neighbourhood, or any set of offsets
        (each undirected offset once: ``(0, 1)`` joins ``(r, c)`` and ``(r, c+1)``).
    periodic : bool
        Wrap around at the edges (a torus); free boundary by default.
    directional : bool
        One edge type per offset (``horizontal``, ``vertical``, ``diagonal``,
        ``antidiagonal``, ``offset_dr_dc``), so pair terms may carry one
        parameter per direction.
    """
    if isinstance(neighbourhood, int | np.integer) and not isinstance(neighbourhood, bool):
        if int(neighbourhood) not in NEIGHBOURHOODS:
            raise ValueError(f"neighbourhood must be 4, 8 or a sequence of (dr, dc) offsets; "
                             f"got {neighbourhood!r}")
        offsets = NEIGHBOURHOODS[int(neighbourhood)]
    else:
        try:
            offsets = tuple((int(a), int(b)) for a, b in neighbourhood)
        except (TypeError, ValueError):
            raise ValueError(f"neighbourhood must be 4, 8 or a sequence of (dr, dc) offsets; "
                             f"got {neighbourhood!r}") from None
        canon = []
        for o in offsets:
            if o == (0, 0):
                raise ValueError("neighbourhood offsets must not include (0, 0) (a self-loop)")
            o = o if (o[0] > 0 or (o[0] == 0 and o[1] > 0)) else (-o[0], -o[1])
            if o in canon:
                raise ValueError(f"neighbourhood lists the offset {o} twice (or with its mirror)")
            canon.append(o)
        if not canon:
            raise ValueError("neighbourhood must hold at least one offset")
        offsets = tuple(canon)
    for name, val in (("periodic", periodic), ("directional", directional)):
        if not isinstance(val, bool | np.bool_):
            raise ValueError(f"{name} must be True or False; got {val!r}")
    return LatticeSpec(offsets, bool(periodic), bool(directional))


def from_adjacency(adjacency: Any, edge_type: Any = None,
                   edge_type_names: tuple[str, ...] | None = None) -> Graph:
    """A :class:`Graph` from a symmetric (sparse or dense) adjacency matrix.

    Parameters
    ----------
    adjacency : (n, n) array or scipy sparse matrix
        Nonzero entries are edges; must be symmetric with an empty diagonal. NaN
        entries are refused (neither an edge nor no edge).
    edge_type : (n, n) integer array or sparse matrix, optional
        Per edge, a type ``1 .. T`` (0 or absent: no edge); defaults to one type.
    edge_type_names : tuple of str, optional
    """
    try:
        A = sp.csr_matrix(adjacency)
    except (TypeError, ValueError):
        raise ValueError(f"adjacency must be an (n, n) matrix; got {type(adjacency).__name__}") \
            from None
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"adjacency must be square (n, n); got shape {A.shape}")
    _refuse_nan(A, "adjacency")
    A.eliminate_zeros()
    if A.diagonal().any():
        i = int(np.flatnonzero(A.diagonal())[0])
        raise ValueError(f"adjacency must have an empty diagonal (no self-loops); "
                         f"node {i} is joined to itself")
    pattern = (A != 0).astype(np.int8)
    if (pattern != pattern.T).nnz:
        rr, cc = (pattern != pattern.T).nonzero()
        raise ValueError(f"adjacency must be symmetric; entry ({rr[0]}, {cc[0]}) has no "
                         f"mirror ({cc[0]}, {rr[0]})")
    upper = sp.triu(pattern, k=1).tocoo()
    edges = np.stack([upper.row, upper.col], axis=1).astype(np.int64)
    if edge_type is None:
        types = np.zeros(edges.shape[0], np.int64)
        names = edge_type_names or ("edge",)
    else:
        try:
            T = sp.csr_matrix(edge_type)
        except (TypeError, ValueError):
            raise ValueError(f"edge_type must be an (n, n) integer matrix; got "
                             f"{type(edge_type).__name__}") from None
        if T.shape != A.shape:
            raise ValueError(f"edge_type must have the adjacency's shape {A.shape}; "
                             f"got {T.shape}")
        _refuse_nan(T, "edge_type")
        if (T != T.T).nnz:
            raise ValueError("edge_type must be symmetric (an undirected edge has one type)")
        raw = np.asarray(T[edges[:, 0], edges[:, 1]], dtype=np.float64).ravel()
        if np.any(raw != np.round(raw)) or np.any(np.abs(raw) > 2**31):
            k = int(np.flatnonzero((raw != np.round(raw)) | (np.abs(raw) > 2**31))[0])
            raise ValueError(f"edge_type must hold integer types 1 .. T; edge ({edges[k, 0]}, "
                             f"{edges[k, 1]}) has {raw[k]:g}")
        types = raw.astype(np.int64) - 1
        if np.any(types < 0):
            raise ValueError("edge_type must give every edge a type >= 1")
        names = edge_type_names or tuple(f"type_{k + 1}" for k in range(int(types.max()) + 1))
    return Graph(A.shape[0], edges, types, tuple(names))


def _refuse_nan(M: sp.csr_matrix, name: str) -> None:
    """ValueError naming how many entries of ``M`` are NaN and the first (row-major)."""
    if M.dtype.kind not in "fc" or not np.isnan(M.data).any():
        return
    coo = M.tocoo()
    bad = np.flatnonzero(np.isnan(coo.data))
    first = bad[np.lexsort((coo.col[bad], coo.row[bad]))[0]]
    raise ValueError(f"{name} holds {bad.size} NaN entr{'y' if bad.size == 1 else 'ies'} (the "
                     f"first at ({coo.row[first]}, {coo.col[first]})): an entry must be a "
                     f"number, zero for no edge")


def from_networkx(graph: Any, edge_type: str | None = None) -> Graph:
    """A :class:`Graph` from a networkx graph (nodes numbered from 0 in node order).

    ``edge_type`` names an edge attribute holding each edge's type (any hashable;
    types are numbered in sorted order of their string form).
    """
    try:
        import networkx as nx
    except ImportError as exc:  # pragma: no cover - networkx is optional
        raise ImportError("from_networkx needs networkx (pip install networkx)") from exc
    if not isinstance(graph, nx.Graph) or graph.is_directed():
        raise ValueError(f"graph must be an undirected networkx.Graph; got {type(graph).__name__}")
    if graph.is_multigraph():
        raise ValueError(f"graph must be a simple networkx.Graph (one edge per pair of nodes); "
                         f"got a {type(graph).__name__}")
    nodes = list(graph.nodes)
    index = {v: k for k, v in enumerate(nodes)}
    pairs, labels = [], []
    for u, v, data in graph.edges(data=True):
        if u == v:
            raise ValueError(f"graph must have no self-loops; node {u!r} is joined to itself")
        pairs.append((index[u], index[v]))
        labels.append(None if edge_type is None else data.get(edge_type))
    if edge_type is None:
        names: tuple[str, ...] = ("edge",)
        types = np.zeros(len(pairs), np.int64)
    else:
        if any(lab is None for lab in labels):
            raise ValueError(f"every edge must carry the attribute {edge_type!r}")
        names = tuple(sorted({str(lab) for lab in labels}))
        types = np.array([names.index(str(lab)) for lab in labels], dtype=np.int64)
    edges = np.array(pairs, dtype=np.int64).reshape(-1, 2)
    return Graph(len(nodes), edges, types, names)


def as_graph_spec(graph: Any) -> Graph | LatticeSpec:
    """A :class:`Graph` or :class:`LatticeSpec` from what a user passes as ``graph``."""
    if isinstance(graph, Graph | LatticeSpec):
        return graph
    if isinstance(graph, int | np.integer) and not isinstance(graph, bool):
        return lattice(int(graph))
    if sp.issparse(graph) or isinstance(graph, np.ndarray):
        return from_adjacency(graph)
    mod = type(graph).__module__ or ""
    if mod.startswith("networkx"):
        return from_networkx(graph)
    raise ValueError(f"graph must be a Graph, a lattice(...), 4 or 8, an adjacency matrix or a "
                     f"networkx graph; got {type(graph).__name__}")
