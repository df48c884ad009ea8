"""BRDF pseudolikelihood targets against independent brute force and their identities."""

from __future__ import annotations

import json

import numpy as np
import pytest

import mrfpe
from mrfpe import brdf as B
from mrfpe.brdf import shading
from mrfpe.brdf.synthetic import make_scene
from mrfpe.targets import get, names, softened
from mrfpe.targets.maximise import grid_points


@pytest.fixture(scope="module")
def tiny():
    """3x3-pixel noisy Ward scene (16 nodes, 4 labels)."""
    return make_scene(brdf="ward", theta=[0.6, 0.5, 0.2], shape=(3, 3), n_labels=4,
                      noise=0.01, seed=3)


# ----------------------------------------------------------------------------------------
# Independent brute force: loops over nodes, labels, pixels and triangles, shading each
# triangle with mrfpe.brdf.shading / mrfpe.brdf directly (no tables, no kernel).
# ----------------------------------------------------------------------------------------
def _radiance(scene, theta_nat, p0, p1, p2):
    g = shading.triangle_geometry(p0[None], p1[None], p2[None], scene.camera, scene.light,
                                  scene.tangent_ref)
    return float(shading.radiance(scene.brdf, theta_nat[None], g)[0, 0])


def brute_energies(scene, theta_nat, sigma_b, data_term="pixel"):
    """U^A_i(s) for every node (row-major) and label, by plain loops."""
    H, W = scene.shape
    Bn = scene.n_labels
    P = scene.label_points()
    Q = scene.observed_points()
    y = scene.image
    U = np.zeros(((H + 1) * (W + 1), Bn))
    for r in range(H + 1):
        for c in range(W + 1):
            for s in range(Bn):
                total = 0.0
                for pr in (r - 1, r):
                    for pc in (c - 1, c):
                        if not (0 <= pr < H and 0 <= pc < W):
                            continue
                        corners = {(pr, pc): "TL", (pr, pc + 1): "TR", (pr + 1, pc): "BL",
                                   (pr + 1, pc + 1): "BR"}

                        def pt(rc, _r=r, _c=c, _s=s):
                            return P[_r, _c, _s] if rc == (_r, _c) else Q[rc]

                        if data_term == "pixel":
                            tl, tr, bl, br = (pr, pc), (pr, pc + 1), (pr + 1, pc), (pr + 1, pc + 1)
                            # renderer's split along TL-BR: (TL, TR, BR) and (TL, BR, BL)
                            la = _radiance(scene, theta_nat, pt(tl), pt(tr), pt(br))
                            lb = _radiance(scene, theta_nat, pt(tl), pt(br), pt(bl))
                            total += abs(y[pr, pc] - 0.5 * (la + lb)) / sigma_b
                        else:
                            me = corners[(r, c)]
                            # horizontal and vertical neighbour of (r, c) inside the pixel
                            j = (r, pc + 1 if me in ("TL", "BL") else pc)
                            k = (pr + 1 if me in ("TL", "TR") else pr, c)
                            lt = _radiance(scene, theta_nat, P[r, c, s], Q[j], Q[k])
                            total += abs(y[pr, pc] - lt) / sigma_b
                U[r * (W + 1) + c, s] = total
    return U


def brute_terms(U, E0, obs, kind):
    E = U + E0
    n = E.shape[0]
    own = E[np.arange(n), obs]
    lse = np.array([np.logaddexp.reduce(-E[i]) for i in range(n)])
    if kind == "pl":
        return -own - lse
    if kind == "fit":
        return -U[np.arange(n), obs]
    raise AssertionError(kind)


