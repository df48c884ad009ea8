"""Synthetic scenes of the thesis's experiments (7.2, Appendix C).

:func:`make_scene` draws a surface as a range map over the image (smooth:
thin-plate-spline interpolation of random control points in a cube; jagged:
independent uniform ranges), renders it with any BRDF under a light at
infinity with the camera at the origin, and builds the per-node label sets and
the range prior of 7.3-7.4. The true labelling renders the image *exactly*
(same code path as the targets' data term, :mod:`mrfpe.brdf.shading`), so
noise-free data have zero data energy at the true labels and parameters.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from mrfpe.brdf import functions as _brdf
from mrfpe.brdf.geometry import AffineCamera, DirectionalLight, PointLight, ProjectiveCamera
from mrfpe.brdf.lattice import Lattice
from mrfpe.brdf.scene import Scene
from mrfpe.brdf.shading import pixel_intensity, radiance, triangle_geometry
from mrfpe.validation import check_seed

__all__ = ["LIGHT_CONE_DEG", "make_scene", "random_light", "render", "surface_ranges"]

#: Half-angle of the cone about the viewing direction from which the default
#: random light is drawn (the thesis, 7.2 step 3, draws "a random light source
#: (at infinity)" without saying from where; lights far from the viewing
#: direction leave much of a surface in shadow, which carries no information).
LIGHT_CONE_DEG = 45.0


def render(brdf: Any, theta: Any, points: Any, camera: Any, light: Any,
           tangent_ref: Any = (1.0, 0.0, 0.0)) -> np.ndarray:
    """Render the piecewise-planar surface through the node points.

    Each pixel is split into the lattice's two triangles (``Lattice.triangles``),
    each triangle is shaded at its centroid (:func:`mrfpe.brdf.shading.triangle_geometry`,
    :func:`~mrfpe.brdf.shading.radiance`, thesis 4.17/4.18) and the pixel is the mean
    of its two triangles (:func:`~mrfpe.brdf.shading.pixel_intensity`).

    Parameters
    ----------
    brdf : str or BRDF model
    theta : (d,) or (N, d)
        Natural-unit parameters.
    points : (H+1, W+1, 3)
        3-D point of every corner-vertex node.
    camera, light : see :mod:`mrfpe.brdf.geometry`
    tangent_ref : (3,)

    Returns
    -------
    ndarray
        (H, W) for a single ``theta`` vector, (N, H, W) for a batch.
    """
    model = _brdf.get(brdf)
    single = np.ndim(theta) == 1
    theta = model.as_batch(theta)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 3 or pts.shape[2] != 3 or min(pts.shape[:2]) < 2:
        raise ValueError(f"points must have shape (H+1, W+1, 3) with H, W >= 1; got {pts.shape}")
    H, W = pts.shape[0] - 1, pts.shape[1] - 1
    tri = Lattice(H, W).triangles
    flat = pts.reshape(-1, 3)
    geom = triangle_geometry(flat[tri[:, 0]], flat[tri[:, 1]], flat[tri[:, 2]],
                             camera, light, tangent_ref)
    rad = radiance(model, theta, geom)  # (N, 2HW): triangles 2p, 2p+1 belong to pixel p
    img = pixel_intensity(rad[:, 0::2], rad[:, 1::2]).reshape(-1, H, W)
    return img[0] if single else img


def surface_ranges(shape: tuple[int, int], surface: str, rng: np.random.Generator,
                   n_control_points: int = 20) -> np.ndarray:
    """Range map (H+1, W+1) of a random surface in pixel-width units, before any offset.

    ``"smooth"``: thin-plate-spline interpolation (Appendix C, C.2-C.6, via
    ``scipy.interpolate.RBFInterpolator(kernel="thin_plate_spline")``, whose
    ``r^2 log r`` kernel is C.3 halved and gives the same interpolant) of
    ``n_control_points`` points drawn uniformly from the cube
    ``[0, W] x [0, H] x [0, W]`` (heights spanning the image's width, 7.2).
    ``"jagged"``: independent uniform ranges on ``[0, 6]`` (7.2).
    """
    H, W = shape
    if surface == "smooth":
        from scipy.interpolate import RBFInterpolator

        n = int(n_control_points)
        if n < 3:
            raise ValueError(f"n_control_points must be >= 3 (a TPS needs an affine part); "
                             f"got {n_control_points!r}")
        ctrl = rng.uniform(0.0, 1.0, (n, 3)) * np.array([W, H, W], dtype=np.float64)
        tps = RBFInterpolator(ctrl[:, :2], ctrl[:, 2], kernel="thin_plate_spline")
        r, c = np.meshgrid(np.arange(H + 1.0), np.arange(W + 1.0), indexing="ij")
        xy = np.stack([c.ravel(), r.ravel()], axis=1)
        return tps(xy).reshape(H + 1, W + 1)
    if surface == "jagged":
        return rng.uniform(0.0, 6.0, (H + 1, W + 1))
    raise ValueError(f"surface must be 'smooth' or 'jagged'; got {surface!r}")


def random_light(rng: np.random.Generator, towards: Any,
                 max_angle_deg: float = LIGHT_CONE_DEG) -> DirectionalLight:
    """Directional light drawn uniformly (in solid angle) from a cone about ``towards``."""
    w = np.asarray(towards, dtype=np.float64)
    w = w / np.linalg.norm(w)
    cos_max = np.cos(np.deg2rad(max_angle_deg))
    cz = rng.uniform(cos_max, 1.0)
    phi = rng.uniform(0.0, 2.0 * np.pi)
    sz = np.sqrt(max(0.0, 1.0 - cz * cz))
    a = np.eye(3)[np.argmin(np.abs(w))]
    e1 = np.cross(w, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(w, e1)
    return DirectionalLight(cz * w + sz * (np.cos(phi) * e1 + np.sin(phi) * e2))


def _pixel_size(camera: Any, xy: np.ndarray, rng_val: float) -> float:
    """World length of one pixel width at range ``rng_val`` about image point ``xy``."""
    p = camera.points(np.stack([xy, xy + np.array([1.0, 0.0])]), np.array([rng_val, rng_val]))
    return float(np.linalg.norm(p[1] - p[0]))


def _int_param(x: Any, name: str, low: int) -> int:
    if isinstance(x, bool) or not isinstance(x, int | np.integer) or x < low:
        raise ValueError(f"{name} must be an integer >= {low}; got {x!r}")
    return int(x)


def _pos_float(x: Any, name: str, allow_zero: bool = False) -> float:
    if isinstance(x, bool | np.bool_ | str):
        raise ValueError(f"{name} must be a number; got {x!r}")
    try:
        val = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number; got {x!r}") from None
    if not np.isfinite(val) or val < 0 or (val == 0 and not allow_zero):
        raise ValueError(f"{name} must be finite and {'>=' if allow_zero else '>'} 0; got {x!r}")
    return val


def _finite_float(x: Any, name: str) -> float:
    if isinstance(x, bool | np.bool_ | str):
        raise ValueError(f"{name} must be a finite number or None; got {x!r}")
    try:
        val = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number or None; got {x!r}") from None
    if not np.isfinite(val):
        raise ValueError(f"{name} must be finite; got {x!r}")
    return val


def make_scene(brdf: str = "ward", theta: Any = None, shape: tuple[int, int] = (100, 100),
               n_labels: int = 20, surface: str = "smooth", light: Any = None,
               noise: float = 0.0, seed: int | None = 0, label_step: float = 0.3,
               prior_sigma: float | None = None, n_control_points: int = 20,
               true_label: Any = "random", camera: Any = None, depth: float | None = None,
               tangent_ref: Any = (1.0, 0.0, 0.0)) -> Scene:
    """A synthetic scene as in the thesis's experiments (7.2).

    Parameters
    ----------
    brdf : str
        Model name (:func:`mrfpe.brdf.names`).
    theta : (d,)
        True parameters in *natural* units, checked against the model's bounds.
    shape : (H, W)
        Image size in pixels (the thesis uses 100 x 100).
    n_labels : int
        B >= 2, candidate labels per node (one label gives a pseudolikelihood of 0).
    surface : "smooth" | "jagged"
        See :func:`surface_ranges` (the thesis uses smooth for Ward, jagged for Phong).
    light : DirectionalLight, PointLight or None
        None draws a random light at infinity (7.2 step 3) from the cone of
        half-angle :data:`LIGHT_CONE_DEG` about the direction to the camera.
    noise : float
        Standard deviation of additive Gaussian pixel noise.
    seed : int or None
        Seeds every random choice (surface, light, true label positions, noise).
    label_step : float
        Range increment between consecutive labels, in pixel widths (7.2: 0.3).
    prior_sigma : float or None
        sigma of the range prior 7.4 *in label units*; None uses B/5 (7.2).
        The prior is ``psi_i(x) = |z_i - r_i(x)| / (prior_sigma * step)`` with
        ``z_i`` the true range of node i, ``r_i(x)`` the range of label x and
        ``step`` the world length of one label step.
    n_control_points : int
        Control points of the smooth surface (7.2: 20).
    true_label : "random" | "centre" | int | (H+1, W+1) ints
        Index of the true range within each node's labels. The thesis (7.2
        step 4) only says the labels are "discrete ranges about the true
        range"; the default draws the index uniformly from ``0..B-1`` per node
        so that no code can rely on the truth sitting at a fixed index.
        The labels of node i are ``z_i + (k - t_i) * step``, k = 0..B-1.
    camera : AffineCamera, ProjectiveCamera or None
        None is the orthographic camera at the origin looking along +z.
    depth : float or None
        Constant added to the range map (world units). None: for the affine
        camera ``max(H, W) + B * label_step`` pixel widths beyond the nearest
        surface point; for a projective camera the focal length (so that one
        world unit is about one pixel width at the surface).
    tangent_ref : (3,)
        Anisotropy reference direction (see :mod:`mrfpe.brdf.shading`).

    Returns
    -------
    Scene
        With ``observed_labels`` the true labels, ``true_theta`` in natural
        units and ``range_prior`` set; ``meta`` records the settings.
    """
    settings = _checked_settings(brdf, theta, shape, n_labels, surface, light, noise, seed,
                                 label_step, prior_sigma, n_control_points, depth, camera)
    return _synthesise(settings, true_label, tangent_ref)


@dataclasses.dataclass(frozen=True)
class _Settings:
    """:func:`make_scene`'s arguments, checked and converted (pixel-width units)."""

    model: Any
    theta: np.ndarray
    H: int
    W: int
    B: int
    seed: int | None
    step_px: float
    sigma_lab: float
    noise: float
    n_ctrl: int
    depth: float | None
    surface: str
    camera: AffineCamera | ProjectiveCamera
    light: Any


