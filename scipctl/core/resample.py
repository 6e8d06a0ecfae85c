"""Sub-pixel image resampling at exact float coordinates (pure numerics).

Pixel convention (docs/conventions.md): ``(u, v)`` = (column, row), 0-based,
``(0, 0)`` is the centre of the top-left pixel; an image is indexed
``img[v, u]``.

Why not ``cv2.remap`` / ``cv2.warpAffine``: OpenCV 4.x rounds every sampling
position to 1/32 px (fixed-point interpolation tables, ``INTER_BITS = 5``)
while OpenCV 5.x uses the exact position, so the same call differs by up to
~0.5 % of the image's range between builds (measured: 0.0021 on a unit-range
texture). The NCC sub-pixel refinement and the stereo slant refinement
evaluate windows at positions 1/4 px apart and fit a peak to them; their
answers then moved by tenths of a pixel with the OpenCV build. Here the
weights are computed in float64 from the exact position, the same on every
build.

Kernels: bilinear, and the cubic convolution kernel of Keys (1981) with
``a = -0.75`` (OpenCV's ``INTER_CUBIC``). Outside the image the border pixel
is repeated (OpenCV's ``BORDER_REPLICATE``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["CUBIC_A", "sample_bilinear", "sample_bicubic", "sample_bicubic_uv", "sample_bicubic_grid",
           "sample_bicubic_grids", "cubic_axis", "cubic_weights", "shifted_image"]

#: the cubic kernel's parameter (OpenCV's INTER_CUBIC uses -0.75)
CUBIC_A = -0.75


def _check(image, u, v):
    img = np.asarray(image)
    if img.ndim != 2 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"image: expected a non-empty (H, W) array, got shape {img.shape}")
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if u.shape != v.shape:
        raise ValueError(f"u, v: expected the same shape, got {u.shape} and {v.shape}")
    if not (np.isfinite(u).all() and np.isfinite(v).all()):
        raise ValueError("u, v: sampling positions must be finite")
    return img, u, v


_OFFSETS = np.arange(-1, 3)  # the cubic kernel's taps around floor(x)


def _clip(i: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """``np.clip`` of integer indices without its Python-level overhead (called per sampled window)."""
    return np.minimum(np.maximum(i, lo), hi)


def cubic_weights(t: np.ndarray, a: float = CUBIC_A) -> np.ndarray:
    """Weights ``(..., 4)`` of the samples at offsets -1, 0, 1, 2 for fractional positions ``t`` ``(...)`` in [0, 1).

    They sum to 1 for every ``t`` and give the sample itself at ``t = 0``.
    """
    t = np.asarray(t, dtype=np.float64)
    w = np.empty(t.shape + (4,))
    # the kernel's two pieces, written out (the same operations in the same order as before):
    # near(x) = ((a + 2) x - (a + 3)) x x + 1 for |x| <= 1, far(x) = ((a x - 5 a) x + 8 a) x - 4 a for 1 < |x| < 2
    x = 1 + t
    w0 = ((a * x - 5 * a) * x + 8 * a) * x - 4 * a
    w1 = ((a + 2) * t - (a + 3)) * t * t + 1
    x = 1 - t
    w2 = ((a + 2) * x - (a + 3)) * x * x + 1
    w[..., 0], w[..., 1], w[..., 2] = w0, w1, w2
    w[..., 3] = 1.0 - w0 - w1 - w2
    return w


def sample_bilinear(image, u, v) -> np.ndarray:
    """``image`` ``(H, W)`` sampled bilinearly at ``(u, v)`` (two arrays of one shape); float64, that shape."""
    img, u, v = _check(image, u, v)
    H, W = img.shape
    uf, vf = np.floor(u), np.floor(v)
    fu, fv = u - uf, v - vf
    i0, j0 = uf.astype(np.int64), vf.astype(np.int64)
    i = np.clip(np.stack([i0, i0 + 1]), 0, W - 1)
    j = np.clip(np.stack([j0, j0 + 1]), 0, H - 1)
    def at(jj, ii):  # gather first, then widen: the image itself is not copied
        return img[jj, ii].astype(np.float64)

    top = (1 - fu) * at(j[0], i[0]) + fu * at(j[0], i[1])
    bot = (1 - fu) * at(j[1], i[0]) + fu * at(j[1], i[1])
    return (1 - fv) * top + fv * bot


def sample_bicubic(image, u, v) -> np.ndarray:
    """``image`` ``(H, W)`` sampled by cubic convolution (``a = -0.75``) at ``(u, v)``; float64, their shape."""
    img, u, v = _check(image, u, v)
    H, W = img.shape
    uf, vf = np.floor(u), np.floor(v)
    wu = cubic_weights(u - uf)  # (..., 4)
    wv = cubic_weights(v - vf)
    iu = _clip(uf.astype(np.int64)[..., None] + _OFFSETS, 0, W - 1)  # (..., 4)
    jv = _clip(vf.astype(np.int64)[..., None] + _OFFSETS, 0, H - 1)
    if img.flags.c_contiguous:  # the same pixels gathered through flat indices (faster than 2-D fancy indexing)
        g = img.take(jv[..., :, None] * W + iu[..., None, :]).astype(np.float64)  # (..., 4 rows, 4 columns)
    else:
        g = img[jv[..., :, None], iu[..., None, :]].astype(np.float64)
    return np.einsum("...r,...rc,...c->...", wv, g, wu)


def _cubic_weights_taps_first(t: np.ndarray, a: float = CUBIC_A) -> np.ndarray:
    """:func:`cubic_weights` of ``t`` ``(...)`` laid out taps first, ``(4, ...)``: its expressions, operation for
    operation (in place where they were temporaries, and the near piece of taps 1 and 2 in one pass)."""
    w = np.empty((4,) + t.shape)
    x = 1 + t
    w0 = w[0]  # ((a x - 5 a) x + 8 a) x - 4 a
    np.multiply(a, x, out=w0)
    w0 -= 5 * a
    w0 *= x
    w0 += 8 * a
    w0 *= x
    w0 -= 4 * a
    near = w[1:3]  # ((a + 2) x - (a + 3)) x x + 1 at x = t and x = 1 - t
    near[0] = t
    np.subtract(1, t, out=near[1])
    y = (a + 2) * near
    y -= a + 3
    y *= near
    y *= near
    y += 1
    near[...] = y
    np.subtract(1.0, w0, out=w[3])  # 1 - w0 - w1 - w2
    w[3] -= w[1]
    w[3] -= w[2]
    return w


def _sum_terms(terms: np.ndarray) -> np.ndarray:
    """The sum over the first axis of ``terms`` ``(16, n)`` taken one term after the other from 0, as
    ``numpy.einsum`` sums :func:`sample_bicubic`'s terms: ``np.add.reduce`` over the outer axis adds whole rows in
    turn (from the first row instead of 0: the ``+ 0.0`` turns the one possible difference, a sum of -0.0 terms,
    into einsum's +0.0). With one column numpy would sum the column pairwise: then a plain loop."""
    if terms.shape[1] >= 2:
        return np.add.reduce(terms, axis=0) + 0.0
    out = np.zeros(terms.shape[1:])
    for k in range(terms.shape[0]):
        out += terms[k]
    return out


def sample_bicubic_uv(image, uv) -> np.ndarray:
    """``image`` ``(H, W)`` sampled by cubic convolution at ``uv`` ``(2, ...)`` (``u`` then ``v`` stacked): float64
    ``(...)``, bit for bit :func:`sample_bicubic` ``(image, uv[0], uv[1])``.

    For the hot loops that sample one small window per call (affine point stereo's Nelder-Mead, hundreds of
    windows per match). The same operations on the same numbers, laid out taps first (``(4, 2, n)`` weights
    and indices, ``(4 rows, 4 columns, n)`` pixels) so that each is one numpy call over long rows, both axes
    at once: the weights are :func:`cubic_weights`' expressions, and each output sums the 16 terms
    ``(wv[r] * pixel[r, c]) * wu[c]`` one after the other from 0, ``r`` outer and ``c`` inner, which is what
    ``numpy.einsum`` does in :func:`sample_bicubic` (``tests/core/test_resample.py`` compares them bit for bit
    on random inputs).
    """
    img = np.asarray(image)
    if img.ndim != 2 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"image: expected a non-empty (H, W) array, got shape {img.shape}")
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim < 1 or uv.shape[0] != 2:
        raise ValueError(f"uv: expected a (2, ...) array, got shape {uv.shape}")
    shape = uv.shape[1:]
    uv = uv.reshape(2, -1)
    if not np.isfinite(uv).all():
        raise ValueError("u, v: sampling positions must be finite")
    H, W = img.shape
    f = np.floor(uv)
    t = uv - f
    w = _cubic_weights_taps_first(t)  # (4 taps, 2 axes, n)
    i = f.astype(np.int64) + _OFFSETS[:, None, None]  # (4, 2, n): tap columns, tap rows
    i = np.minimum(np.maximum(i, 0), np.array([[W - 1], [H - 1]]))
    if img.flags.c_contiguous:
        g = img.take((i[:, 1] * W)[:, None, :] + i[None, :, 0]).astype(np.float64)  # (4 rows, 4 columns, n)
    else:
        g = img[i[:, None, 1], i[None, :, 0]].astype(np.float64)
    g *= w[:, None, 1]  # wv[r] * pixel[r, c]
    g *= w[None, :, 0]  # (...) * wu[c]
    return _sum_terms(g.reshape(16, -1)).reshape(shape)