@pytest.mark.parametrize("data_term", ["pixel", "triplet"])
@pytest.mark.parametrize("name", ["pl", "pls"])
def test_brute_force_pseudolikelihood(tiny, name, data_term):
    t = get(name, tiny, sigma_b=0.03, data_term=data_term)
    rng = np.random.default_rng(0)
    u = np.vstack([t.true_theta, rng.uniform(0.05, 1.0, (3, 3))])
    got = t.log_prob(u)
    n = tiny.lattice.n_nodes
    obs = tiny.observed_labels.reshape(n)
    E0 = tiny.range_prior.reshape(n, -1) if name == "pls" else np.zeros((n, tiny.n_labels))
    want = [brute_terms(brute_energies(tiny, B.get("ward").to_natural(x), 0.03, data_term),
                        E0, obs, "pl").sum() for x in u]
    np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-9)


def test_brute_force_fit_and_pml(tiny):
    n = tiny.lattice.n_nodes
    obs = tiny.observed_labels.reshape(n)
    x = np.array([0.3, 0.7, 0.5])
    U = brute_energies(tiny, B.get("ward").to_natural(x), 0.05)
    fit = get("fit", tiny, sigma_b=0.05).log_prob(x)[0]
    np.testing.assert_allclose(fit, brute_terms(U, 0, obs, "fit").sum(), rtol=1e-12)
    E0 = tiny.range_prior.reshape(n, -1)
    p0 = np.exp(-E0) / np.exp(-E0).sum(axis=1, keepdims=True)
    want = np.log((p0 * np.exp(-U)).sum(axis=1)).sum()
    got = get("pml", tiny, sigma_b=0.05).log_prob(x)[0]
    np.testing.assert_allclose(got, want, rtol=1e-11)
    got_flat = get("pml", tiny, sigma_b=0.05, prior="none").log_prob(x)[0]
    np.testing.assert_allclose(got_flat, np.log(np.exp(-U).mean(axis=1)).sum(), rtol=1e-11)


def test_pl2_pairwise_brute_force(tiny):
    """V^B (6.57 with 6.24) on range differences in label steps, by loops."""
    sp, ep = 1.5, 0.02
    t = get("pl2", tiny, sigma_b=0.05, smoothness_sigma=sp, smoothness_e=ep)
    H1, W1 = tiny.lattice.node_shape
    r = tiny.label_ranges
    obs = tiny.observed_labels
    V = np.zeros((H1 * W1, tiny.n_labels))
    for i in range(H1):
        for j in range(W1):
            step = np.median(np.abs(np.diff(r[i, j])))
            for s in range(tiny.n_labels):
                for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                    a, b = i + di, j + dj
                    if 0 <= a < H1 and 0 <= b < W1:
                        d = (r[i, j, s] - r[a, b, obs[a, b]]) / step
                        V[i * W1 + j, s] += -np.log((1 - ep) * np.exp(-abs(d) / sp) + ep)
    x = np.array([0.5, 0.5, 0.5])
    U = brute_energies(tiny, B.get("ward").to_natural(x), 0.05)
    want = brute_terms(U, V, obs.reshape(-1), "pl").sum()
    np.testing.assert_allclose(t.log_prob(x)[0], want, rtol=1e-11)
    # without smoothness and match cost PL2 is PL
    t0 = get("pl2", tiny, sigma_b=0.05, smoothness=False)
    np.testing.assert_allclose(t0.log_prob(x), get("pl", tiny, sigma_b=0.05).log_prob(x),
                               rtol=1e-13)


def test_zero_data_energy_at_truth_noise_free():
    s = make_scene(brdf="phong", theta=[0.5, 0.4, 8.0], shape=(6, 7), n_labels=5,
                   surface="jagged", seed=2)
    t = get("fit", s)
    assert abs(t.log_prob(t.true_theta)[0]) < 1e-9
    terms = get("pl", s).node_terms(t.true_theta)
    assert terms.shape == (1, s.lattice.n_nodes)
    # the triplet form does not agree with the renderer
    assert get("fit", s, data_term="triplet").log_prob(t.true_theta)[0] < -1.0


