"""Exact overlaps of equirectangular pixels with cubemap texels.

Everything happens in the *texture* frame (``tex = R @ world``), where the pixels form a
latitude-longitude grid: pixel ``(i, j)`` covers ``z = cos(theta)`` in ``[z_{i+1}, z_i]``,
``z_i = cos(i pi / H)``, and the azimuth ``phi`` in ``[pi - 2 pi (j+1)/W, pi - 2 pi j/W]``
(``u = 0.5 - phi / 2 pi``).  The map ``(phi, z)`` is equal-area (``dw = dphi dz``): a
solid angle is an area in that plane.  A texel turned into the texture frame is a convex
quadrilateral bounded by four great circles.

A great circle with unit normal ``m`` (``m_z != 0``) meets every meridian once.  With
``rho = |m_xy|``, ``a`` the azimuth of its highest point and ``d = phi - a``, its height is

    z_e(d) = rho cos d / sqrt(cos^2 d + m_z^2 sin^2 d),    int z_e dd = asin(rho sin d),

it lies above the latitude ``z = c`` exactly on ``|d| < acos(c |m_z| / (rho sin theta_c))``,
and a point on it at ``d`` is ``psi = atan2(|m_z| sin d, cos d)`` along it from the top.
So the area of a column part ``[d0, d1]`` between the latitude ``c`` and the curve, and its
first moment ``int w dw = 1/2 oint w x dw`` (a latitude arc, two meridian arcs and the
curve, each in closed form: a great-circle arc gives its normal times its angle), are exact.

On every meridian a texel is one arc.  An edge whose inward normal points down bounds the
texel from above, one pointing up bounds it from below, and an edge through the poles
(``m_z = 0``) bounds only its azimuths.  So the overlap of texel T with any region is

    sum over T's upper edges of (the region below the edge, over the edge's azimuths)
  - sum over T's lower edges of (the same)      [+ the whole columns over T's azimuths when
                                                  T holds the north pole].

Per edge and pixel column the region below the edge is, in the rows the curve crosses, the
closed forms above and, below them, whole rows read from per-column suffix sums of ``L dz``
(:class:`ImageSums`, kept per image: turning the world only redoes the geometry).  Each
edge is computed once for both of its texels, so the texel energies add up to the image's
and every pixel's weights to its solid angle.  All is exact up to floating-point rounding
(a constant image resamples to within 1e-10); as a texel's energy is a difference of edge
sums, energies below ``1e-12`` of those sums (their rounding) are taken as zero, so a dark
texel stays exactly dark.  Texel edges passing within ``1e-12`` of a texture pole are taken
through it and vertices within ``1e-10`` are put on it (errors below 1e-8 there).
"""

from __future__ import annotations

import numpy as np

from ..common.cache import memo
from .directions import FACE_AXES

_TWO_PI = 2.0 * np.pi
#: A rotated texel vertex closer than this (radians) to a texture pole is put on it.
SNAP_VERTEX = 1e-10
#: A texel edge whose normal has |n_z| below this passes through the poles (a meridian).
SNAP_FLAT = 1e-12
#: Relative size, against the edge sums it is made of, below which a texel's energy is zero.
ZERO_TOL = 1e-12
#: Edge-column segments handled at once (bounds the temporaries).
CHUNK = 100_000
#: Bytes of per-column sums kept per image (all rows up to 2.4 M pixels, 1024 x 2048).
SUMS_BUDGET = 96 * 2**20
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


