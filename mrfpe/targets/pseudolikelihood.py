"""Pseudolikelihood targets over BRDF parameters (thesis 4.23-4.24, 5.64-5.68, 6.54-6.62, 7.5-7.10).

Every target here is a sum over lattice nodes ``i`` of a per-node term built
from the node's energies at each of its B labels,

    ``E_i(s) = U^A_i(s; theta) + E0_i(s)``,

with ``U^A`` the BRDF data energy (:mod:`mrfpe.targets.energy`, 4.12/4.20/4.27
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
``sigma_b``'s default) is :class:`mrfpe.targets.brdf_target.BRDFTarget`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.targets.brdf_target import BRDFTarget, _positive, auto_sigma_b
from mrfpe.targets.residuals import RESIDUAL_KINDS

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


def _robust(x: np.ndarray, sigma: float, e: float) -> np.ndarray:
    """Truncated robust potential ``-ln((1-e) exp(-|x|/sigma) + e)`` (6.23, 6.24)."""
    return -np.log((1.0 - e) * np.exp(-np.abs(x) / sigma) + e)


class PL(BRDFTarget):
    """Pseudolikelihood of the BRDF MRF, thesis 4.23-4.24 / 5.64-5.66 (no unary energy)."""

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

    name = "pls"

    def _check_options(self, scene: Any, options: dict) -> dict:
        opts = dict(options)
        w = opts.pop("prior_weight", 1.0)
        if opts:
            raise ValueError(f"pls options are prior_weight, sigma_b, data_term, dtype; "
                             f"got unknown {sorted(opts)}")
        if scene.range_prior is None:
            raise ValueError("scene has no range_prior; pls (7.5-7.7) needs the range "
                             "potentials psi_i of 7.4 (mrfpe.synthetic.make_scene sets them)")
        w = float(w)
        if not (np.isfinite(w) and w >= 0):
            raise ValueError(f"prior_weight must be finite and >= 0; got {w!r}")
        return {"prior_weight": w}

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

    name = "pl3"

    def _check_options(self, scene: Any, options: dict) -> dict:
        opts = dict(options)
        beliefs = opts.pop("beliefs", None)
        T = opts.pop("temperature", 1.0)
        if opts:
            raise ValueError(f"pl3 options are beliefs, temperature, sigma_b, data_term, dtype; "
                             f"got unknown {sorted(opts)}")
        T = _positive("temperature", T)
        shape = (*scene.lattice.node_shape, scene.n_labels)
        if beliefs is None:
            if scene.beliefs is None:
                raise ValueError("scene has no beliefs; pl3 (6.60-6.62) needs per-node label "
                                 "beliefs (pass beliefs=... or use a stereo scene)")
            b = np.asarray(scene.beliefs, dtype=np.float64)
            source = "scene"
        else:
            b = np.asarray(beliefs, dtype=np.float64)
            source = "option"
            if b.shape != shape:
                raise ValueError(f"beliefs must have shape {shape}; got {b.shape}")
            if not np.all(np.isfinite(b)) or np.any(b < 0):
                raise ValueError("beliefs must be finite and >= 0")
            if not np.allclose(b.sum(axis=2), 1.0, rtol=0, atol=1e-6):
                raise ValueError("beliefs must be normalised per node (sum over labels = 1)")
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

    name = "pl2"

    def _check_options(self, scene: Any, options: dict) -> dict:
        opts = dict(options)
        smooth = bool(opts.pop("smoothness", True))
        sp = _positive("smoothness_sigma", opts.pop("smoothness_sigma", 1.0))
        ep = float(opts.pop("smoothness_e", 0.01))
        on = opts.pop("pairwise_on", "range")
        mc = opts.pop("match_cost", None)
        sd = _positive("match_sigma", opts.pop("match_sigma", 1.0))
        ed = float(opts.pop("match_e", 0.01))
        if opts:
            raise ValueError(
                "pl2 options are smoothness, smoothness_sigma, smoothness_e, pairwise_on, "
                f"match_cost, match_sigma, match_e, sigma_b, data_term, dtype; got unknown "
                f"{sorted(opts)}")
        for nm, e in (("smoothness_e", ep), ("match_e", ed)):
            if not 0 <= e < 1:
                raise ValueError(f"{nm} must lie in [0, 1); got {e!r}")
        if on not in ("range", "label"):
            raise ValueError(f"pairwise_on must be 'range' or 'label'; got {on!r}")
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

    name = "pml"
    _a, _b = 0.0, 1.0

    def _check_options(self, scene: Any, options: dict) -> dict:
        opts = dict(options)
        prior = opts.pop("prior", "auto")
        if opts:
            raise ValueError(f"pml options are prior, sigma_b, data_term, dtype; got unknown "
                             f"{sorted(opts)}")
        choices = ("auto", "range", "beliefs", "none")
        if prior not in choices:
            raise ValueError(f"prior must be one of {choices}; got {prior!r}")
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