def test_uniform_beliefs_pl3_equals_pl(tiny):
    beliefs = np.full((*tiny.lattice.node_shape, tiny.n_labels), 1.0 / tiny.n_labels)
    x = np.random.default_rng(1).random((5, 3))
    a = get("pl3", tiny, beliefs=beliefs, temperature=2.0).log_prob(x)
    b = get("pl", tiny).log_prob(x)
    np.testing.assert_allclose(a, b, rtol=1e-12)
    # non-uniform beliefs: brute force of 6.60-6.61
    rng = np.random.default_rng(2)
    bl = rng.random(beliefs.shape)
    bl /= bl.sum(axis=2, keepdims=True)
    t = get("pl3", tiny, beliefs=bl, sigma_b=0.05)
    n = tiny.lattice.n_nodes
    U = brute_energies(tiny, B.get("ward").to_natural(x[0]), 0.05)
    want = brute_terms(U, -np.log(bl.reshape(n, -1)), tiny.observed_labels.reshape(-1), "pl")
    np.testing.assert_allclose(t.log_prob(x[0])[0], want.sum(), rtol=1e-11)


@pytest.mark.parametrize("name", ["pl", "pls", "fit", "pml"])
def test_partition_identity(tiny, name):
    t = get(name, tiny)
    x = np.random.default_rng(4).random((9, 3))
    full = t.log_prob(x)
    for kind in ("strided", "block"):
        for k in (1, 2, 3, 5, tiny.lattice.n_nodes):
            parts = t.partition(k, kind)
            assert len(parts) == k
            assert sum(p.cost for p in parts) == pytest.approx(1.0)
            np.testing.assert_allclose(sum(p.log_prob(x) for p in parts), full, rtol=1e-12,
                                       atol=1e-10)
            nodes = np.sort(np.concatenate([p.nodes for p in parts]))
            np.testing.assert_array_equal(nodes, np.arange(tiny.lattice.n_nodes))
    # the parts are the lattice's sub-lattices (5.67, 5.68) and touch only their own nodes
    for kind in ("strided", "block"):
        for p, ids in zip(t.partition(3, kind), tiny.lattice.partition(3, kind)):
            np.testing.assert_array_equal(p.nodes, ids)
            assert p._tables.n_nodes == len(ids)
            assert p.cost == pytest.approx(len(ids) / tiny.lattice.n_nodes)
    # nested partitions still add up
    sub = t.partition(2, "block")[1]
    np.testing.assert_allclose(sum(p.log_prob(x) for p in sub.partition(3, "strided")),
                               sub.log_prob(x), rtol=1e-12)


def test_softened_partition(tiny):
    t = get("pls", tiny)
    x = np.random.default_rng(5).random((4, 3))
    st = softened(t, 0.3)
    np.testing.assert_allclose(st.log_prob(x), 0.3 * t.log_prob(x), rtol=1e-14)
    np.testing.assert_allclose(sum(p.log_prob(x) for p in st.partition(3)), st.log_prob(x),
                               rtol=1e-12)
    assert all(p.cost < 1 for p in st.partition(3))