def _checked_settings(brdf: str, theta: Any, shape: Any, n_labels: Any, surface: str,
                      light: Any, noise: Any, seed: Any, label_step: Any, prior_sigma: Any,
                      n_control_points: Any, depth: Any, camera: Any) -> _Settings:
    """Every setting of :func:`make_scene` checked, before anything is drawn or allocated."""
    model = _brdf.get(brdf)
    theta_arr = _true_theta(model, theta)
    H, W = _image_shape(shape)
    seed = check_seed(seed)
    # B >= 2: with one label the pseudolikelihood is identically 0 (no alternative label)
    B = _int_param(n_labels, "n_labels", 2)
    from mrfpe.budget import check_memory

    # per node: the label ranges, the range prior and beliefs (B floats each) and a dozen
    # per-pixel working arrays (normals, shading, the range map): checked before any
    check_memory(8.0 * ((H + 1) * (W + 1) * (3 * B + 16) + 16 * H * W),
                 f"a {H}x{W} scene with {B} labels", "use a smaller shape or fewer labels")
    step_px = _pos_float(label_step, "label_step")
    sigma_lab = B / 5.0 if prior_sigma is None else _pos_float(prior_sigma, "prior_sigma")
    noise = _pos_float(noise, "noise", allow_zero=True)
    n_ctrl = _int_param(n_control_points, "n_control_points", 3)
    if depth is not None:
        depth = _finite_float(depth, "depth")
    if surface not in ("smooth", "jagged"):
        raise ValueError(f"surface must be 'smooth' or 'jagged'; got {surface!r}")
    camera = _camera_and_light(camera, light)
    return _Settings(model, theta_arr, H, W, B, seed, step_px, sigma_lab, noise, n_ctrl, depth,
                     surface, camera, light)