def cubic_axis(x, n: int) -> tuple:
    """The cubic-convolution taps of positions ``x`` ``(m,)`` along an axis of ``n`` samples: weights ``(m, 4)``
    (:func:`cubic_weights`) and tap indices ``(m, 4)`` clipped to ``[0, n - 1]``, computed as
    :func:`sample_bicubic` computes them."""
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    if not np.isfinite(x).all():
        raise ValueError("u, v: sampling positions must be finite")
    xf = np.floor(x)
    return cubic_weights(x - xf), _clip(xf.astype(np.int64)[:, None] + _OFFSETS, 0, n - 1)


def sample_bicubic_grid(image, u, v) -> np.ndarray:
    """``image`` ``(H, W)`` sampled by cubic convolution on the grid of columns ``u`` and rows ``v``: ``(h, w)``
    float64, bit for bit :func:`sample_bicubic` ``(image, U, V)`` with ``U, V = np.meshgrid(u, v)``.

    ``u`` is the columns' positions ``(w,)`` or their taps ``cubic_axis(u, W)``, ``v`` the rows' ``(h,)`` or
    ``cubic_axis(v, H)`` (a caller sampling several grids that share columns or rows computes them once).
    A grid's weights and indices depend on its column or its row only: they are computed per column and per
    row (the same operations on the same numbers) and then laid out as :func:`sample_bicubic` lays them out,
    so that its final sum runs on identical arrays.
    """
    img = np.asarray(image)
    if img.ndim != 2 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"image: expected a non-empty (H, W) array, got shape {img.shape}")
    H, W = img.shape
    wu1, iu = u if isinstance(u, tuple) else cubic_axis(u, W)
    wv1, jv = v if isinstance(v, tuple) else cubic_axis(v, H)
    h, w = len(wv1), len(wu1)
    wu = np.ascontiguousarray(np.broadcast_to(wu1, (h, w, 4)))
    wv = np.ascontiguousarray(np.broadcast_to(wv1[:, None, :], (h, w, 4)))
    # the pixels (h, w, 4 rows, 4 columns): the tap rows, then their tap columns (a C-ordered float64 copy)
    g = img[jv.reshape(-1)][:, iu.reshape(-1)].reshape(h, 4, w, 4).transpose(0, 2, 1, 3).astype(np.float64, order="C")
    return np.einsum("...r,...rc,...c->...", wv, g, wu)


