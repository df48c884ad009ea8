"""Numba kernels of :mod:`mrfpe.models.multispin`: multi-spin coded heat-bath sweeps.

One ``uint64`` word per site holds 64 replicas (bit ``r``: replica ``r``'s spin), as in
multi-spin coding (Jacobs & Rebbi 1981; Zorn, Herrmann & Rebbi 1981). A site's
neighbours are counted for all 64 replicas at once by bit-sliced adders; the heat-bath
(Gibbs; Geman & Geman 1984) draw ``[U_r < p_r]`` is then decided digit by digit, most
significant first: digit ``k`` of every replica's ``U_r`` is bit ``r`` of one random word,
digit ``k`` of every replica's ``p_r`` is bit ``r`` of a word selected, by multiplexers
on the count bits, from a table of probability digits. A replica is decided at the first
digit where the two differ; the word is done when every replica is.

Random words are SplitMix64 (Steele, Lea & Flood 2014) of the counter ``(((sweep *
n_words + word) * H + row) * W + column) * 64 + digit``, so results do not depend on the
number of threads.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from mrfpe.models.gibbs_sites import splitmix64 as _word
from mrfpe.threads import configure_vector_width

configure_vector_width()  # before our first @njit, as mrfpe.models.simulate does

__all__ = ["AHEAD", "sweeps"]

#: Digits of every site done in vectorised loops over a row (random words included): a
#: site's 64 replicas need about 7.3 on average and are all decided within 12 with
#: probability 0.985; the rest finish one by one.
AHEAD = 12
_ZERO, _ONE = np.uint64(0), np.uint64(1)
_TWO64 = 18446744073709551616.0


@njit(inline="always", cache=True)
def _mux(a, b, sel):
    """Bitwise ``sel ? b : a``."""
    return a ^ ((a ^ b) & sel)


@njit(inline="always", cache=True)
def _add2(a0, a1, b0, b1):
    """Bit-sliced sum of two 2-bit numbers: three bit planes."""
    c = a0 & b0
    return a0 ^ b0, a1 ^ b1 ^ c, (a1 & b1) | (c & (a1 ^ b1))


@njit(inline="always", cache=True)
def _add3(a0, a1, a2, b0, b1, b2):
    """Bit-sliced sum of two 3-bit numbers: four bit planes."""
    c0 = a0 & b0
    c1 = (a1 & b1) | (c0 & (a1 ^ b1))
    return (a0 ^ b0, a1 ^ b1 ^ c0, a2 ^ b2 ^ c1, (a2 & b2) | (c1 & (a2 ^ b2)))


@njit(inline="always", cache=True)
def _count(xp, w, R, C, offsets, s0, s1, cb):
    """Per edge type ``t``, the replicas with 1 (``s0[t]``) or 2 (``s1[t]``) neighbours of
    that type in state 1 (a pair's XOR and AND); then their total in bit planes ``cb``.
    ``(R, C)`` is the site in the padded array (a ghost border: zeros, or the wrap)."""
    T = offsets.shape[0]
    for t in range(T):
        dr, dc = offsets[t, 0], offsets[t, 1]
        a, b = xp[w, R + dr, C + dc], xp[w, R - dr, C - dc]
        s0[t], s1[t] = a ^ b, a & b
    if T == 2:
        cb[0], cb[1], cb[2] = _add2(s0[0], s1[0], s0[1], s1[1])
    else:
        p0, p1, p2 = _add2(s0[0], s1[0], s0[1], s1[1])
        q0, q1, q2 = _add2(s0[2], s1[2], s0[3], s1[3])
        cb[0], cb[1], cb[2], cb[3] = _add3(p0, p1, p2, q0, q1, q2)


@njit(inline="always", cache=True)
def _digit(D, w, cls, k, mode, cb, s0, s1, tmp):
    """Digit word of the replicas' probabilities: bit ``r`` is ``D[w, cls, k, leaf_r]``'s.

    ``mode`` 0: leaf = total count 0..4 (bit planes ``cb``; plane 2 set only for 4);
    1: total count 0..8 (plane 3 only for 8); 2: per-type counts in base 3 (a count's
    planes ``s0, s1`` are exclusive, so a base-3 digit takes two multiplexers).
    """
    if mode == 0:
        lo = _mux(_mux(D[w, cls, k, 0], D[w, cls, k, 1], cb[0]),
                  _mux(D[w, cls, k, 2], D[w, cls, k, 3], cb[0]), cb[1])
        return _mux(lo, D[w, cls, k, 4], cb[2])
    if mode == 1:
        a = _mux(_mux(D[w, cls, k, 0], D[w, cls, k, 1], cb[0]),
                 _mux(D[w, cls, k, 2], D[w, cls, k, 3], cb[0]), cb[1])
        b = _mux(_mux(D[w, cls, k, 4], D[w, cls, k, 5], cb[0]),
                 _mux(D[w, cls, k, 6], D[w, cls, k, 7], cb[0]), cb[1])
        return _mux(_mux(a, b, cb[2]), D[w, cls, k, 8], cb[3])
    n = D.shape[3]
    for j in range(n):
        tmp[j] = D[w, cls, k, j]
    for t in range(s0.size):  # fold the lowest base-3 digit: type t's count
        n //= 3
        for j in range(n):
            tmp[j] = _mux(_mux(tmp[3 * j], tmp[3 * j + 1], s0[t]), tmp[3 * j + 2], s1[t])
    return tmp[0]


@njit(inline="always", cache=True)
def _leaf(r, mode, cb, s0, s1) -> int:
    """Replica ``r``'s table leaf (what :func:`_digit` selects for bit ``r``)."""
    one = np.uint64(1)
    if mode < 2:
        leaf = 0
        for b in range(3 + mode):
            leaf += np.int64((cb[b] >> np.uint64(r)) & one) << b
        return leaf
    leaf, base = 0, 1
    for t in range(s0.size):
        leaf += base * np.int64(((s0[t] >> np.uint64(r)) & one)
                                + np.uint64(2) * ((s1[t] >> np.uint64(r)) & one))
        base *= 3
    return leaf


@njit(inline="always", cache=True)
def _fixed(logit: float) -> np.uint64:
    """``floor(2^64 p)`` (at most ``2^64 - 1``) of ``p = 1 / (1 + exp(-logit))``."""
    p = 1.0 / (1.0 + np.exp(-logit))
    if p >= 1.0:
        return np.uint64(0xFFFFFFFFFFFFFFFF)
    return np.uint64(p * _TWO64)


@njit(inline="always", cache=True)
def _site_class(r, c, H, W, periodic) -> int:
    """Boundary class 0..15: which of the four borders the site lies on (0 if periodic)."""
    if periodic:
        return 0
    return ((r == 0) + 2 * (r == H - 1)) * 4 + (c == 0) + 2 * (c == W - 1)


@njit(cache=True)
def _row(xp, w, r, c0, base, D, G, field, active, offsets, periodic, mode, key,
         s0, s1, cb, tmp) -> None:
    """Scalar heat-bath update of sites ``c0, c0 + 2, ...`` of row ``r`` of word ``w``: per
    edge type tables (mode 2), or per-node fields (one 64-bit uniform per replica)."""
    H, W = xp.shape[1] - 2, xp.shape[2] - 2
    for c in range(c0, W, 2):
        _count(xp, w, r + 1, c + 1, offsets, s0, s1, cb)
        cls = _site_class(r, c, H, W, periodic)
        ctr = (base + np.uint64(c)) * np.uint64(64)
        res = _ZERO
        if field.shape[0] > 0:
            for rr in range(64):
                if (active[w] >> np.uint64(rr)) & _ONE:
                    lg = field[w * 64 + rr, r, c] + G[w, cls, _leaf(rr, mode, cb, s0, s1), rr]
                    if _word(key, ctr + np.uint64(rr)) < _fixed(lg):
                        res |= _ONE << np.uint64(rr)
        else:
            und = active[w]
            for k in range(64):
                d = _digit(D, w, cls, k, mode, cb, s0, s1, tmp)
                diff = (_word(key, ctr + np.uint64(k)) ^ d) & und
                res |= diff & d  # decided here: U < p where p's digit is the 1
                und &= ~diff
                if und == _ZERO:
                    break  # undecided after 64 digits: U >= floor(2^64 p) / 2^64, spin 0
        xp[w, r + 1, c + 1] = res


@njit(inline="always", cache=True)
def _select(D, w, cls, k, eight, p0, p1, p2, p3):
    """Digit ``k`` word for total counts in bit planes ``p0..p3`` (:func:`_digit`, modes 0, 1)."""
    lo = _mux(_mux(D[w, cls, k, 0], D[w, cls, k, 1], p0),
              _mux(D[w, cls, k, 2], D[w, cls, k, 3], p0), p1)
    if not eight:
        return _mux(lo, D[w, cls, k, 4], p2)
    hi = _mux(_mux(D[w, cls, k, 4], D[w, cls, k, 5], p0),
              _mux(D[w, cls, k, 6], D[w, cls, k, 7], p0), p1)
    return _mux(_mux(lo, hi, p2), D[w, cls, k, 8], p3)


@njit(cache=True)
def _finish(D, w, cls, k0, eight, j, planes, rnd, und, res, key, ctr) -> None:
    """Digits ``k0, k0 + 1, ...`` of site ``j`` until every replica is decided."""
    u_, r_ = und[j], res[j]
    for k in range(k0, 64):
        if u_ == _ZERO:
            break
        d = _select(D, w, cls, k, eight, planes[0, j], planes[1, j], planes[2, j],
                    planes[3, j])
        u = rnd[k, j] if k < AHEAD else _word(key, ctr + np.uint64(k))
        diff = (u ^ d) & u_
        r_ |= diff & d
        u_ &= ~diff
    und[j], res[j] = u_, r_


@njit(cache=True)
def _row_iso(xp, w, r, c0, base, D, active, periodic, eight, key, planes, rnd, und,
             res) -> None:
    """Heat-bath update of sites ``c0, c0 + 2, ...`` of row ``r`` of word ``w`` with one
    coupling (total counts): counts, random words and the first :data:`AHEAD` digits
    in loops over the row's sites (vectorisable), then the undecided sites one by one."""
    H, W = xp.shape[1] - 2, xp.shape[2] - 2
    n, R = (W - c0 + 1) // 2, r + 1
    for j in range(n):
        C = c0 + 2 * j + 1
        a, b, e, f = xp[w, R, C - 1], xp[w, R, C + 1], xp[w, R - 1, C], xp[w, R + 1, C]
        p0, p1, p2 = _add2(a ^ b, a & b, e ^ f, e & f)
        p3 = _ZERO
        if eight:
            a, b, e, f = xp[w, R - 1, C - 1], xp[w, R + 1, C + 1], xp[w, R - 1, C + 1], \
                xp[w, R + 1, C - 1]
            q0, q1, q2 = _add2(a ^ b, a & b, e ^ f, e & f)
            p0, p1, p2, p3 = _add3(p0, p1, p2, q0, q1, q2)
        planes[0, j], planes[1, j], planes[2, j], planes[3, j] = p0, p1, p2, p3
        und[j], res[j] = active[w], _ZERO
    for k in range(AHEAD):
        for j in range(n):
            rnd[k, j] = _word(key, (base + np.uint64(c0 + 2 * j)) * np.uint64(64)
                              + np.uint64(k))
    cls = _site_class(r, 1, H, W, periodic) if W > 2 else 0  # an inner column's class
    for k in range(AHEAD):
        for j in range(n):
            d = _select(D, w, cls, k, eight, planes[0, j], planes[1, j], planes[2, j],
                        planes[3, j])
            diff = (rnd[k, j] ^ d) & und[j]  # decided here: U < p where p's digit is the 1
            res[j] |= diff & d
            und[j] &= ~diff
    for j in range(n):
        c = c0 + 2 * j
        ctr = (base + np.uint64(c)) * np.uint64(64)
        own = _site_class(r, c, H, W, periodic)
        if own != cls:  # a border column: its own table, from the first digit
            und[j], res[j] = active[w], _ZERO
            _finish(D, w, own, 0, eight, j, planes, rnd, und, res, key, ctr)
        elif und[j] != _ZERO:
            _finish(D, w, cls, AHEAD, eight, j, planes, rnd, und, res, key, ctr)
        xp[w, r + 1, c + 1] = res[j]  # undecided after 64 digits: U >= p_fix / 2^64, spin 0


@njit(cache=True)
def _ghosts(xp) -> None:
    """Refresh the periodic ghost border (rows, then columns, which fills the corners)."""
    H, W = xp.shape[1] - 2, xp.shape[2] - 2
    for w in range(xp.shape[0]):
        for c in range(1, W + 1):
            xp[w, 0, c], xp[w, H + 1, c] = xp[w, H, c], xp[w, 1, c]
        for r in range(H + 2):
            xp[w, r, 0], xp[w, r, W + 1] = xp[w, r, W], xp[w, r, 1]


@njit(cache=True, parallel=True)
def sweeps(xp, D, G, field, active, offsets, periodic, mode, key, slot, out) -> None:
    """``slot.size`` checkerboard sweeps of the packed spins ``xp`` (n_words, H + 2, W + 2)
    with a ghost border (zeros: free boundary; else the wrap, kept by :func:`_ghosts`).

    Colour classes in the order of :mod:`mrfpe.models.graph`'s lattice colourings:
    ``(r + c) % 2`` (4-neighbour), ``2 (r % 2) + c % 2`` (8-neighbour); rows of a class
    in parallel. After sweep ``s`` the state is stored in ``out[slot[s]]`` if that is
    ``>= 0``. ``D`` (n_words, classes, 64, leaves) holds probability digits (site-shared
    fields), else ``G`` (n_words, classes, leaves, 64) the logits without the per-node
    ``field`` (n_words * 64, H, W).
    """
    nw, H, W = xp.shape[0], xp.shape[1] - 2, xp.shape[2] - 2
    T, n_colours = offsets.shape[0], 2 if offsets.shape[0] == 2 else 4
    fast = field.shape[0] == 0 and mode < 2
    n_leaves = D.shape[3] if D.shape[0] > 0 else G.shape[2]
    if periodic:
        _ghosts(xp)
    for s in range(slot.size):
        for col in range(n_colours):
            rows = H if n_colours == 2 else (H - col // 2 + 1) // 2
            for job in prange(nw * rows):
                w, j = job // rows, job % rows
                r = j if n_colours == 2 else col // 2 + 2 * j
                c0 = (col + r) % 2 if n_colours == 2 else col % 2
                base = ((np.uint64(s) * np.uint64(nw) + np.uint64(w)) * np.uint64(H)
                        + np.uint64(r)) * np.uint64(W)
                if fast:
                    m = (W + 1) // 2
                    _row_iso(xp, w, r, c0, base, D, active, periodic, mode == 1, key,
                             np.empty((4, m), np.uint64), np.empty((AHEAD, m), np.uint64),
                             np.empty(m, np.uint64), np.empty(m, np.uint64))
                else:
                    _row(xp, w, r, c0, base, D, G, field, active, offsets, periodic, mode,
                         key, np.empty(T, np.uint64), np.empty(T, np.uint64),
                         np.empty(4, np.uint64), np.empty(n_leaves, np.uint64))
            if periodic:
                _ghosts(xp)
        if slot[s] >= 0:
            out[slot[s]] = xp[:, 1:H + 1, 1:W + 1]