def test_bad_input(tiny):
    t = get("pl", tiny)
    out = t.log_prob([[0.5, 0.5, 1.2], [-0.1, 0.5, 0.5], [0.5, 0.5, 0.5]])
    assert out[0] == -np.inf and out[1] == -np.inf and np.isfinite(out[2])
    with pytest.raises(ValueError, match="NaN"):
        t.log_prob([[0.5, np.nan, 0.5]])
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        t.log_prob(np.zeros((2, 4)))
    with pytest.raises(ValueError, match="name must be one of"):
        get("nope", tiny)
    with pytest.raises(ValueError, match="data_term"):
        get("pl", tiny, data_term="quad")
    with pytest.raises(ValueError, match="sigma_b"):
        get("pl", tiny, sigma_b=-1.0)
    with pytest.raises(ValueError, match="sigma_b"):
        get("pl", tiny, sigma_b="big")
    with pytest.raises(ValueError, match="dtype"):
        get("pl", tiny, dtype="float16")
    with pytest.raises(ValueError, match=r"unknown option.*valid options: sigma_b"):
        get("pl", tiny, prior_weight=2.0)
    with pytest.raises(ValueError, match="Scene"):
        get("pls", np.zeros((3, 3)))
    with pytest.raises(ValueError, match="no beliefs"):
        get("pl3", tiny)
    with pytest.raises(ValueError, match="beliefs must have shape"):
        get("pl3", tiny, beliefs=np.ones((2, 2, 2)))
    with pytest.raises(ValueError, match="k must be"):
        t.partition(0)
    with pytest.raises(ValueError, match="kind"):
        t.partition(2, "random")
    with pytest.raises(ValueError, match="power"):
        softened(t, 0.0)
    with pytest.raises(ValueError, match="kind must be one of"):
        t.residuals([0.5, 0.5, 0.5], kind="square")
    no_prior = make_scene(brdf="ward", theta=[0.5, 0.5, 0.2], shape=(2, 2), n_labels=3, seed=0)
    no_prior = mrfpe.brdf.scene.Scene(image=no_prior.image, camera=no_prior.camera,
                                 light=no_prior.light, label_ranges=no_prior.label_ranges,
                                 observed_labels=no_prior.observed_labels)
    with pytest.raises(ValueError, match="range_prior"):
        get("pls", no_prior)
    zero = np.full((*tiny.lattice.node_shape, tiny.n_labels), 1.0 / tiny.n_labels)
    zero[0, 0] = 1.0 / (tiny.n_labels - 1)
    zero[0, 0, tiny.observed_labels[0, 0]] = 0.0
    with pytest.raises(ValueError, match="observed label"):
        get("pl3", tiny, beliefs=zero)


def test_never_nan_at_edges(tiny):
    """Bounds of the unit cube (alpha = 0, rho = 0, 1) give finite or -inf values, never NaN."""
    corners = grid_points([[0, 1]] * 3, 2)
    for name in ("pl", "pls", "fit", "pml"):
        v = get(name, tiny).log_prob(corners)
        assert not np.any(np.isnan(v))


def test_residuals(tiny):
    t = get("pls", tiny)
    x = np.array([0.4, 0.6, 0.3])
    ell = t.node_terms(x)[0]
    np.testing.assert_allclose(ell.sum(), t.log_prob(x)[0], rtol=1e-12)
    np.testing.assert_allclose(t.residuals(x), np.exp(-ell), rtol=1e-12)  # 7.10
    np.testing.assert_allclose(t.residuals(x, "one_minus"), 1 - np.exp(ell), rtol=1e-12)  # 7.11
    np.testing.assert_allclose((t.residuals(x, "sqrt") ** 2).sum(), -t.log_prob(x)[0],
                               rtol=1e-12)
    r = t.residuals(np.array([[0.4, 0.6, 0.3], [0.4, 0.6, 1.3]]))
    assert r.shape == (2, tiny.lattice.n_nodes) and np.all(np.isinf(r[1]))
    parts = t.partition(3)
    assert sum(p.residuals(x).shape[0] for p in parts) == tiny.lattice.n_nodes


def test_describe_and_api(tiny):
    t = get("pls", tiny, prior_weight=0.5)
    d = t.describe()
    json.dumps(d)
    assert d["name"] == "pls" and d["options"]["prior_weight"] == 0.5
    assert d["scene"]["shape"] == [3, 3] and d["scene"]["n_labels"] == 4
    assert t.param_names == ("rho_d", "rho_s", "alpha")
    np.testing.assert_array_equal(t.bounds, [[0, 1]] * 3)
    np.testing.assert_allclose(t.to_natural([1.0, 1.0, 1.0]), [1.0, 1.0, 0.5])
    np.testing.assert_allclose(t.to_natural(t.true_theta), tiny.true_theta)
    assert set(names()) >= {"pl", "pl2", "pl3", "pls", "fit", "pml", "potts", "potts_exact"}
    json.dumps(softened(t, 0.5).describe())
    x = np.array([0.2, 0.8, 0.6])
    np.testing.assert_allclose(get("pls", tiny, prior_weight=0.0).log_prob(x),
                               get("pl", tiny).log_prob(x), rtol=1e-13)


