"""Window match measures and the data-energy cost volume on the corner-vertex lattice.

Pixel level (thesis 6.3.3, Appendix B)
--------------------------------------
For every pixel ``(r, c)`` of the reference (left) rectified image and every
disparity label ``d`` the window ``A`` about ``(r, c)`` is compared with the
window ``B`` about ``(r, c - d)`` in the right image (``x_right = x_left - d``,
the Middlebury convention):

* ``"ncc"``: the 2-D correlation coefficient (6.36, B.1) with a variance
  regulariser ``eps``,
  ``r = sum cov(A, B) / sqrt((sum var A + eps) (sum var B + eps))``,
  mapped to ``[0, 1]`` by ``d = (r + 1) / 2`` (6.37). Colour images are
  compared as one vector per window with each channel centred on its own mean
  (the sums run over channels). ``eps`` (in squared [0, 1]-intensity units)
  keeps textureless windows from dividing by zero: a flat window gets
  ``r -> 0``, i.e. ``d = 1/2``, "no information".
* ``"ssd"``: the sum of squared differences (B.2), negated, shifted and scaled
  to ``[0, 1]`` as B.2 suggests: ``d = 1 - SSD / SSD_max`` with
  ``SSD_max = n_window * n_channels`` (the largest SSD of [0, 1] images).

Window sums are box filters (``cv2.boxFilter``, border ``BORDER_REFLECT_101``)
over the whole image, one pass per disparity label: no loop over pixels.
Fractional disparity labels are allowed; the right image is then shifted by
linear interpolation along the scan line.

Data energy (6.5, 6.23, 6.27)
-----------------------------
``data="log"`` (default): ``psi_d = -ln((1 - e_d) d + e_d)``, the match measure
read as the local-evidence probability ``v_s ∝ d`` of 6.27 with the outlier
floor ``e_d`` of 6.23 (for ``e_d -> 0`` this is ``-ln((1 + r)/2)``).
``data="robust"``: the thesis's 6.23 literally, ``F = 1 - d`` (6.5) and
``psi_d = -ln((1 - e_d) exp(-F / sigma_d) + e_d)``.

A pixel whose correspondence ``c - d`` falls outside the right image has no
match: it gets the energy of an uncorrelated window (``d = 1/2``), so the
smoothness term, not a made-up match, decides its label.

Corner-vertex nodes (thesis 6 intro, 4.2)
-----------------------------------------
The disparity MRF lives on the (H+1) x (W+1) corner-vertex nodes, node
``(i, j)`` at image position ``(x, y) = (j, i)`` (pixel ``(r, c)`` covers
``[c, c+1] x [r, r+1]``, :mod:`mrfpe.brdf.lattice`). A node with disparity ``d``
says that the pixels around that corner all shift by ``d``, so its data energy
is the **mean of the pixel energies of the (up to four) pixels that touch
it** at the same label: 4 pixels inside, 2 on an edge, 1 at a corner. The mean
(not the sum) keeps border nodes on the same scale as interior ones.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = [
    "MATCH_MEASURES",
    "as_image",
    "data_energy",
    "match_measure",
    "node_costs",
    "pixel_to_node",
]

MATCH_MEASURES = ("ncc", "ssd")
DATA_ENERGIES = ("log", "robust")


def as_image(img: Any, name: str) -> np.ndarray:
    """Validate an image and return it as float64 (H, W, C) in [0, 1]-ish units.

    ``uint8`` is divided by 255, ``uint16`` by 65535; floats are used as given.

    Raises
    ------
    ValueError
        Wrong number of dimensions, empty, a non-numeric dtype, or NaN/inf.
    """
    arr = np.asarray(img)
    if arr.dtype == np.bool_ or not (np.issubdtype(arr.dtype, np.integer)
                                     or np.issubdtype(arr.dtype, np.floating)):
        raise ValueError(f"{name} must be an integer or floating image; got dtype {arr.dtype}")
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (1, 3, 4)):
        raise ValueError(f"{name} must have shape (H, W) or (H, W, 1|3|4); got {arr.shape}")
    if arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"{name} must not be empty; got shape {arr.shape}")
    if arr.dtype == np.uint8:
        out = arr.astype(np.float64) / 255.0
    elif arr.dtype == np.uint16:
        out = arr.astype(np.float64) / 65535.0
    else:
        out = arr.astype(np.float64)
    if not np.all(np.isfinite(out)):
        raise ValueError(f"{name} contains NaN or inf")
    if out.ndim == 2:
        out = out[:, :, None]
    if out.shape[2] == 4:  # drop alpha
        out = out[:, :, :3]
    return np.ascontiguousarray(out)


def _box(img: np.ndarray, window: int) -> np.ndarray:
    """Window mean of each channel, (H, W, C) -> (H, W, C)."""
    import cv2

    out = np.empty_like(img)
    for k in range(img.shape[2]):  # per channel: cv2 keeps float64 for 2-D arrays
        out[:, :, k] = cv2.boxFilter(img[:, :, k], -1, (window, window), normalize=True,
                                     borderType=cv2.BORDER_REFLECT_101)
    return out


def _shift_right(right: np.ndarray, d: float) -> tuple[np.ndarray, np.ndarray]:
    """Right image resampled at ``x - d`` for every left column, and the valid-column mask.

    Columns whose correspondence ``c - d`` falls outside the image replicate
    the border column (so box filters near the border see sensible values) and
    are flagged invalid.
    """
    W = right.shape[1]
    x = np.arange(W) - d
    valid = (x >= 0.0) & (x <= W - 1)
    xc = np.clip(x, 0.0, W - 1)
    x0 = np.floor(xc).astype(np.int64)
    f = xc - x0
    x1 = np.minimum(x0 + 1, W - 1)
    if np.all(f == 0.0):
        shifted = right[:, x0, :]
    else:
        shifted = right[:, x0, :] * (1.0 - f)[None, :, None] + right[:, x1, :] * f[None, :, None]
    return np.ascontiguousarray(shifted), valid


def _check_window(window: Any) -> int:
    if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 1 \
            or window % 2 == 0:
        raise ValueError(f"window must be an odd integer >= 1; got {window!r}")
    return int(window)


def match_measure(left: Any, right: Any, disparities: Any, *, window: int = 3,
                  match: str = "ncc", eps: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Pixel match measure ``d(s, d_s, I^R)`` in [0, 1] for every pixel and label (6.36-6.37, B.2).

    Parameters
    ----------
    left, right : (H, W) or (H, W, C)
        Rectified images (left is the reference view); uint8 or float.
    disparities : (L,)
        Disparity of each label in pixels (fractional values allowed; negative
        values mean ``x_right > x_left``, as with a principal-point offset).
    window : odd int
        Side of the square match window.
    match : {"ncc", "ssd"}
    eps : float
        NCC variance regulariser (>= 0).

    Returns
    -------
    measure : ndarray (H, W, L)
        1 for a perfect match, 0 for the worst (see module docstring).
    valid : ndarray (H, W, L) of bool
        False where the correspondence falls outside the right image.
    """
    L_img = as_image(left, "left")
    R_img = as_image(right, "right")
    if L_img.shape != R_img.shape:
        raise ValueError(f"left and right must have the same shape; got {np.shape(left)} and "
                         f"{np.shape(right)}")
    window = _check_window(window)
    if match not in MATCH_MEASURES:
        raise ValueError(f"match must be one of {MATCH_MEASURES}; got {match!r}")
    eps = float(eps)
    if not np.isfinite(eps) or eps < 0:
        raise ValueError(f"eps must be finite and >= 0; got {eps!r}")
    disp = np.asarray(disparities, dtype=np.float64).reshape(-1)
    if disp.size == 0 or not np.all(np.isfinite(disp)):
        raise ValueError("disparities must be a non-empty array of finite values")

    H, W, C = L_img.shape
    out = np.empty((H, W, disp.size))
    valid = np.empty((H, W, disp.size), dtype=bool)
    # theta-free window statistics of the reference image, computed once
    if match == "ncc":
        muL = _box(L_img, window)
        varL = np.maximum(_box(L_img * L_img, window) - muL * muL, 0.0).sum(axis=2)
    for k, d in enumerate(disp):  # one vectorised pass per label (not per pixel)
        Rd, ok = _shift_right(R_img, d)
        valid[:, :, k] = ok[None, :]
        if match == "ncc":
            muR = _box(Rd, window)
            varR = np.maximum(_box(Rd * Rd, window) - muR * muR, 0.0).sum(axis=2)
            cov = (_box(L_img * Rd, window) - muL * muR).sum(axis=2)
            r = cov / np.sqrt((varL + eps) * (varR + eps))
            out[:, :, k] = (np.clip(r, -1.0, 1.0) + 1.0) / 2.0
        else:
            diff = L_img - Rd
            msd = _box(diff * diff, window).sum(axis=2) / C
            out[:, :, k] = 1.0 - np.clip(msd, 0.0, 1.0)
    return out, valid