# --------------------------------------------------------------------------- geometry
@memo(4)
def cube_topology(n: int):
    """The texel grid of a ``6 n^2`` cubemap as a mesh on the sphere (world frame).

    Returns ``(vertices (V, 3) unit, edges (E, 2) vertex ids, texel_edges (6n^2, 4) edge
    ids, centres (6n^2, 3))``; a vertex or edge shared by two faces is one entry."""
    e = 2 * np.arange(n + 1) - n                          # face coordinate * n (integers)
    t, s = np.meshgrid(e, e, indexing="ij")
    ax = FACE_AXES.astype(np.int64)
    lat = (n * ax[:, None, None, 0, :] + s[None, :, :, None] * ax[:, None, None, 1, :]
           + t[None, :, :, None] * ax[:, None, None, 2, :])              # (6, n+1, n+1, 3)
    keys, vid = np.unique(lat.reshape(-1, 3), axis=0, return_inverse=True)
    vid = vid.reshape(6, n + 1, n + 1)
    verts = keys / np.linalg.norm(keys, axis=1, keepdims=True)
    corners = np.stack([vid[:, :-1, :-1], vid[:, :-1, 1:], vid[:, 1:, 1:], vid[:, 1:, :-1]],
                       axis=-1).reshape(-1, 4)
    pairs = np.stack([corners, np.roll(corners, -1, axis=1)], axis=-1).reshape(-1, 2)
    edges, eid = np.unique(np.sort(pairs, axis=1), axis=0, return_inverse=True)
    c = (2 * np.arange(n) + 1 - n) / n
    t, s = np.meshgrid(c, c, indexing="ij")
    centres = (FACE_AXES[:, None, None, 0, :] + s[None, :, :, None] * FACE_AXES[:, None, None, 1, :]
               + t[None, :, :, None] * FACE_AXES[:, None, None, 2, :]).reshape(-1, 3)
    out = (verts, edges, eid.reshape(-1, 4), centres)
    for a in out:
        a.setflags(write=False)
    return out


def _rows(h: int):
    """Row edges k = 0..H: ``z_k``, ``sin(theta_k)``, ``theta_k`` (exact at the poles)."""
    th = np.arange(h + 1) * (np.pi / h)
    z, s = np.cos(th), np.sin(th)
    z[0], z[-1], s[0], s[-1] = 1.0, -1.0, 0.0, 0.0
    return z, s, th


def edge_geometry(n: int, rotation):
    """The cubemap's edges turned into the texture frame.

    Returns a dict: per edge ``apex``, ``rho``, ``nz`` (``|m_z|``) of its great circle,
    ``phi0 <= phi1`` (its azimuths, unwrapped), ``curved`` (False: through the poles);
    per texel and side ``coef`` (+1 the edge bounds it from above, -1 from below, 0 through
    the poles) and ``north`` (the texel holds the north pole)."""
    R = np.asarray(rotation, dtype=np.float64)
    verts, edges, tedges, centres = cube_topology(n)
    V = verts @ R.T
    pole = np.hypot(V[:, 0], V[:, 1]) < SNAP_VERTEX
    V[pole, 2] = np.sign(V[pole, 2])
    V[pole, :2] = 0.0
    P, Q = V[edges[:, 0]], V[edges[:, 1]]
    m = np.cross(P, Q)
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    mz = np.where(np.abs(m[:, 2]) < SNAP_FLAT, 0.0, m[:, 2])
    curved = mz != 0.0
    sg = -np.sign(mz)
    apex = np.arctan2(sg * m[:, 1], sg * m[:, 0])          # azimuth of the highest point
    # A vertex near a pole has an ill-conditioned azimuth; on a meridian edge it takes that
    # of the edge's far end (or its opposite, across the pole), so that the texels on both
    # sides of the meridian meet exactly.
    az = np.arctan2(V[:, 1], V[:, 0])
    r = np.hypot(V[:, 0], V[:, 1])
    ends = edges[~curved & ~pole[edges].any(axis=1)]
    swap = r[ends[:, 0]] > r[ends[:, 1]]
    near = np.where(swap, ends[:, 1], ends[:, 0])
    far = np.where(swap, ends[:, 0], ends[:, 1])
    az[near] = az[far] + np.pi * np.round((az[near] - az[far]) / np.pi)
    a0, a1 = az[edges[:, 0]], az[edges[:, 1]]
    a1 = a1 + _TWO_PI * np.round((a0 - a1) / _TWO_PI)      # the short way round
    cen = centres @ R.T
    inward = np.sign(np.einsum("tkc,tc->tk", m[tedges], cen))
    coef = -np.sign(inward * mz[tedges])                    # +1: the texel lies below the edge
    return dict(apex=apex, rho=np.hypot(m[:, 0], m[:, 1]), nz=np.abs(mz), curved=curved,
                phi0=np.minimum(a0, a1), phi1=np.maximum(a0, a1), coef=coef,
                north=~(coef > 0).any(axis=1), texel_edges=tedges)


