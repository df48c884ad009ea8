"""Simulating the depth labels of the BRDF MRF at given BRDF parameters (thesis 4.3, 4.22).

The joint
---------
For a scene (image ``y``, camera, light, the B candidate ranges of every
corner-vertex node) and BRDF parameters ``theta`` the label field is the Gibbs
distribution (4.3 with T = 1, 4.22)

    ``p(x | theta) = exp(-U(x; theta)) / Z(theta)``,
    ``U(x; theta) = sum_t D_t(x; theta) + sum_i E0_i(x_i)``,

with one data term ``D_t`` per image observation, counted once, and a unary
energy ``E0`` per node. :func:`label_energy` computes ``U`` this way, directly:
it renders every observation at the labelling, without the pseudolikelihood's
tables or kernels.

* ``data_term="pixel"`` (the targets' default, :mod:`mrfpe.brdf.targets.energy`): one
  term per pixel ``p``, ``D_p = |y_p - (L(T_2p) + L(T_2p+1)) / 2| / sigma_b``
  (4.12 with the renderer's two triangles per pixel), a function of the pixel's
  four corner labels.
* ``data_term="triplet"`` (the thesis's literal form, 4.12/4.20 with 4.27): one
  term per triplet clique ``c = (i, j, k)``, ``D_c = |y_p(c) - L(i, j, k)| /
  sigma_b``, a function of its three labels.
* ``prior``: ``"none"`` (E0 = 0, the ``pl`` target), ``"range"`` (``E0 = w psi_i``,
  the range potentials 7.4 of ``pls``, 7.5-7.7) or ``"beliefs"`` (``E0 = -T log
  b_i``, the belief potential 6.60 of ``pl3``, 6.61-6.62).

Question: are the pseudolikelihood's conditionals those of this joint?
------------------------------------------------------------------------
The full conditional of node ``i`` in the joint is ``p(x_i = s | x_-i) ∝
exp(-E_i(s))`` with ``E_i(s) = E0_i(s) + sum_{t touching i} D_t(x with x_i = s)``:
every term that contains node ``i`` enters with weight 1.

* Pixel form: **consistent**. The targets' node energy 4.23 for node ``i`` sums
  ``D_p`` over exactly the (up to four) pixels that have ``i`` as a corner, each
  with weight 1 (the variable and fixed triangles of
  :mod:`mrfpe.brdf.targets.energy`), so ``U(x^s) - U(x^t) = E_i(s) - E_i(t)``: the
  ``pl``/``pls``/``pl3`` conditionals are the full conditionals of the joint above
  (the unary terms are singleton cliques; they enter their own node once).
* Triplet form: **not consistent**. 4.27 sums, for node ``i``, only the four
  cliques *centred* on ``i``; but clique ``(i, j, k)`` also depends on ``x_j`` and
  ``x_k``, whose node energies omit it. No joint has these conditionals (they
  would need ``D_c`` to depend on the centre only). This module samples the
  joint ``U = sum_c D_c`` over all ``4HW`` cliques, whose exact full conditional
  at node ``i`` sums the (up to 12) cliques containing ``i``: every clique of
  every pixel touching ``i`` except the one centred on that pixel's opposite
  corner. The triplet ``pl`` is then not the pseudolikelihood of this (or any) field.
* ``pl2`` (6.57-6.59) is not offered: its smoothness term is a pairwise clique
  whose value is measured in each node's own label spacing, so it is symmetric
  (and the conditionals consistent) only when neighbouring nodes share a spacing.

Sampling
--------
:func:`simulate_labels` runs Gibbs sweeps (Geman & Geman 1984) over Besag's four
codings (:meth:`mrfpe.brdf.lattice.Lattice.codings`). Every data term lies inside one
pixel and every pixel has exactly one node of each coding, so the nodes of a
coding are conditionally independent given the rest and one coding is updated
at once: for each label ``s`` the whole coding is set to ``s``, every term is
rendered once (one batch of ``B`` labellings), and node ``i``'s energy ``E_i(s)``
is the sum of the terms touching it (a fixed node-term incidence matrix). Terms
that do not touch ``i`` do not depend on ``s`` and cancel in the normalisation. A
label is drawn per node with the Gumbel-max trick from ``-E_i``; every random
number comes from one ``numpy.random.Generator`` seeded by ``seed``.

This needs each term ``B`` times per coding, i.e. about ``8 H W B`` triangle
radiances per sweep for the pixel form. A chain at one ``theta`` meets the same
(triangle, vertex labels) over and over, so radiances are memoised
(:class:`mrfpe.brdf.label_render.RadianceMemo`, the same numbers as rendering
them afresh) and after the first sweeps a sweep is mostly look-ups. Measured on
one core of a shared host (Ward, pixel form): with B = 10, 2.5-2.7 ms per sweep
for a 10 x 10 image, 11-12 ms for 20 x 20 and 28-43 ms for 40 x 40 rendering
every triangle; a 100 x 100 image with B = 20 took 0.47 s per sweep rendering
every triangle and 0.07-0.13 s with the memo after 40-80 sweeps. The triplet
form renders twice as many triangles (four cliques per pixel).

Default chain length
--------------------
The integrated autocorrelation time ``tau`` (``emcee.autocorr.integrated_time``
on 1500 consecutive sweeps after 200 sweeps of burn-in, started at the observed
labelling) of the total energy ``U`` and of the mean label index was measured on
``make_scene`` scenes with 10 labels and noise 0.01, pixel form, no prior,
``sigma_b="auto"``, at the scene's parameters (unit-cube 0.5, 0.4, 0.3):

=========================  ========  =================
scene (make_scene seed)    tau of U  tau of mean label
=========================  ========  =================
Ward, smooth, 20^2 (2)     2.6       6.9
Phong, jagged, 20^2 (2)    2.2       6.6
Ward, smooth, 40^2 (2)     2.2       3.2
Phong, jagged, 40^2 (2)    3.4       12.0
Ward, smooth, 40^2 (5)     5.6       10.5
Phong, jagged, 40^2 (5)    2.5       5.7
=========================  ========  =================

The mean label (a drift of the whole surface along the rays) is the slow
statistic; 56-69 % of the nodes change label in each sweep. From a random start
``U`` reached its stationary level within about 10 sweeps on five of these
scenes but was still above it after 60 sweeps on the Ward 40 x 40 (seed 5): start
from the observed labelling (the default) or burn in longer. The defaults
are ten times the largest ``tau`` of burn-in, :data:`DEFAULT_SWEEPS` = 120, and
one ``tau`` between draws, :data:`DEFAULT_THIN` = 12 (the rule of
:func:`mrfpe.models.draws.simulate_draws`). Chains at other parameters,
priors or scene sizes may mix more slowly;
:func:`mrfpe.models.mixing.autocorrelation_time` measures them.
"""