def _synthesise(s: _Settings, true_label: Any, tangent_ref: Any) -> Scene:
    """The scene of checked settings: surface, labels, prior, light, rendered image."""
    H, W, B, camera = s.H, s.W, s.B, s.camera
    ss = np.random.SeedSequence(s.seed)
    rng_surface, rng_light, rng_label, rng_noise = (np.random.default_rng(x) for x in ss.spawn(4))

    f = surface_ranges((H, W), s.surface, rng_surface, s.n_ctrl)  # pixel widths
    centre_xy = np.array([W / 2.0, H / 2.0])
    base, px = _base_depth(camera, centre_xy, f, max(H, W) + B * s.step_px, s.depth)
    z = base + f * px  # true range of every node
    step = s.step_px * px
    t = _true_labels(true_label, rng_label, (H + 1, W + 1), B)

    k = np.arange(B, dtype=np.float64)
    # (k - t) * step is exactly 0.0 at k = t, so the true label's range is z bit for bit.
    label_ranges = z[..., None] + (k - t[..., None]) * step
    if isinstance(camera, ProjectiveCamera) and np.any(label_ranges <= 0):
        raise ValueError(f"depth={s.depth!r} puts some candidate ranges behind the camera; "
                         "choose a larger depth")
    range_prior = np.abs(z[..., None] - label_ranges) / (s.sigma_lab * step)  # 7.4

    light = s.light
    if light is None:
        mid = camera.points(centre_xy, np.array(float(np.median(z))))
        light = random_light(rng_light, camera.to_camera(mid))

    meta = {
        "generator": "mrfpe.brdf.synthetic.make_scene",
        "surface": s.surface,
        "seed": None if s.seed is None else int(s.seed),
        "label_step": s.step_px,
        "prior_sigma": s.sigma_lab,
        "n_control_points": s.n_ctrl,
        "true_label": true_label if isinstance(true_label, str) else "given",
        "depth": float(base),
        "pixel_size": px,
    }
    scene = Scene(image=np.zeros((H, W)), camera=camera, light=light,
                  label_ranges=label_ranges, observed_labels=t, brdf=s.model.name,
                  true_theta=s.theta, range_prior=range_prior, tangent_ref=tangent_ref,
                  noise_sigma=s.noise, meta=meta)
    image = render(s.model, s.theta, scene.observed_points(), camera, scene.light,
                   scene.tangent_ref)
    if s.noise > 0:
        image = image + rng_noise.normal(0.0, s.noise, image.shape)
    # Rebuilding validates the image; label points are recomputed with identical bits.
    return dataclasses.replace(scene, image=image)


