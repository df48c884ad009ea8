"""A scene: one image, its corner-vertex lattice, candidate ranges and the labelling.

Everything a pseudolikelihood target needs (thesis 4.11, 6.59-6.61, 7.5): the
image ``y``, the camera and light, the B candidate ranges of every node along
its ray (the label set), the observed labelling ``f`` whose parameters are
estimated, and optionally a range prior (7.3-7.4) or stereo beliefs (6.60).
Scenes round-trip exactly through netCDF (:meth:`Scene.save` / :meth:`Scene.load`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mrfpe.brdf import functions as _brdf
from mrfpe.brdf.geometry import (
    AffineCamera,
    DirectionalLight,
    PointLight,
    ProjectiveCamera,
    camera_from_dict,
    light_from_dict,
)
from mrfpe.brdf.lattice import Lattice
from mrfpe.validation import check_beliefs

__all__ = ["Scene"]

_FORMAT_VERSION = 1


def _float_array(x: Any, name: str) -> np.ndarray:
    try:
        return np.array(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array: {exc}") from None


@dataclass(eq=False)
class Scene:
    """A single-image MRF scene on the corner-vertex lattice.

    Parameters
    ----------
    image : (H, W) float
        Pixel intensities (linear radiance units, not clipped).
    camera : AffineCamera or ProjectiveCamera
    light : DirectionalLight or PointLight
    label_ranges : (H+1, W+1, B) float
        Range of each of the B candidate labels of every node along its ray.
    observed_labels : (H+1, W+1) int
        The labelling ``f`` being explained (the true labels for synthetic scenes).
    brdf : str
        BRDF model name (see :func:`mrfpe.brdf.names`).
    true_theta : (d,) or None
        True BRDF parameters in natural units, if known.
    range_prior : (H+1, W+1, B) or None
        Range potentials ``psi_i(x_i, z_i)`` (7.3-7.4), energies (no NaN / -inf).
    beliefs : (H+1, W+1, B) or None
        Stereo label beliefs ``b``, normalised per node (6.60).
    tangent_ref : (3,)
        Reference direction of the anisotropy axis (see :mod:`mrfpe.brdf.shading`).
    noise_sigma : float
        Standard deviation of the pixel noise added to the image (0 if none).
    meta : dict
        JSON-serialisable provenance.
    """

    image: Any
    camera: Any
    light: Any
    label_ranges: Any
    observed_labels: Any
    brdf: str = "ward"
    true_theta: Any = None
    range_prior: Any = None
    beliefs: Any = None
    tangent_ref: Any = (1.0, 0.0, 0.0)
    noise_sigma: float = 0.0
    meta: dict = field(default_factory=dict)
    _cache: dict = field(default_factory=dict, init=False, repr=False)

    # ------------------------------------------------------------------ validation
    def __post_init__(self) -> None:
        H, W = self._check_image()
        self._check_camera_and_light(H, W)
        self._check_labels((H + 1, W + 1))
        self._check_model()
        self._check_node_priors()
        self._check_shading_and_meta()
        self._cache = {}

    # Each check below replaces its fields by their checked, converted values, in the
    # order the constructor calls them (a later check reads the earlier fields).
    def _check_image(self) -> tuple[int, int]:
        img = _float_array(self.image, "image")
        if img.ndim != 2 or min(img.shape) < 1:
            raise ValueError(f"image must have shape (H, W) with H, W >= 1; got {img.shape}")
        if not np.all(np.isfinite(img)):
            raise ValueError(f"image contains {np.count_nonzero(~np.isfinite(img))} "
                             "NaN/inf values; it must be finite")
        self.image = img
        return img.shape

    def _check_camera_and_light(self, H: int, W: int) -> None:
        if not isinstance(self.camera, AffineCamera | ProjectiveCamera):
            raise ValueError(f"camera must be an AffineCamera or ProjectiveCamera; "
                             f"got {type(self.camera).__name__}")
        shp = getattr(self.camera, "image_shape", None)
        if shp is not None and tuple(shp) != (H, W):
            raise ValueError(f"camera image_shape {tuple(shp)} does not match the image "
                             f"shape {(H, W)}")
        if not isinstance(self.light, DirectionalLight | PointLight):
            raise ValueError(f"light must be a DirectionalLight or PointLight; "
                             f"got {type(self.light).__name__}")

    def _check_labels(self, node_shape: tuple[int, int]) -> None:
        """``label_ranges`` (H+1, W+1, B) and ``observed_labels`` (H+1, W+1) in 0..B-1."""
        lr = _float_array(self.label_ranges, "label_ranges")
        if lr.ndim != 3 or lr.shape[:2] != node_shape:
            raise ValueError(f"label_ranges must have shape (H+1, W+1, B) = (*{node_shape}, B); "
                             f"got {lr.shape}")
        if lr.shape[2] < 1:
            raise ValueError("label_ranges must hold at least one label per node (B >= 1); "
                             "got B = 0")
        if not np.all(np.isfinite(lr)):
            raise ValueError("label_ranges must be finite")
        if isinstance(self.camera, ProjectiveCamera) and np.any(lr <= 0):
            raise ValueError("label_ranges must be > 0 for a projective camera "
                             "(ranges are distances from the camera centre)")
        self.label_ranges = lr
        B = lr.shape[2]

        obs = np.asarray(self.observed_labels)
        if obs.shape != node_shape:
            raise ValueError(f"observed_labels must have shape {node_shape}; got {obs.shape}")
        if obs.dtype.kind not in "iu":
            if obs.dtype.kind == "f" and np.all(np.isfinite(obs)) and np.all(obs == np.round(obs)):
                obs = obs.astype(np.int64)
            else:
                raise ValueError(f"observed_labels must be integers; got dtype {obs.dtype}")
        obs = obs.astype(np.int64)
        if obs.size and (obs.min() < 0 or obs.max() >= B):
            raise ValueError(f"observed_labels must lie in [0, {B - 1}] (B = {B} labels); "
                             f"got range [{obs.min()}, {obs.max()}]")
        self.observed_labels = obs

    def _check_model(self) -> None:
        model = _brdf.get(self.brdf)  # ValueError names the argument
        self.brdf = model.name
        if self.true_theta is not None:
            tt = _float_array(self.true_theta, "true_theta").reshape(-1)
            self.true_theta = model.check_theta(tt, "true_theta")[0]

    def _check_node_priors(self) -> None:
        """``range_prior`` and ``beliefs``, each of ``label_ranges``'s shape, if given."""
        shape = self.label_ranges.shape
        if self.range_prior is not None:
            rp = _float_array(self.range_prior, "range_prior")
            if rp.shape != shape:
                raise ValueError(f"range_prior must have shape {shape}; got {rp.shape}")
            if np.any(np.isnan(rp)) or np.any(rp == -np.inf):
                raise ValueError("range_prior must not contain NaN or -inf")
            self.range_prior = rp
        if self.beliefs is not None:
            self.beliefs = check_beliefs(self.beliefs, shape)

    def _check_shading_and_meta(self) -> None:
        """``tangent_ref``, ``noise_sigma`` and ``meta``."""
        ref = _float_array(self.tangent_ref, "tangent_ref")
        if ref.shape != (3,) or not np.all(np.isfinite(ref)) or not np.any(ref != 0):
            raise ValueError(f"tangent_ref must be a finite non-zero (3,) vector; got {ref}")
        self.tangent_ref = ref

        try:
            sigma = float(self.noise_sigma)
        except (TypeError, ValueError):
            raise ValueError(f"noise_sigma must be a number; got {self.noise_sigma!r}") from None
        if not np.isfinite(sigma) or sigma < 0:
            raise ValueError(f"noise_sigma must be finite and >= 0; got {self.noise_sigma!r}")
        self.noise_sigma = sigma

        if not isinstance(self.meta, dict):
            raise ValueError(f"meta must be a dict; got {type(self.meta).__name__}")
        try:
            json.dumps(self.meta, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"meta must be JSON-serialisable: {exc}") from None

    # -------------------------------------------------------------------- accessors
    @property
    def shape(self) -> tuple[int, int]:
        return self.image.shape

    @property
    def lattice(self) -> Lattice:
        if "lattice" not in self._cache:
            self._cache["lattice"] = Lattice(*self.image.shape)
        return self._cache["lattice"]

    @property
    def n_labels(self) -> int:
        return self.label_ranges.shape[2]

    @property
    def model(self) -> _brdf.BRDF:
        return _brdf.get(self.brdf)

    def node_xy(self) -> np.ndarray:
        """Image position (x, y) = (column, row) of every node, (H+1, W+1, 2)."""
        H, W = self.image.shape
        r, c = np.meshgrid(np.arange(H + 1, dtype=np.float64),
                           np.arange(W + 1, dtype=np.float64), indexing="ij")
        return np.stack([c, r], axis=-1)

    def label_points(self) -> np.ndarray:
        """3-D point of every (node, label), (H+1, W+1, B, 3); cached, read-only."""
        if "label_points" not in self._cache:
            pts = self.camera.points(self.node_xy()[:, :, None, :], self.label_ranges)
            pts.flags.writeable = False
            self._cache["label_points"] = pts
        return self._cache["label_points"]

    def observed_points(self) -> np.ndarray:
        """3-D point of every node at its observed label, (H+1, W+1, 3).

        Taken from :meth:`label_points`, so the two agree bit for bit.
        """
        idx = self.observed_labels[:, :, None, None]
        return np.take_along_axis(self.label_points(), idx, axis=2)[:, :, 0, :]

    # ------------------------------------------------------------------ serialisation
    def to_dataset(self):
        """The scene as an ``xarray.Dataset`` (see :meth:`from_dataset`)."""
        import xarray as xr

        data = {
            "image": (("y", "x"), self.image),
            "label_ranges": (("node_y", "node_x", "label"), self.label_ranges),
            "observed_labels": (("node_y", "node_x"), self.observed_labels),
            "tangent_ref": (("xyz",), self.tangent_ref),
        }
        coords = {}
        if self.true_theta is not None:
            data["true_theta"] = (("param",), self.true_theta)
            coords["param"] = list(self.model.param_names)
        if self.range_prior is not None:
            data["range_prior"] = (("node_y", "node_x", "label"), self.range_prior)
        if self.beliefs is not None:
            data["beliefs"] = (("node_y", "node_x", "label"), self.beliefs)
        attrs = {
            "mrfpe_scene_version": _FORMAT_VERSION,
            "brdf": self.brdf,
            "camera": json.dumps(self.camera.to_dict()),
            "light": json.dumps(self.light.to_dict()),
            "noise_sigma": self.noise_sigma,
            "meta": json.dumps(self.meta),
        }
        return xr.Dataset(data, coords=coords, attrs=attrs)

    @classmethod
    def from_dataset(cls, ds: Any) -> Scene:
        """Rebuild a scene from :meth:`to_dataset` output (validated again)."""
        for name in ("image", "label_ranges", "observed_labels", "tangent_ref"):
            if name not in ds:
                raise ValueError(f"ds is not a scene dataset: variable {name!r} is missing")
        for name in ("brdf", "camera", "light", "noise_sigma", "meta"):
            if name not in ds.attrs:
                raise ValueError(f"ds is not a scene dataset: attribute {name!r} is missing")

        def opt(name):
            return np.asarray(ds[name].values) if name in ds else None

        return cls(
            image=np.asarray(ds["image"].values, dtype=np.float64),
            camera=camera_from_dict(json.loads(ds.attrs["camera"])),
            light=light_from_dict(json.loads(ds.attrs["light"])),
            label_ranges=np.asarray(ds["label_ranges"].values, dtype=np.float64),
            observed_labels=np.asarray(ds["observed_labels"].values, dtype=np.int64),
            brdf=str(ds.attrs["brdf"]),
            true_theta=opt("true_theta"),
            range_prior=opt("range_prior"),
            beliefs=opt("beliefs"),
            tangent_ref=np.asarray(ds["tangent_ref"].values, dtype=np.float64),
            noise_sigma=float(ds.attrs["noise_sigma"]),
            meta=json.loads(ds.attrs["meta"]),
        )

    def save(self, path: str | Path) -> None:
        """Write the scene to a netCDF4 file, atomically and sealed with a checksum
        (:func:`mrfpe.netcdf.write_atomic`)."""
        from mrfpe.netcdf import write_atomic

        ds = self.to_dataset()
        encoding = {v: {"_FillValue": None} for v in ds.data_vars}
        write_atomic(ds, path, "scene", encoding=encoding)

    @classmethod
    def load(cls, path: str | Path) -> Scene:
        """Read a scene written by :meth:`save`.

        A missing, truncated, corrupt or damaged file (:func:`mrfpe.netcdf.open_dataset`),
        or a netCDF file that is not a scene, raises ``ValueError`` naming it (one
        without an ``image`` variable is refused before its data is read, saying
        what it holds).
        """
        from mrfpe.netcdf import describe_contents, open_dataset

        def expect(ds: Any) -> None:
            if "image" not in ds.variables:
                raise ValueError(f"{path}: not a scene file (written by Scene.save / mrfpe "
                                 f"demo): it holds {describe_contents(ds)}")

        ds = open_dataset(path, "scene", expect=expect)
        try:
            return cls.from_dataset(ds)
        except Exception as exc:  # whatever a damaged attribute makes the decoders raise
            raise ValueError(f"{path}: not a scene file (written by Scene.save / mrfpe demo): "
                             f"{type(exc).__name__}: {exc}") from None

    def __repr__(self) -> str:
        H, W = self.image.shape
        return (f"Scene(shape=({H}, {W}), n_labels={self.n_labels}, brdf={self.brdf!r}, "
                f"camera={type(self.camera).__name__}, light={type(self.light).__name__})")