def data_energy(measure: np.ndarray, *, data: str = "log", e_d: float = 1e-4,
                sigma_d: float = 0.1) -> np.ndarray:
    """Data energy ``psi_d`` from a match measure in [0, 1] (6.5, 6.23, 6.27).

    ``data="log"``: ``-ln((1 - e_d) d + e_d)``; ``data="robust"``:
    ``-ln((1 - e_d) exp(-(1 - d) / sigma_d) + e_d)`` (6.23 with F = 1 - d, 6.5).
    """
    if data not in DATA_ENERGIES:
        raise ValueError(f"data must be one of {DATA_ENERGIES}; got {data!r}")
    e_d = float(e_d)
    if not 0.0 <= e_d < 1.0:
        raise ValueError(f"e_d must be in [0, 1); got {e_d!r}")
    m = np.clip(np.asarray(measure, dtype=np.float64), 0.0, 1.0)
    if data == "log":
        p = m
    else:
        sigma_d = float(sigma_d)
        if not np.isfinite(sigma_d) or sigma_d <= 0:
            raise ValueError(f"sigma_d must be > 0; got {sigma_d!r}")
        p = np.exp(-(1.0 - m) / sigma_d)
    with np.errstate(divide="ignore"):
        return -np.log((1.0 - e_d) * p + e_d)