def sample_bicubic_grids(image, u, v) -> np.ndarray:
    """``image`` ``(H, W)`` sampled by cubic convolution on every grid of one set of columns ``u[a]`` and one set
    of rows ``v[b]``: ``u`` ``(A, w)`` and ``v`` ``(B, h)`` positions; returns ``(B, A, h, w)`` float64 with
    ``[b, a]`` bit for bit :func:`sample_bicubic_grid` ``(image, u[a], v[b])`` (the NCC peak refinement samples
    a 3 x 3 set of shifted windows at once).

    :func:`sample_bicubic` sums, per output, the 16 terms ``(wv[r] * pixel[r, c]) * wu[c]`` one after the other
    (``r`` outer, ``c`` inner, from 0; ``numpy.einsum``'s order). Here the same terms are summed in the same
    order, but the first product ``wv[r] * pixel`` is computed once per tap row and image column (its value does
    not depend on which output or column shift uses it) and the sum runs over whole arrays (the terms' slices
    added in turn, see ``_sum_terms``), not per output. ``tests/core/test_resample.py`` compares it with :func:`sample_bicubic_grid` bit for
    bit.
    """
    img = np.asarray(image)
    if img.ndim != 2 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"image: expected a non-empty (H, W) array, got shape {img.shape}")
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if u.ndim != 2 or v.ndim != 2:
        raise ValueError(f"u, v: expected (A, w) and (B, h) arrays, got shapes {u.shape} and {v.shape}")
    H, W = img.shape
    (A, w), (B, h) = u.shape, v.shape
    wu, iu = cubic_axis(u, W)  # (A w, 4)
    wv, jv = cubic_axis(v, H)  # (B h, 4)
    # the tap rows (4 r, B h, W) in float64, each times its weight: wv[r] * pixel[r, column]
    q = img[jv.T.reshape(-1)].astype(np.float64).reshape(4, B * h, W)
    q *= wv.T[:, :, None]
    # every term: (4 r, B h, 4 c, A w) = (wv[r] * pixel[r, c]) * wu[c]
    p = np.take(q, iu.T.reshape(4, A * w), axis=2)
    p *= wu.T
    if A * w >= 2:  # numpy adds the (B h, A w) slices in turn, r outer, c inner (as _sum_terms)
        out = np.add.reduce(p, axis=(0, 2)) + 0.0
    else:
        out = np.zeros((B * h, A * w))
        for r in range(4):
            for c in range(4):
                out += p[r, :, c]
    return np.ascontiguousarray(out.reshape(B, h, A, w).transpose(0, 2, 1, 3))


def shifted_image(image, shift_uv) -> np.ndarray:
    """``image`` ``(H, W)`` translated by ``-shift_uv`` ``(2,)`` px: ``out[v, u] = image(u + du, v + dv)`` by cubic
    convolution, ``(H, W)`` float64, the border repeated. Separable (rows, then columns): the same values as
    :func:`sample_bicubic` on the shifted grid up to rounding, at a fraction of its memory."""
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 2 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"image: expected a non-empty (H, W) array, got shape {img.shape}")
    d = np.asarray(shift_uv, dtype=np.float64)
    if d.shape != (2,) or not np.isfinite(d).all():
        raise ValueError(f"shift_uv: expected a finite (2,), got {shift_uv!r}")
    H, W = img.shape
    wv, jv = cubic_axis(np.arange(H) + d[1], H)  # (H, 4) each
    rows = np.einsum("hk,hkw->hw", wv, img[jv])
    wu, iu = cubic_axis(np.arange(W) + d[0], W)  # (W, 4) each
    return np.einsum("wk,hwk->hw", wu, rows[:, iu])
