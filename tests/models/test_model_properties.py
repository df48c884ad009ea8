"""Property: for random small declared models the pseudolikelihood (and, where the lattice
is small enough to list, the exact likelihood) equals brute force.

A model is drawn from the declarations (fields, couplings per edge type or shared across
groups of edge types, state-specific or value covariates, array edge covariates, or a
general potential with forbidden pairs). The brute force reads the declaration's meaning
straight from the drawn choices: edges listed from the offsets, statistics counted by
hand, forbidden entries as zero weight; it never uses the model's design.
"""

from __future__ import annotations

import itertools
from datetime import timedelta

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.special import logsumexp

from mrfpe.models import MRF, Coupling, EdgeCovariate, Field, NodeCovariate, Potential, lattice

OFFSETS = {4: ((0, 1), (1, 0)), 8: ((0, 1), (1, 0), (1, 1), (1, -1))}
NAMES = ("horizontal", "vertical", "diagonal", "antidiagonal")


def _pairs(H, W, offsets):
    return np.array([(r * W + c, (r + dr) * W + c + dc, t) for r in range(H) for c in range(W)
                     for t, (dr, dc) in enumerate(offsets)
                     if 0 <= r + dr < H and 0 <= c + dc < W])


@st.composite
def _term(draw, q, types, H, W, used, rng):
    """(term, stats(X, P, v) -> (N, k), covariates) for one drawn log-linear term."""
    n = H * W
    what = draw(st.sampled_from(["field", "coupling", "node", "edge"]))
    if what == "field":
        kind = draw(st.sampled_from(["indicator", "value"]))
        name = f"f{len(used)}"

        def stats(X, P, v):
            return v[X].sum(1)[:, None] if kind == "value" else np.stack(
                [(X == a).sum(1) for a in range(1, q)], axis=1)
        return Field(kind, name=name), stats, {}
    if what == "coupling":
        kind = draw(st.sampled_from(["indicator", "product"]))
        mode = draw(st.sampled_from(["shared", "each", "groups"]))
        if mode == "groups":  # a random partition of a random subset of the types
            chosen = draw(st.lists(st.sampled_from(range(len(types))), min_size=1, unique=True))
            cut = draw(st.integers(1, len(chosen)))
            parts = [chosen[:cut], chosen[cut:]] if cut < len(chosen) else [chosen]
            by_type = {f"g{k}": tuple(types[t] for t in p) for k, p in enumerate(parts)}
            groups = parts
        else:
            by_type = mode == "each"
            groups = ([[t] for t in range(len(types))] if by_type and len(types) > 1
                      else [list(range(len(types)))])
        name = f"c{len(used)}"

        def stats(X, P, v):
            f = (X[:, P[:, 0]] == X[:, P[:, 1]]) if kind == "indicator" else (
                v[X[:, P[:, 0]]] * v[X[:, P[:, 1]]])
            return np.stack([f[:, np.isin(P[:, 2], g)].sum(1) for g in groups], axis=1)
        return Coupling(kind, by_type=by_type, name=name), stats, {}
    if what == "node":
        k = draw(st.integers(1, 2))
        z = rng.normal(size=(H, W, k)) if k > 1 else rng.normal(size=(H, W))
        zz = z.reshape(n, k)
        kind = draw(st.sampled_from(["indicator", "value"]))
        states = None
        if kind == "indicator" and draw(st.booleans()):
            states = draw(st.lists(st.integers(0, q - 1), min_size=1, max_size=q - 1,
                                   unique=True))
        cov = f"z{len(used)}"
        sts = (list(range(1, q)) if states is None else states)

        def stats(X, P, v):
            if kind == "value":
                return np.stack([(v[X] * zz[:, j]).sum(1) for j in range(k)], axis=1)
            return np.stack([((X == a) * zz[:, j]).sum(1) for j in range(k) for a in sts], 1)
        return NodeCovariate(cov, kind, states=states), stats, {cov: z}
    kind = draw(st.sampled_from(["indicator", "product"]))
    cov = f"w{len(used)}"
    w_of = {}

    def stats(X, P, v):
        w = np.array([w_of[(i, j)] for i, j, _ in P])
        f = (X[:, P[:, 0]] == X[:, P[:, 1]]) if kind == "indicator" else (
            v[X[:, P[:, 0]]] * v[X[:, P[:, 1]]])
        return (f * w).sum(1)[:, None]
    return EdgeCovariate(cov, kind), stats, {cov: w_of}