def _true_theta(model: Any, theta: Any) -> np.ndarray:
    """``theta`` as the model's ``d`` natural parameters, checked against its bounds."""
    if theta is None:
        raise ValueError(f"theta is required: the true {model.name} parameters "
                         f"{model.param_names} in natural units")
    try:
        theta_arr = np.asarray(theta, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"theta must be {model.d} numbers {model.param_names} in natural "
                         f"units; got {theta!r}") from None
    if theta_arr.shape != (model.d,):
        raise ValueError(f"theta must have shape ({model.d},) for {model.name} "
                         f"{model.param_names}; got {theta_arr.shape}")
    return model.check_theta(theta_arr)[0]


def _image_shape(shape: Any) -> tuple[int, int]:
    """``(H, W)``, two integers >= 1."""
    try:
        H, W = (int(s) for s in shape)
    except (TypeError, ValueError):
        raise ValueError(f"shape must be (H, W); got {shape!r}") from None
    if H < 1 or W < 1 or tuple(shape) != (H, W):
        raise ValueError(f"shape must be (H, W) with integers >= 1; got {shape!r}")
    return H, W


def _camera_and_light(camera: Any, light: Any) -> AffineCamera | ProjectiveCamera:
    """The camera (the orthographic one for ``None``), after checking both kinds."""
    if camera is None:
        camera = AffineCamera()
    if not isinstance(camera, AffineCamera | ProjectiveCamera):
        raise ValueError(f"camera must be an AffineCamera, ProjectiveCamera or None; "
                         f"got {type(camera).__name__}")
    if light is not None and not isinstance(light, DirectionalLight | PointLight):
        raise ValueError(f"light must be a DirectionalLight, PointLight or None; "
                         f"got {type(light).__name__}")
    return camera


def _base_depth(camera: Any, centre_xy: np.ndarray, f: np.ndarray, reach_px: float,
                depth: float | None) -> tuple[float, float]:
    """``(base, px)``: the range added to the surface, and one pixel's world width there.

    ``reach_px`` is how far (in pixel widths) the affine camera's default depth puts the
    nearest surface point: the image's size plus the labels' span.
    """
    if isinstance(camera, ProjectiveCamera):
        d0 = _pos_float(_pixel_size(camera, centre_xy, 1.0), "camera pixel size")
        base = 1.0 / d0 if depth is None else float(depth)
        px = _pixel_size(camera, centre_xy, base)
    else:
        px = _pixel_size(camera, centre_xy, 0.0)
        base = reach_px * px - f.min() * px if depth is None else float(depth)
    if not np.isfinite(base):
        raise ValueError(f"depth must be finite; got {depth!r}")
    return base, px


def _true_labels(true_label: Any, rng: np.random.Generator, nodes: tuple[int, int],
                 B: int) -> np.ndarray:
    """The index of each node's true range among its ``B`` labels (int64, ``nodes``)."""
    if isinstance(true_label, str):
        if true_label == "random":
            t = rng.integers(0, B, size=nodes)
        elif true_label in ("centre", "center"):
            t = np.full(nodes, B // 2)
        else:
            raise ValueError(f"true_label must be 'random', 'centre', an int or an "
                             f"(H+1, W+1) array; got {true_label!r}")
    else:
        t = np.asarray(true_label)
        if t.dtype.kind not in "iu":
            raise ValueError(f"true_label must hold integers; got dtype {t.dtype}")
        t = np.broadcast_to(t, nodes) if t.ndim == 0 else t
        if t.shape != nodes:
            raise ValueError(f"true_label must be an int or have shape {nodes}; "
                             f"got {t.shape}")
        if t.min() < 0 or t.max() >= B:
            raise ValueError(f"true_label must lie in [0, {B - 1}]; got [{t.min()}, {t.max()}]")
    return np.array(t, dtype=np.int64)