def test_batch_invariance(tiny):
    """A row's value does not depend on the batch it is evaluated in."""
    t = get("pls", tiny)
    x = np.random.default_rng(6).random((70, 3))
    whole = t.log_prob(x)
    single = np.array([t.log_prob(r)[0] for r in x[:9]])
    np.testing.assert_allclose(whole[:9], single, rtol=1e-13)
    np.testing.assert_allclose(t.log_prob(x[:33]), whole[:33], rtol=1e-13)


def test_thread_count_does_not_change_values(tiny, monkeypatch):
    """The per-call thread budget changes speed, never the numbers."""
    from mrfpe import threads

    t = get("pls", tiny)
    x = np.random.default_rng(7).random((70, 3))
    default = t.log_prob(x)
    monkeypatch.setattr(threads, "MIN_EVALS_PER_THREAD", 1)  # every call on all threads
    np.testing.assert_array_equal(t.log_prob(x), default)
    np.testing.assert_array_equal(t.log_prob(x[:3]), default[:3])


CASES = [
    ("ward", [0.7, 0.4, 0.45], "smooth"),
    ("ward", [0.3, 0.6, 0.1], "smooth"),
    ("phong", [0.5, 0.4, 0.3], "jagged"),
]


@pytest.mark.parametrize("brdf,u,surface", CASES)
def test_truth_beats_grid_noise_free(brdf, u, surface):
    """Pixel data term: the true parameters score above every point of a 12^3 grid."""
    model = B.get(brdf)
    s = make_scene(brdf=brdf, theta=model.to_natural(np.array(u)), shape=(20, 20), n_labels=10,
                   surface=surface, seed=1)
    grid = grid_points([[0, 1]] * 3, 12)
    for name in ("pls", "pl"):
        t = get(name, s)
        assert t.log_prob(np.array(u))[0] > t.log_prob(grid).max()


def test_done_when_line_small():
    s = make_scene(brdf="ward", theta=[0.7, 0.4, 0.45], shape=(30, 30), n_labels=20, seed=0)
    t = mrfpe.targets.get("pls", s)
    out = t.log_prob(np.random.default_rng(0).random((1000, 3)))
    assert out.shape == (1000,) and np.all(np.isfinite(out))


@pytest.mark.parametrize("brdf,u,surface", [CASES[1], CASES[2]])
def test_float32_accuracy(brdf, u, surface):
    """float32 kernels: log_prob within 2e-6 relative, same grid maximiser, same PMC weights."""
    model = B.get(brdf)
    s = make_scene(brdf=brdf, theta=model.to_natural(np.array(u)), shape=(30, 30), n_labels=20,
                   surface=surface, seed=2)
    grid = grid_points([[0, 1]] * 3, 12)
    x = np.vstack([grid, np.random.default_rng(0).random((200, 3)), np.array(u)])
    for name in ("pls", "pml"):
        a = get(name, s).log_prob(x)
        b = get(name, s, dtype="float32").log_prob(x)
        assert np.array_equal(np.isinf(a), np.isinf(b))
        ok = np.isfinite(a)
        np.testing.assert_allclose(b[ok], a[ok], rtol=2e-6)
        assert np.argmax(a) == np.argmax(b)
        # importance weights of a softened target (PMC's default power 0.02): total variation
        wa = np.exp(0.02 * (a[ok] - a[ok].max()))
        wb = np.exp(0.02 * (b[ok] - b[ok].max()))
        assert 0.5 * np.abs(wa / wa.sum() - wb / wb.sum()).sum() < 1e-4
    t32 = get("pls", s, dtype="float32")
    np.testing.assert_allclose(sum(p.log_prob(x[:20]) for p in t32.partition(3)),
                               t32.log_prob(x[:20]), rtol=1e-12)
    assert t32.log_prob(np.array(u)[None])[0] > t32.log_prob(grid).max()