def _column_pieces(phi0, phi1, w: int):
    """Split azimuth ranges at the pixel columns: (range index, column, phi_lo, phi_hi)."""
    x0 = w * (0.5 - phi1 / _TWO_PI)
    x1 = w * (0.5 - phi0 / _TWO_PI)
    j0 = np.floor(x0).astype(np.int64)
    cnt = np.maximum(np.ceil(x1).astype(np.int64) - j0, 1)
    idx = np.repeat(np.arange(len(x0)), cnt)
    j = j0[idx] + (np.arange(len(idx)) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    xa = np.maximum(x0[idx], j)
    xb = np.minimum(x1[idx], j + 1)
    keep = xb > xa
    idx, j, xa, xb = idx[keep], j[keep], xa[keep], xb[keep]
    return idx, np.mod(j, w), np.pi - (_TWO_PI / w) * xb, np.pi - (_TWO_PI / w) * xa


def _row_of(z, h: int):
    return np.clip((np.arccos(np.clip(z, -1.0, 1.0)) * (h / np.pi)).astype(np.int64), 0, h - 1)


def _ends(d, ca, sa, rho, nz):
    """The curve at offsets ``d`` from its apex (d in [-pi, pi]): [offset, its integral Z,
    position psi along it, polar angle theta, cos and sin of the azimuth, height z]."""
    cd, sd = np.cos(d), np.sin(d)
    D = np.sqrt(cd * cd + nz * nz * sd * sd)
    rc = rho * cd
    return [d, np.arctan2(rho * sd, D), np.arctan2(nz * sd, cd), np.arctan2(nz, rc),
            ca * cd - sa * sd, sa * cd + ca * sd, rc / D]


def _lowest(ca, sa, rho, nz, sign):
    """:func:`_ends` at d = sign * pi (the curve's lowest point), exactly."""
    one = np.ones_like(rho)
    return [sign * np.pi * one, 0.0 * one, sign * np.pi * one, np.arctan2(nz, -rho), -ca, -sa,
            -rho]


def _region(lo, hi, ca, sa, rho, nz, c, s, th):
    """Area and first moment of ``{d in [lo_d, hi_d], c <= z <= z_e(d)}`` for latitudes
    ``c`` (``s = sin theta_c``, ``th = theta_c``), ``lo``/``hi`` from :func:`_ends`."""
    # the curve is above c on |d| < beta; (k, sb) = (cos, sin) beta
    den = rho * s
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.where(den > 0, c * nz / np.where(den > 0, den, 1.0), np.sign(c) * np.inf)
    k = np.clip(k, -1.0, 1.0)
    sb = np.sqrt(1.0 - k * k)
    Zb = np.arctan2(rho * sb, np.sqrt(k * k + nz * nz * sb * sb))
    psib = np.arctan2(nz * sb, k)
    beta = np.arccos(k)
    use_lo = lo[0] >= -beta           # p = max(lo_d, -beta), q = min(hi_d, beta)
    use_hi = hi[0] <= beta
    p_d = np.where(use_lo, lo[0], -beta)
    q_d = np.where(use_hi, hi[0], beta)
    some = q_d > p_d
    dd = np.where(some, q_d - p_d, 0.0)
    area = np.where(some, np.where(use_hi, hi[1], Zb) - np.where(use_lo, lo[1], -Zb), 0.0) - c * dd
    dpsi = np.where(some, np.where(use_hi, hi[2], psib) - np.where(use_lo, lo[2], -psib), 0.0)
    # 1/2 of the boundary integral of w x dw: latitude c from p to q, meridian at q from c up
    # to the curve, the curve back to p (its normal times the angle), meridian at p down to c
    p_c = np.where(use_lo, lo[4], ca * k + sa * sb)
    p_s = np.where(use_lo, lo[5], sa * k - ca * sb)
    q_c = np.where(use_hi, hi[4], ca * k - sa * sb)
    q_s = np.where(use_hi, hi[5], sa * k + ca * sb)
    dth_q = np.where(use_hi & some, hi[3] - th, 0.0)
    dth_p = np.where(use_lo & some, th - lo[3], 0.0)
    cr = np.where(some, c * s, 0.0)
    mom = 0.5 * np.stack([-cr * (q_s - p_s) - q_s * dth_q - p_s * dth_p + rho * ca * dpsi,
                          cr * (q_c - p_c) + q_c * dth_q + p_c * dth_p + rho * sa * dpsi,
                          s * s * dd - nz * dpsi], axis=1)
    return area, mom


# --------------------------------------------------------------------------- image side
class ImageSums:
    """What the resampling needs of an equirect image, whatever the rotation: the pixels
    (flat, float32) and per column the suffix sums over rows ``i >= k`` of ``L dz`` (RGB),
    ``Y int sqrt(1 - z^2) dz`` and ``Y int z dz`` (Y the luminance) in float64, 40 bytes a
    pixel.  Beyond ``budget`` bytes only every ``stride``-th row is kept, and a sum at
    another row adds the rows up to the next kept one."""

    def __init__(self, image: np.ndarray, budget: int = SUMS_BUDGET):
        self.image = np.asarray(image, dtype=np.float32)
        self.h, self.w = h, w = self.image.shape[:2]
        self.pixels = self.image.reshape(-1, 3)
        z, s, th = _rows(h)
        self.z, self.s, self.theta = z, s, th
        Hz = 0.5 * (z * s + (0.5 * np.pi - th))                  # int sqrt(1 - z^2) dz
        self._row_w = np.stack([z[:-1] - z[1:], Hz[:-1] - Hz[1:],
                                0.5 * (z[:-1] ** 2 - z[1:] ** 2)], axis=1)   # (H, 3)
        self.stride = m = max(1, -(-40 * h * w // int(budget)))
        self._kept = np.minimum(np.arange(-(-h // m) + 1) * m, h)            # kept rows
        self.sums = np.zeros((len(self._kept), w, 5))
        band = max(1, 4_000_000 // (5 * h))
        for c0 in range(0, w, band):
            x = self._terms(np.s_[:, c0:c0 + band])
            x = np.cumsum(x[::-1], axis=0)[::-1]                 # rows i >= k, k < H
            self.sums[:-1, c0:c0 + band] = x[self._kept[:-1]]

    def _terms(self, where):
        """The summed terms (..., 5) of the pixels ``image[where]`` (rows in ``where[0]``)."""
        px = self.image[where].astype(np.float64)
        rw = self._row_w[where[0]]
        y = px @ LUMINANCE
        return np.concatenate([px * rw[..., None, :1], (y * rw[..., None, 1])[..., None],
                               (y * rw[..., None, 2])[..., None]], axis=-1)

    def suffix(self, rows, cols):
        """Per-column suffix sums (k, 5) at ``rows`` (0..H) of ``cols``."""
        m = self.stride
        j = -(-rows // m)
        out = np.take(self.sums.reshape(-1, 5), j * self.w + cols, axis=0)
        extra = self._kept[j] - rows
        has = np.nonzero(extra)[0]
        if len(has):
            cnt = extra[has]
            at = np.repeat(has, cnt)
            first = np.cumsum(cnt) - cnt
            r = rows[at] + (np.arange(len(at)) - np.repeat(first, cnt))
            px = np.take(self.pixels, r * self.w + cols[at], axis=0).astype(np.float64)
            rw = self._row_w[r]
            y = _luminance(px)
            t = np.concatenate([px * rw[:, :1], (y * rw[:, 1])[:, None],
                                (y * rw[:, 2])[:, None]], axis=1)
            out[has] += np.add.reduceat(t, first, axis=0)
        return out


# --------------------------------------------------------------------------- resampling
def _luminance(rgb):
    """``rgb @ LUMINANCE`` for (k, 3) arrays (faster written out)."""
    return LUMINANCE[0] * rgb[:, 0] + LUMINANCE[1] * rgb[:, 1] + LUMINANCE[2] * rgb[:, 2]


def _per_edge(out, edge, values):
    """``out[edge] += values`` for ``edge`` sorted (runs summed with reduceat)."""
    if not len(edge):
        return
    starts = np.flatnonzero(np.r_[True, edge[1:] != edge[:-1]])
    out[edge[starts]] += np.add.reduceat(values, starts, axis=0)


def edge_sums(sums: ImageSums, geo: dict, chunk: int = CHUNK):
    """Per edge: RGB energy (E, 3) and luminance-weighted first moment (E, 3; texture
    frame) of the image below the edge, over the edge's azimuths."""
    h, w = sums.h, sums.w
    ne = len(geo["apex"])
    acc = np.zeros((ne + 1, 6))                 # row ne: pairs of breakpoints of two edges
    curved = np.nonzero(geo["curved"])[0]
    x0 = w * (0.5 - geo["phi1"][curved] / _TWO_PI)
    x1 = w * (0.5 - geo["phi0"][curved] / _TWO_PI)
    j0 = np.floor(x0).astype(np.int64)
    nseg = np.maximum(np.ceil(x1).astype(np.int64) - j0, 1)
    ends = np.cumsum(nseg)
    zE, sE, tE = sums.z, sums.s, sums.theta
    img = sums.pixels
    start = 0
    while start < len(curved):
        stop = max(int(np.searchsorted(ends, ends[start] - nseg[start] + chunk, side="right")),
                   start + 1)
        sl = slice(start, stop)
        start = stop
        e_c, ns, jj0 = curved[sl], nseg[sl], j0[sl]
        # breakpoints: each edge's ends and the column boundaries between (x grows as phi
        # falls); segment = breakpoint b to b + 1 (b not the last of its edge)
        nb = ns + 1
        be = np.repeat(np.arange(len(e_c)), nb)
        bfirst = np.cumsum(nb) - nb
        t = np.arange(len(be)) - np.repeat(bfirst, nb)
        jb = jj0[be] + t
        bx = jb.astype(np.float64)
        bx[bfirst] = x0[sl]
        bx[bfirst + ns] = x1[sl]
        e_b = e_c[be]
        apex, rho_b, nz_b = geo["apex"][e_b], geo["rho"][e_b], geo["nz"][e_b]
        ca_b, sa_b = np.cos(apex), np.sin(apex)
        phi_b = np.pi - (_TWO_PI / w) * bx
        E = _ends(np.mod(phi_b - apex + np.pi, _TWO_PI) - np.pi, ca_b, sa_b, rho_b, nz_b)
        hi = [x[:-1] for x in E]
        lo = [x[1:] for x in E]
        e = e_b[:-1].copy()
        e[(bfirst + ns)[:-1]] = ne
        col = np.mod(jb[:-1], w)
        ca, sa, rho, nz = ca_b[:-1], sa_b[:-1], rho_b[:-1], nz_b[:-1]
        dphi = phi_b[:-1] - phi_b[1:]
        wrap = hi[0] < lo[0]                       # the segment holds the lowest point d = pi
        zmax = np.where((lo[0] <= 0.0) & (hi[0] >= 0.0), rho, np.maximum(lo[6], hi[6]))
        zmin = np.where(wrap, -rho, np.minimum(lo[6], hi[6]))
        i0, i1 = _row_of(zmax, h), _row_of(zmin, h)
        i1[e == ne] = i0[e == ne]
        # R_k: the region between latitude z_k and the curve.  Below the curve in rows
        # i0..i1 lies sum_k L_{k-1} (R_k - R_{k-1}) = sum_{k=i0+1}^{i1} R_k (L_{k-1} - L_k)
        # + R_{i1+1} L_{i1} (R_{i0} is empty); the rows below i1 are whole.
        b = i1 + 1
        c, sb, th = zE[b], sE[b], tE[b]
        dpsi = hi[2] - lo[2] + np.where(wrap, _TWO_PI, 0.0)
        dth_q = hi[3] - th
        dth_p = th - lo[3]
        cr = c * sb
        pix = i1 * w + col
        S = sums.suffix(b, col)
        L = np.take(img, pix, axis=0).astype(np.float64)
        Y = 0.5 * _luminance(L)
        vals = np.empty((len(e), 6))
        vals[:, :3] = L * (hi[1] - lo[1] - c * dphi)[:, None] + dphi[:, None] * S[:, :3]
        vals[:, 3] = Y * (-cr * (hi[5] - lo[5]) - hi[5] * dth_q - lo[5] * dth_p
                          + rho * ca * dpsi) + (hi[5] - lo[5]) * S[:, 3]
        vals[:, 4] = Y * (cr * (hi[4] - lo[4]) + hi[4] * dth_q + lo[4] * dth_p
                          + rho * sa * dpsi) + (lo[4] - hi[4]) * S[:, 3]
        vals[:, 5] = Y * (sb * sb * dphi - nz * dpsi) + dphi * S[:, 4]
        _per_edge(acc, e, vals)
        # latitudes the curve crosses: segments through d = pi are cut there
        inn = np.nonzero(i1 > i0)[0]
        if not len(inn):
            continue
        part = np.repeat(inn, 1 + wrap[inn])
        second = np.r_[False, part[1:] == part[:-1]]
        p_lo = [x[part] for x in lo]
        p_hi = [x[part] for x in hi]
        f = np.nonzero(wrap[part] & ~second)[0]
        g = np.nonzero(second)[0]
        if len(f):
            for x, y in zip(p_hi, _lowest(ca[part[f]], sa[part[f]], rho[part[f]], nz[part[f]], 1.0)):
                x[f] = y
            for x, y in zip(p_lo, _lowest(ca[part[g]], sa[part[g]], rho[part[g]], nz[part[g]], -1.0)):
                x[g] = y
        cnt = (i1 - i0)[part]
        lv = np.repeat(np.arange(len(part)), cnt)
        k = (i0[part] + 1)[lv] + (np.arange(len(lv)) - np.repeat(np.cumsum(cnt) - cnt, cnt))
        sg = part[lv]
        area, mom = _region([x[lv] for x in p_lo], [x[lv] for x in p_hi], ca[sg], sa[sg],
                            rho[sg], nz[sg], zE[k], sE[k], tE[k])
        above = (k - 1) * w + col[sg]
        dL = (np.take(img, above, axis=0).astype(np.float64)
              - np.take(img, above + w, axis=0).astype(np.float64))
        dY = _luminance(dL)
        _per_edge(acc, e[sg], np.concatenate([area[:, None] * dL, mom * dY[:, None]], axis=1))
    return acc[:ne, :3], acc[:ne, 3:]


def full_columns(sums: ImageSums, phi0, phi1):
    """Energy (k, 3) and luminance-weighted first moment (k, 3) of the whole columns over
    azimuth ranges ``[phi0, phi1]``."""
    idx, col, pl, ph = _column_pieces(phi0, phi1, sums.w)
    T = sums.sums[0, col]
    dphi = ph - pl
    vals = np.concatenate([dphi[:, None] * T[:, :3], ((np.sin(ph) - np.sin(pl)) * T[:, 3])[:, None],
                           ((np.cos(pl) - np.cos(ph)) * T[:, 3])[:, None],
                           (dphi * T[:, 4])[:, None]], axis=1)
    out = np.zeros((len(phi0), 6))
    _per_edge(out, idx, vals)
    return out[:, :3], out[:, 3:]


def texel_sums(sums: ImageSums, n: int, rotation):
    """Exact per-texel energy (6n^2, 3) and luminance-weighted first moment (6n^2, 3; texture
    frame) of an image whose texture direction is ``rotation @ world``."""
    geo = edge_geometry(n, rotation)
    energy, moment = edge_sums(sums, geo)
    te, coef = geo["texel_edges"], geo["coef"]
    E = np.einsum("tk,tkc->tc", coef, energy[te])
    M = np.einsum("tk,tkc->tc", coef, moment[te])
    scale = np.einsum("tk,tkc->tc", np.abs(coef), np.abs(energy[te]))
    # a texel holding the north pole also has the whole columns over its azimuths, which
    # its lower edges span
    ti, ki = np.nonzero(geo["north"][:, None] & (coef < 0))
    if len(ti):
        e = te[ti, ki]
        fe, fm = full_columns(sums, geo["phi0"][e], geo["phi1"][e])
        np.add.at(E, ti, fe)
        np.add.at(M, ti, fm)
        np.add.at(scale, ti, fe)
    E[E <= ZERO_TOL * scale] = 0.0
    M[(E @ LUMINANCE) <= 0.0] = 0.0
    return E, M