from __future__ import annotations

from dataclasses import dataclass
from dataclasses import field as _slot
from typing import Any

import numpy as np
import scipy.sparse as sp

from mrfpe.brdf.label_render import BATCH_TRIANGLES, data_terms, memo_at, memo_for, term_energies
from mrfpe.brdf.targets import reflectance
from mrfpe.brdf.targets.brdf_target import auto_sigma_b
from mrfpe.brdf.targets.energy import DATA_TERMS
from mrfpe.budget import check_memory
from mrfpe.validation import check_bool, check_choice, check_positive_int, check_range, check_seed

__all__ = ["DEFAULT_SWEEPS", "DEFAULT_THIN", "PRIORS", "LabelField", "conditional_energies",
           "label_energy", "label_field", "simulate_labels"]

#: Unary energies the joint can carry (module docstring).
PRIORS = ("none", "range", "beliefs")
#: Default burn-in sweeps and sweeps between draws (measured, module docstring).
DEFAULT_SWEEPS = 120
DEFAULT_THIN = 12


@dataclass(frozen=True, eq=False)
class LabelField:
    """The label field ``p(x | theta) ∝ exp(-U(x; theta))`` of one scene (module docstring).

    Everything here is theta-independent and built once by :func:`label_field`.

    Attributes
    ----------
    scene : mrfpe.brdf.scene.Scene
    data_term : "pixel" | "triplet"
    sigma_b : float
        Data-energy scale of 4.12.
    prior : "none" | "range" | "beliefs"
    unary : (n_nodes, B) float64
        ``E0``; ``+inf`` forbids a label.
    points : (n_nodes, B, 3)
        3-D point of every (node, label).
    tri : (n_tri, 3) int64
        Vertices of the rendered triangles, in the order the targets pass them.
    per_term : int
        Triangles per data term (2 for pixels, 1 for cliques); term ``t`` owns
        triangles ``per_term * t ...``.
    y, w : (n_terms,)
        Each term's intensity and the weight of its triangles' radiance sum.
    incidence : scipy.sparse.csr_matrix (n_nodes, n_terms)
        1 where the term depends on the node's label.
    memo : dict
        Working memory of the simulator (:class:`mrfpe.brdf.label_render.RadianceMemo`).
    """

    scene: Any
    data_term: str
    sigma_b: float
    prior: str
    unary: np.ndarray
    points: np.ndarray
    tri: np.ndarray
    per_term: int
    y: np.ndarray
    w: np.ndarray
    incidence: Any
    memo: dict = _slot(default_factory=dict, repr=False)

    @property
    def n_nodes(self) -> int:
        return int(self.unary.shape[0])

    @property
    def n_labels(self) -> int:
        return int(self.unary.shape[1])

    @property
    def node_shape(self) -> tuple[int, int]:
        return self.scene.lattice.node_shape


