"""Pseudolikelihood targets over BRDF parameters (thesis 4.23-4.24, 5.64-5.68, 6.54-6.62, 7.5-7.10).

Every target here is a sum over lattice nodes ``i`` of a per-node term built
from the node's energies at each of its B labels,

    ``E_i(s) = U^A_i(s; theta) + E0_i(s)``,

with ``U^A`` the BRDF data energy (:mod:`mrfpe.brdf.targets.energy`, 4.12/4.20/4.27
or the renderer-consistent pixel form) and ``E0`` a theta-independent unary
energy that distinguishes the variants:

=====  ===========================================  ==================================
name   E0                                           per-node term
=====  ===========================================  ==================================
pl     0                                            ``log p(x_i | x_N_i)`` (4.23-4.24, 5.64-5.66)
pl2    ``V^B + U^C`` (6.57, 6.58 with 6.23-6.24)    ``log p(x_i | x_N_i)`` (6.59)
pl3    ``U^D = -T log b`` (6.60)                    ``log p(x_i | x_N_i)`` (6.61-6.62)
pls    ``U^R = psi_i`` range prior (7.4, 7.6)       ``log p(x_i | x_N_i)`` (7.5-7.7)
fit    0                                            ``-U^A_i(x_i)``
pml    prior (range, beliefs or none)               ``log sum_s p0_i(s) exp(-U^A_i(s))``
=====  ===========================================  ==================================

with ``log p(x_i | x_N_i) = -E_i(x_i) - log sum_s exp(-E_i(s))``. ``fit`` is the
log conditional likelihood of the image given the observed labels (each pixel
counted once per corner node); ``pml`` marginalises each node's label under the
normalised prior ``p0_i`` (uniform without one) -- a composite marginal
likelihood. Both are beyond the thesis; they use the same energies, so a
study can measure what the pseudolikelihood's reward for making the
alternative labels fit badly costs.

Targets sample the unit cube (7.1-7.2); ``to_natural`` maps to BRDF units.
All theta-independent geometry is precomputed at construction; ``log_prob``
runs one fused numba kernel over a batch of parameter vectors.

The shared machinery (construction, kernel call, residuals, ``partition``,
``sigma_b``'s default) is :class:`mrfpe.brdf.targets.brdf_target.BRDFTarget`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.brdf.targets.brdf_target import COMMON_OPTIONS, BRDFTarget, auto_sigma_b
from mrfpe.brdf.targets.residuals import RESIDUAL_KINDS
from mrfpe.targets.options import Option, bool_check, choice_check, number_check, optional
from mrfpe.validation import check_beliefs

__all__ = [
    "PL",
    "PL2",
    "PL3",
    "PLS",
    "RESIDUAL_KINDS",
    "BRDFTarget",
    "CompositeMarginalLikelihood",
    "ImageFit",
    "auto_sigma_b",
]


_positive = number_check(0.0, np.inf, low_open=True)
_unit_open = number_check(0.0, 1.0, high_open=True)


def _array(name: str, value: Any) -> np.ndarray:
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an array of numbers; got {type(value).__name__}") \
            from None


def _robust(x: np.ndarray, sigma: float, e: float) -> np.ndarray:
    """Truncated robust potential ``-ln((1-e) exp(-|x|/sigma) + e)`` (6.23, 6.24)."""
    return -np.log((1.0 - e) * np.exp(-np.abs(x) / sigma) + e)


class PL(BRDFTarget):
    """Pseudolikelihood of the BRDF MRF, thesis 4.23-4.24 / 5.64-5.66 (no unary energy)."""

    calibrated = False

    name = "pl"


class PLS(BRDFTarget):
    """Synthetic-data pseudolikelihood ``PL_s`` with the range prior ``U^R`` (7.3-7.7).

    Options
    -------
    prior_weight : float, default 1
        Multiplies the scene's range potentials ``psi_i(x_i, z_i) = |z_i - r_i(x_i)|/sigma``
        (7.4, stored as ``scene.range_prior``); 1 is the thesis's PL_s. A weight
        ``w`` is the same as a prior scale ``sigma / w`` (synthetic scenes use
        ``sigma = B/5`` label steps, ``make_scene(prior_sigma=...)``); 0 gives ``pl``.
    """

    calibrated = False

    name = "pls"

    option_specs = (*COMMON_OPTIONS,
                    Option("prior_weight", "float >= 0", 1.0, number_check(0.0),
                           "multiplies the range potentials psi_i of 7.4 (1: PL_s)"))

    def _check_options(self, scene: Any, options: dict) -> dict:
        if scene.range_prior is None:
            raise ValueError("scene has no range_prior; pls (7.5-7.7) needs the range "
                             "potentials psi_i of 7.4 (mrfpe.brdf.synthetic.make_scene sets them)")
        return {"prior_weight": options["prior_weight"]}

    def _unary(self, scene):
        n = scene.lattice.n_nodes
        u = self.options["prior_weight"] * np.asarray(scene.range_prior).reshape(n, -1)
        return u, np.zeros(n)


class PL3(BRDFTarget):
    """Pseudolikelihood ``PL_3`` with the stereo belief potential ``U^D`` (6.60-6.62).

    ``U^D_i(x) = -T log(b_i(x) / k1)``; ``k1`` cancels in 6.61 and is taken as 1.
    With uniform beliefs ``U^D`` is constant per node and PL3 equals :class:`PL`.
    A zero belief forbids its label (infinite energy).

    Options
    -------
    beliefs : (H+1, W+1, B) array, optional
        Overrides ``scene.beliefs``; normalised per node.
    temperature : float, default 1
        ``T`` of 6.60.
    """

    calibrated = False

    name = "pl3"

    option_specs = (*COMMON_OPTIONS,
                    Option("beliefs", "(H+1, W+1, B) array | None", None, optional(_array),
                           "per-node label beliefs b_i (default: scene.beliefs)"),
                    Option("temperature", "float > 0", 1.0, _positive, "T of 6.60"))

    def _check_options(self, scene: Any, options: dict) -> dict:
        beliefs, T = options["beliefs"], options["temperature"]
        shape = (*scene.lattice.node_shape, scene.n_labels)
        if beliefs is None:
            if scene.beliefs is None:
                raise ValueError("scene has no beliefs; pl3 (6.60-6.62) needs per-node label "
                                 "beliefs (pass beliefs=... or use a stereo scene)")
            b = np.asarray(scene.beliefs, dtype=np.float64)
            source = "scene"
        else:
            b = check_beliefs(beliefs, shape)
            source = "option"
        self._beliefs = b
        return {"temperature": T, "beliefs": source}

    def _unary(self, scene):
        n = scene.lattice.n_nodes
        b = self._beliefs.reshape(n, -1)
        with np.errstate(divide="ignore"):
            u = -self.options["temperature"] * np.log(b)
        return u, np.zeros(n)


class PL2(BRDFTarget):
    """Pseudolikelihood ``PL_2`` with pairwise smoothness ``V^B`` and match energy ``U^C`` (6.59).

    ``V^B_i(s) = sum_{t in N_i} psi_p(d_i(s), d_t(x_t))`` over the node's four
    lattice neighbours (6.57: every pairwise term of the node, even though this
    counts each pair twice over the lattice) with the robust potential
    ``psi_p(d, d') = -ln((1 - e_p) exp(-|d - d'| / sigma_p) + e_p)`` (6.24).
    ``d`` is measured in label steps: by default the node's *range* divided by
    its label spacing (``pairwise_on="range"``), which equals the thesis's
    disparity difference for a label set of shared disparities and stays
    meaningful when each node's labels sit about its own range (synthetic
    scenes); ``pairwise_on="label"`` uses the label indices literally.

    ``U^C_i(s) = psi_d(F_i(s))`` (6.58, 6.23) from a stereo match cost
    ``F = 1 - match`` in [0, 1] (6.5), taken from the ``match_cost`` option or
    a ``scene.match_cost`` attribute; without one the term is omitted (as a
    synthetic scene has no stereo match), which ``describe()`` records.

    Options
    -------
    smoothness : bool, default True
        Include ``V^B`` (6.59's text: omit it for surfaces not expected to be smooth).
    smoothness_sigma, smoothness_e : float, default 1.0, 0.01
        ``sigma_p`` (label steps) and ``e_p`` of 6.24 (the thesis's Fig. 6.3 values).
    pairwise_on : "range" | "label"
    match_cost : (H+1, W+1, B) array, optional
    match_sigma, match_e : float, default 1.0, 0.01
        ``sigma_d`` and ``e_d`` of 6.23.
    """

    calibrated = False

    name = "pl2"

    option_specs = (
        *COMMON_OPTIONS,
        Option("smoothness", "bool", True, bool_check, "include V^B (6.57)"),
        Option("smoothness_sigma", "float > 0", 1.0, _positive, "sigma_p of 6.24, label steps"),
        Option("smoothness_e", "float in [0, 1)", 0.01, _unit_open, "e_p of 6.24"),
        Option("pairwise_on", "'range' | 'label'", "range", choice_check("range", "label"),
               "what d of 6.24 measures: the node's range or the label index"),
        Option("match_cost", "(H+1, W+1, B) array | None", None, optional(_array),
               "stereo match cost F of 6.5 (default: scene.match_cost, else omitted)"),
        Option("match_sigma", "float > 0", 1.0, _positive, "sigma_d of 6.23"),
        Option("match_e", "float in [0, 1)", 0.01, _unit_open, "e_d of 6.23"),
    )

    def _check_options(self, scene: Any, options: dict) -> dict:
        o = options
        smooth, sp, ep, on = (o["smoothness"], o["smoothness_sigma"], o["smoothness_e"],
                              o["pairwise_on"])
        mc, sd, ed = o["match_cost"], o["match_sigma"], o["match_e"]
        shape = (*scene.lattice.node_shape, scene.n_labels)
        source = None
        if mc is None and getattr(scene, "match_cost", None) is not None:
            mc, source = scene.match_cost, "scene"
        elif mc is not None:
            source = "option"
        if mc is not None:
            mc = np.asarray(mc, dtype=np.float64)
            if mc.shape != shape or not np.all(np.isfinite(mc)):
                raise ValueError(f"match_cost must be a finite array of shape {shape}; "
                                 f"got shape {mc.shape}")
        self._match = mc
        return {"smoothness": smooth, "smoothness_sigma": sp, "smoothness_e": ep,
                "pairwise_on": on, "match_cost": source, "match_sigma": sd, "match_e": ed}

    def _unary(self, scene):
        o = self.options
        H1, W1 = scene.lattice.node_shape
        B = scene.n_labels
        u = np.zeros((H1, W1, B))
        if o["smoothness"]:
            if o["pairwise_on"] == "range":
                val = np.asarray(scene.label_ranges, dtype=np.float64)  # world units
                step = (np.median(np.abs(np.diff(val, axis=2)), axis=2) if B > 1
                        else np.ones((H1, W1)))
                step = np.where(step > 0, step, 1.0)  # the node's label spacing
            else:
                val = np.broadcast_to(np.arange(B, dtype=np.float64), (H1, W1, B))
                step = np.ones((H1, W1))
            obs = scene.observed_labels
            val_obs = np.take_along_axis(val, obs[..., None], axis=2)[..., 0]
            for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                # node (r, c) in `me`, its neighbour (r + dr, c + dc) in `nb`, where it exists
                me = (slice(max(0, -dr), H1 - max(0, dr)), slice(max(0, -dc), W1 - max(0, dc)))
                nb = (slice(max(0, dr), H1 - max(0, -dr)), slice(max(0, dc), W1 - max(0, -dc)))
                diff = (val[me] - val_obs[nb][..., None]) / step[me][..., None]
                u[me] += _robust(diff, o["smoothness_sigma"], o["smoothness_e"])
        if self._match is not None:
            u += _robust(self._match, o["match_sigma"], o["match_e"])
        n = H1 * W1
        return u.reshape(n, B), np.zeros(n)


class ImageFit(BRDFTarget):
    """``fit``: ``-sum_i U^A_i(x_i)``, the image's log conditional likelihood given the labels.

    Beyond the thesis. Unary energies at the observed labels would only add a
    theta-independent constant and are left out. Each pixel enters once per
    corner node (4 times in the interior) with the pixel data term.
    """

    name = "fit"
    _a, _b = 1.0, 0.0


class CompositeMarginalLikelihood(BRDFTarget):
    """``pml``: ``sum_i log sum_s p0_i(s) exp(-U^A_i(s))`` (beyond the thesis).

    Each node's label is marginalised under the normalised prior
    ``p0_i(s) = exp(-E0_i(s)) / sum_s' exp(-E0_i(s'))`` with ``E0`` the range
    prior (7.4), the belief potential (6.60) or zero (uniform over the B labels).

    Options
    -------
    prior : "auto" | "range" | "beliefs" | "none"
        "auto" uses the scene's range prior, else its beliefs, else none.
    """

    calibrated = False

    name = "pml"
    _a, _b = 0.0, 1.0

    option_specs = (*COMMON_OPTIONS,
                    Option("prior", "'auto' | 'range' | 'beliefs' | 'none'", "auto",
                           choice_check("auto", "range", "beliefs", "none"),
                           "the node prior p0 the label is marginalised under"))

    def _check_options(self, scene: Any, options: dict) -> dict:
        prior = options["prior"]
        if prior == "auto":
            prior = ("range" if scene.range_prior is not None
                     else "beliefs" if scene.beliefs is not None else "none")
        if prior == "range" and scene.range_prior is None:
            raise ValueError("prior='range' but the scene has no range_prior")
        if prior == "beliefs" and scene.beliefs is None:
            raise ValueError("prior='beliefs' but the scene has no beliefs")
        return {"prior": prior}

    def _unary(self, scene):
        n = scene.lattice.n_nodes
        B = scene.n_labels
        prior = self.options["prior"]
        if prior == "range":
            e0 = np.asarray(scene.range_prior, dtype=np.float64).reshape(n, B)
        elif prior == "beliefs":
            with np.errstate(divide="ignore"):
                e0 = -np.log(np.asarray(scene.beliefs, dtype=np.float64).reshape(n, B))
        else:
            e0 = np.zeros((n, B))
        m = np.min(e0, axis=1, keepdims=True)
        log_z = -m[:, 0] + np.log(np.sum(np.exp(-(e0 - m)), axis=1))
        return e0, -log_z