def _cond_log(lw, obs):
    """log p(obs) from log-weights: -inf where the observed alternative is forbidden."""
    return -np.inf if lw[obs] == -np.inf else lw[obs] - logsumexp(lw)


@st.composite
def _log_linear(draw):
    q, nb, directional = draw(st.integers(2, 3)), draw(st.sampled_from([4, 8])), draw(
        st.booleans())
    H, W = draw(st.integers(1, 3)), draw(st.integers(2, 3))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    types = NAMES[:len(OFFSETS[nb])] if directional else ("edge",)
    used: list = []
    for _ in range(draw(st.integers(1, 3))):
        used.append(draw(_term(q, types, H, W, used, rng)))
    v = np.sort(rng.normal(size=q)) if draw(st.booleans()) else np.arange(q, dtype=float)
    model = MRF(lattice(nb, directional=directional), q, [t for t, _, _ in used],
                state_values=v)
    P = _pairs(H, W, OFFSETS[nb])
    if not directional:
        P[:, 2] = 0
    g = model.graph((H, W))
    cov = {}
    for _, _, c in used:
        for name, val in c.items():
            if isinstance(val, dict):  # an edge covariate: by node pair, then in graph order
                val.update({(int(i), int(j)): float(rng.normal()) for i, j, _ in P})
                cov[name] = np.array([val[(int(i), int(j))] for i, j in g.edges])
            else:
                cov[name] = val

    def energy(theta, X):
        return np.concatenate([s(X, P, v) for _, s, _ in used], axis=1) @ theta
    return model, (H, W), cov or None, energy, rng


@st.composite
def _potential(draw):
    """theta = (scale, slope): pair_t = scale A_t + B_t (B_t with -inf: forbidden pairs),
    node = slope * a."""
    q, nb, directional = draw(st.integers(2, 4)), draw(st.sampled_from([4, 8])), draw(
        st.booleans())
    H, W = draw(st.integers(1, 3)), draw(st.integers(2, 3))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    T = len(OFFSETS[nb]) if directional else 1
    A = rng.normal(size=(T, q, q))
    B = rng.normal(size=(T, q, q))
    B[rng.random((T, q, q)) < draw(st.sampled_from([0.0, 0.15, 0.4]))] = -np.inf
    A, B = A + A.transpose(0, 2, 1), np.minimum(B, B.transpose(0, 2, 1))

    def pair(theta):
        out = theta[:, 0, None, None, None] * A[None] + B[None]
        return out[:, 0] if T == 1 and draw_shared else out
    draw_shared = draw(st.booleans())
    pot = Potential([("scale", (-2.0, 2.0)), ("slope", (-1.0, 1.0))], pair=pair,
                    node=lambda th: th[:, 1:2] * np.arange(q))
    model = MRF(lattice(nb, directional=directional), q, potential=pot)
    P = _pairs(H, W, OFFSETS[nb])
    if not directional:
        P[:, 2] = 0

    def energy(theta, X):
        tab = theta[0] * A + B
        return tab[P[:, 2], X[:, P[:, 0]], X[:, P[:, 1]]].sum(1) + theta[1] * X.sum(1)
    return model, (H, W), None, energy, rng


@settings(max_examples=60, deadline=timedelta(seconds=10), derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(_log_linear(), _potential()), st.integers(1, 2))
def test_property_pl_and_exact_equal_brute_force(case, M):
    model, shape, cov, energy, rng = case
    q, n = model.n_states, shape[0] * shape[1]
    names = model.param_names(covariates=cov, shape=shape)
    theta = rng.uniform(-0.9, 0.9, size=len(names))
    x = rng.integers(0, q, (M, *shape))
    flat = x.reshape(M, n)
    want = 0.0
    for xm in flat:
        for i in range(n):
            alt = np.repeat(xm[None], q, axis=0)
            alt[:, i] = np.arange(q)
            want += _cond_log(energy(theta, alt), xm[i])
    got = model.target("pl", x, covariates=cov).log_prob(theta)[0]
    if want == -np.inf:
        assert got == -np.inf
    else:
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10)
    if q ** n <= 4096:
        X = np.array(list(itertools.product(range(q), repeat=n)))
        lw = energy(theta, X)
        if np.all(lw == -np.inf):  # no configuration at all: every datum is forbidden
            want = -np.inf
        else:
            lz = logsumexp(lw)
            want = sum(energy(theta, xm[None])[0] - lz for xm in flat)
        got = model.target("exact", x, covariates=cov).log_prob(theta)[0]
        if want == -np.inf:
            assert got == -np.inf
        else:
            np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10)