def _unary(scene: Any, prior: str, prior_weight: float, temperature: float) -> np.ndarray:
    n, B = scene.lattice.n_nodes, scene.n_labels
    if prior == "none":
        return np.zeros((n, B))
    if prior == "range":
        if scene.range_prior is None:
            raise ValueError("prior='range' needs the scene's range_prior (7.4); it has none")
        return prior_weight * np.asarray(scene.range_prior, dtype=np.float64).reshape(n, B)
    if scene.beliefs is None:
        raise ValueError("prior='beliefs' needs the scene's beliefs (6.60); this scene has none")
    with np.errstate(divide="ignore"):
        return -temperature * np.log(np.asarray(scene.beliefs, dtype=np.float64).reshape(n, B))


def label_field(scene: Any, *, data_term: str = "pixel", sigma_b: float | str = "auto",
                prior: str = "none", prior_weight: float = 1.0,
                temperature: float = 1.0) -> LabelField:
    """The theta-independent parts of the label field of ``scene`` (checked arguments).

    Parameters
    ----------
    scene : mrfpe.brdf.scene.Scene
    data_term : "pixel" | "triplet"
        As the targets' option of that name (:mod:`mrfpe.brdf.targets.energy`).
    sigma_b : float > 0 or "auto"
        As the targets' option (``"auto"``:
        :func:`mrfpe.brdf.targets.pseudolikelihood.auto_sigma_b`).
    prior : "none" | "range" | "beliefs"
        The unary energy: none (``pl``), the range prior (``pls``) or the beliefs (``pl3``).
    prior_weight : float >= 0
        Multiplies the range potentials (as ``pls``'s option).
    temperature : float > 0
        ``T`` of the belief potential 6.60 (as ``pl3``'s option).
    """
    from mrfpe.brdf.scene import Scene

    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be an mrfpe.brdf.scene.Scene; got {type(scene).__name__}")
    check_choice("data_term", data_term, DATA_TERMS)
    check_choice("prior", prior, PRIORS)
    if isinstance(sigma_b, str) and sigma_b == "auto":
        sigma = auto_sigma_b(scene)
    else:
        sigma = check_range("sigma_b", sigma_b, 0.0, np.inf, low_open=True, high_open=True)
    weight = check_range("prior_weight", prior_weight, 0.0, np.inf, high_open=True)
    temp = check_range("temperature", temperature, 0.0, np.inf, low_open=True, high_open=True)
    unary = _unary(scene, prior, weight, temp)
    if np.any(np.isnan(unary)) or np.any(unary == -np.inf):
        raise ValueError(f"prior={prior!r}: the scene's unary energies contain NaN or -inf")
    if (dead := np.flatnonzero(np.all(np.isinf(unary), axis=1))).size:
        raise ValueError(f"prior={prior!r} forbids every label of node {dead[0]} (zero beliefs)")
    lat = scene.lattice
    img = scene.image.reshape(-1)
    if data_term == "pixel":
        tri, per, y, w = lat.triangles, 2, img, np.full(lat.n_pixels, 0.5)
        term_nodes = lat.pixel_nodes
    else:
        tri, per, y, w = lat.cliques, 1, img[lat.clique_pixel], np.ones(4 * lat.n_pixels)
        term_nodes = lat.cliques
    n_terms = term_nodes.shape[0]
    rows = term_nodes.reshape(-1)
    cols = np.repeat(np.arange(n_terms), term_nodes.shape[1])
    inc = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(lat.n_nodes, n_terms))
    points = np.asarray(scene.label_points(), dtype=np.float64).reshape(lat.n_nodes, -1, 3)
    return LabelField(scene, data_term, float(sigma), prior, np.ascontiguousarray(unary),
                      points, np.asarray(tri, dtype=np.int64), per, np.asarray(y, float),
                      w, inc)