def pixel_to_node(pixel: np.ndarray) -> np.ndarray:
    """Mean over the (up to four) pixels touching each corner-vertex node.

    (H, W, ...) -> (H+1, W+1, ...): node ``(i, j)`` averages pixels
    ``(i-1..i, j-1..j)`` that exist.
    """
    pixel = np.asarray(pixel, dtype=np.float64)
    H, W = pixel.shape[:2]
    pad = np.zeros((H + 2, W + 2, *pixel.shape[2:]))
    pad[1:-1, 1:-1] = pixel
    cnt = np.zeros((H + 2, W + 2))
    cnt[1:-1, 1:-1] = 1.0
    s = pad[:-1, :-1] + pad[1:, :-1] + pad[:-1, 1:] + pad[1:, 1:]
    n = cnt[:-1, :-1] + cnt[1:, :-1] + cnt[:-1, 1:] + cnt[1:, 1:]
    return s / n.reshape(n.shape + (1,) * (pixel.ndim - 2))


def node_costs(left: Any, right: Any, disparities: Any, *, window: int = 3,
               match: str = "ncc", eps: float = 1e-6, data: str = "log", e_d: float = 1e-4,
               sigma_d: float = 0.1) -> np.ndarray:
    """Data energy of every corner-vertex node and disparity label, (H+1, W+1, L).

    Pixel match measures (:func:`match_measure`) -> pixel energies
    (:func:`data_energy`; unmatched pixels get the energy of ``d = 1/2``) ->
    node energies as the mean over the touching pixels (:func:`pixel_to_node`).
    """
    m, valid = match_measure(left, right, disparities, window=window, match=match, eps=eps)
    m = np.where(valid, m, 0.5)
    return pixel_to_node(data_energy(m, data=data, e_d=e_d, sigma_d=sigma_d))