def _coefficients(field: LabelField, theta: Any) -> np.ndarray:
    """Separable radiance coefficients (1, 5) of one unit-cube parameter vector."""
    model = field.scene.model
    th = np.asarray(theta, dtype=np.float64)
    if th.shape != (model.d,) or not np.all(np.isfinite(th)):
        raise ValueError(f"theta must be {model.d} finite numbers {model.param_names} in the "
                         f"unit cube; got {np.asarray(theta).tolist()}")
    if np.any(th < 0) or np.any(th > 1):
        raise ValueError(f"theta must lie in the unit cube (the targets' sampling space, "
                         f"7.1-7.2); got {th.tolist()}")
    coef = reflectance.coefficients(model, model.to_natural(th[None]))
    if not np.all(np.isfinite(coef)):
        raise ValueError(f"theta {th.tolist()} gives non-finite radiance coefficients")
    return coef


def _as_labellings(field: LabelField, labels: Any, name: str) -> tuple[np.ndarray, bool]:
    """Labellings as (M, n_nodes) int64 and whether a single one was given."""
    arr = np.asarray(labels)
    n, shape = field.n_nodes, field.node_shape
    if arr.shape in ((n,), shape):
        single, arr = True, arr.reshape(1, n)
    elif arr.ndim in (2, 3) and arr.shape[1:] in ((n,), shape):
        single, arr = False, arr.reshape(arr.shape[0], n)
    else:
        raise ValueError(f"{name} must have shape ({n},), {shape}, (M, {n}) or (M, *{shape}); "
                         f"got {arr.shape}")
    if arr.dtype.kind not in "iu":
        if arr.dtype.kind != "f" or not np.all(arr == np.round(arr)):
            raise ValueError(f"{name} must hold integer label indices; got dtype {arr.dtype}")
    arr = arr.astype(np.int64)
    if arr.size and (arr.min() < 0 or arr.max() >= field.n_labels):
        raise ValueError(f"{name} must lie in [0, {field.n_labels - 1}]; got range "
                         f"[{arr.min()}, {arr.max()}]")
    return arr, single


def _field(scene: Any, options: dict[str, Any]) -> LabelField:
    """``scene`` if it is a LabelField (then no options), else its :func:`label_field`."""
    if isinstance(scene, LabelField) and options:
        raise ValueError(f"options {sorted(options)} cannot be given with a LabelField")
    return scene if isinstance(scene, LabelField) else label_field(scene, **options)


def _energies(field: LabelField, coef: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``U`` (N, M) of labellings ``x`` (M, n_nodes) at coefficient rows ``coef`` (N, 5)."""
    data = term_energies(field, coef, x, memo_at(field, coef)).sum(axis=2)
    return data + _unary_energies(field, x)


def _unary_energies(field: LabelField, x: np.ndarray) -> np.ndarray:
    """``sum_i E0_i(x_i)`` (M,) of labellings ``x`` (M, n_nodes)."""
    return field.unary[np.arange(field.n_nodes)[None, :], x].sum(axis=1)


def label_energy(scene: Any, theta: Any, labels: Any, **options: Any) -> np.ndarray | float:
    """``U(x; theta)``, the energy of whole labellings (4.3, 4.12/4.20; module docstring).

    Computed directly: every data term (pixel or clique) rendered once at the
    labelling and summed, plus the unary energies of the labels (7.4 or 6.60);
    ``-U`` is ``log p(x | theta)`` up to ``-log Z(theta)``.

    Parameters
    ----------
    scene : mrfpe.brdf.scene.Scene or LabelField
    theta : (d,)
        BRDF parameters in the unit cube (the targets' sampling space, 7.1-7.2).
    labels : (H+1, W+1) or (n_nodes,) ints, or a batch (M, ...) of them
    **options
        ``data_term``, ``sigma_b``, ``prior``, ``prior_weight``, ``temperature`` of
        :func:`label_field` (for a Scene).

    Returns
    -------
    float for one labelling, (M,) for a batch; ``inf`` where a label is forbidden.
    """
    field = _field(scene, options)
    x, single = _as_labellings(field, labels, "labels")
    coef = _coefficients(field, theta)
    check_memory(8.0 * x.shape[0] * (field.tri.shape[0] + field.n_nodes),
                 f"label_energy of {x.shape[0]} labellings", "pass fewer at a time")
    out = _energies(field, coef, x)[0]
    return float(out[0]) if single else out


def conditional_energies(field: LabelField, coef: np.ndarray, x: np.ndarray,
                         nodes: np.ndarray, memo: Any = None) -> np.ndarray:
    """``E_i(s)`` (B, len(nodes)) of nodes no two of which share a term, given ``x``.

    Up to a per-node constant (the terms not touching ``i``): each label ``s`` sets
    every node of ``nodes`` to ``s`` at once and renders every term once (radiances
    from ``memo``, a :class:`~mrfpe.brdf.label_render.RadianceMemo` at ``coef``, if given).
    """
    B = field.n_labels
    if memo is not None:
        D = data_terms(field, memo.coding_radiance(field, x, nodes)[None])[0]  # (B, n_terms)
    else:
        X = np.repeat(x[None, :], B, axis=0)
        X[:, nodes] = np.arange(B)[:, None]
        D = term_energies(field, coef, X)[0]
    E = np.asarray(field.incidence[nodes] @ D.T).T  # (B, len(nodes))
    return E + field.unary[nodes].T


def _start(field: LabelField, init: Any, rng: np.random.Generator) -> np.ndarray:
    if isinstance(init, str):
        check_choice("init", init, ("observed", "random"))
        if init == "observed":
            return field.scene.observed_labels.reshape(-1).astype(np.int64).copy()
        allowed = np.isfinite(field.unary)  # uniform over each node's allowed labels
        g = np.where(allowed, rng.gumbel(size=allowed.shape), -np.inf)
        return np.argmax(g, axis=1).astype(np.int64)
    x, single = _as_labellings(field, init, "init")
    if not single:
        raise ValueError(f"init must be 'observed', 'random' or one labelling; got "
                         f"{x.shape[0]} labellings")
    return x[0].copy()


def simulate_labels(scene: Any, theta: Any, n: int = 1, *, n_sweeps: int = DEFAULT_SWEEPS,
                    thin: int = DEFAULT_THIN, seed: int | None = None,
                    init: Any = "observed", progress: bool = False, memoise: bool = True,
                    **options: Any) -> np.ndarray:
    """Draw ``n`` labellings from ``p(x | theta) ∝ exp(-U(x; theta))`` by Gibbs sweeps.

    One sweep updates Besag's four codings in turn, each coding's nodes at once
    from their exact full conditionals (module docstring). Draw ``k`` is the state
    after ``n_sweeps + k * thin`` sweeps of one chain.

    Parameters
    ----------
    scene : mrfpe.brdf.scene.Scene or LabelField
    theta : (d,)
        BRDF parameters in the unit cube (the targets' sampling space, 7.1-7.2).
    n : int >= 1
    n_sweeps : int >= 0
        Burn-in sweeps (default :data:`DEFAULT_SWEEPS`, chosen from the measured
        autocorrelation times in the module docstring).
    thin : int >= 1
        Sweeps between successive draws (default :data:`DEFAULT_THIN`).
    seed : int or None
        Every random number derives from ``numpy.random.default_rng(seed)``.
    init : "observed", "random" or one labelling ((H+1, W+1) or (n_nodes,) ints)
        The start: the scene's observed labels, labels uniform over each node's
        allowed ones, or the labelling given.
    progress : bool
        Show a tqdm bar over the sweeps.
    memoise : bool
        Keep radiances in a :class:`~mrfpe.brdf.label_render.RadianceMemo` (if it fits);
        ``False`` renders every term at every update. The same chain either way.
    **options
        ``data_term``, ``sigma_b``, ``prior``, ``prior_weight``, ``temperature``
        (:func:`label_field`), for a Scene.

    Returns
    -------
    (n, H+1, W+1) int64
        Label indices, shaped as ``scene.observed_labels``.
    """
    field = _field(scene, options)
    n = check_positive_int("n", n)
    n_sweeps = check_positive_int("n_sweeps", n_sweeps, minimum=0)
    thin = check_positive_int("thin", thin)
    check_bool("progress", progress)
    check_bool("memoise", memoise)
    rng = np.random.default_rng(check_seed(seed))
    coef = _coefficients(field, theta)
    B, n_nodes = field.n_labels, field.n_nodes
    check_memory(8.0 * (n * n_nodes + 3 * B * (n_nodes + field.tri.shape[0]))
                 + 1024.0 * BATCH_TRIANGLES,
                 f"simulating {n} labellings of a {field.scene.shape[0]}x"
                 f"{field.scene.shape[1]} scene with {B} labels", "draw fewer at a time")
    x = _start(field, init, rng)
    memo = memo_for(field, coef) if memoise else None
    codings = field.scene.lattice.codings()
    out = np.empty((n, n_nodes), dtype=np.int64)
    total = n_sweeps + thin * (n - 1)
    if n_sweeps == 0:
        out[0] = x
    from tqdm.auto import tqdm

    for s in tqdm(range(1, total + 1), disable=not progress, leave=False,
                  desc="label sweeps", unit="sweep"):
        for nodes in codings:
            logits = -conditional_energies(field, coef, x, nodes, memo)
            # Gumbel-max: argmax(logit + Gumbel) is a draw from softmax(logit)
            x[nodes] = np.argmax(logits + rng.gumbel(size=logits.shape), axis=0)
        if s >= n_sweeps and (s - n_sweeps) % thin == 0:
            out[(s - n_sweeps) // thin] = x
    return out.reshape(n, *field.node_shape)
