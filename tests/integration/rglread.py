#!/usr/bin/python3
"""rglread: an independent reader of RGL tabulated BRDF files (.bsdf), written from the format facts
(shared/docs/rgl-bsdf.md, copied into recon/output.md) for the tests: it parses the tensor file, checks every
block lies inside the file, and evaluates f(wi, wo, lambda) the way a renderer does (VNDF inversion, bilinear
spectra, D/(4 sigma)). What a renderer gets from spectra D/(4 sigma) is the cosine-weighted BRDF f cos(theta_o):
the reference loader's eval is "f_r * cos", Mitsuba 3's BSDF::eval includes the foreshortening of wo, and pbrt-v4's
sampling divides by that cosine (rgl-bsdf.md's "f = spectra D/(4 sigma)" leaves it out; recon/output.md). So eval
returns f = spectra D/(4 sigma)/cos(theta_o), and weighted=True the renderer's own value. numpy only; shares no
code with the C writer."""
import struct

import numpy as np

DTYPES = {1: "<u1", 2: "<i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4", 7: "<u8", 8: "<i8", 9: "<f2", 10: "<f4",
          11: "<f8"}


def read_tensor_file(path):
    with open(path, "rb") as fh:
        buf = fh.read()
    if buf[:12] != b"tensor_file\0":
        raise ValueError("%s: not a tensor file" % path)
    major, minor = buf[12], buf[13]
    if (major, minor) != (1, 0):
        raise ValueError("%s: version %d.%d" % (path, major, minor))
    (nf,) = struct.unpack_from("<I", buf, 14)
    pos, fields = 18, {}
    for _ in range(nf):
        (nl,) = struct.unpack_from("<H", buf, pos)
        name = buf[pos + 2:pos + 2 + nl].decode("utf-8")
        pos += 2 + nl
        ndim, dtype, off = struct.unpack_from("<HBQ", buf, pos)
        pos += 11
        shape = struct.unpack_from("<%dQ" % ndim, buf, pos)
        pos += 8 * ndim
        dt = np.dtype(DTYPES[dtype])
        size = int(np.prod(shape)) * dt.itemsize
        if off + size > len(buf) or off < pos:
            raise ValueError("%s: field %s [%d bytes at %d] outside the file" % (path, name, size, off))
        fields[name] = np.frombuffer(buf, dt, int(np.prod(shape)), off).reshape(shape)
    return fields


def elevation(w):
    """Robust zenith angle: 2 asin(|w - z| / 2)."""
    d = w.copy()
    d[:, 2] -= 1
    return 2 * np.arcsin(np.clip(np.linalg.norm(d, axis=1) / 2, 0, 1))


def bilerp(tab, x, y):
    """tab [..., H, W] at unit-square points x (along W), y (along H); leading dims broadcast with x."""
    H, W = tab.shape[-2:]
    fx, fy = np.clip(x, 0, 1) * (W - 1), np.clip(y, 0, 1) * (H - 1)
    i = np.minimum(fx.astype(int), W - 2)
    j = np.minimum(fy.astype(int), H - 2)
    tx, ty = fx - i, fy - j
    return ((1 - ty) * ((1 - tx) * tab[..., j, i] + tx * tab[..., j, i + 1]) +
            ty * ((1 - tx) * tab[..., j + 1, i] + tx * tab[..., j + 1, i + 1]))


def invert(V, x, y):
    """Inversion method for the bilinear density V [n, H, W] (one table per query): the uniform point s."""
    n, H, W = V.shape
    dx, dy = 1.0 / (W - 1), 1.0 / (H - 1)
    rows = dx * (0.5 * (V[:, :, :-1] + V[:, :, 1:])).sum(2)                       # [n, H]
    marg = np.concatenate([np.zeros((n, 1)), np.cumsum(0.5 * dy * (rows[:, :-1] + rows[:, 1:]), 1)], 1)
    fy = np.clip(y, 0, 1) * (H - 1)
    j = np.minimum(fy.astype(int), H - 2)
    ty = fy - j
    a = np.arange(n)
    r0, r1 = rows[a, j], rows[a, j + 1]
    sy = (marg[a, j] + dy * (r0 * ty + 0.5 * (r1 - r0) * ty * ty)) / marg[:, -1]
    q = (1 - ty)[:, None] * V[a, j] + ty[:, None] * V[a, j + 1]                  # [n, W]
    cum = np.concatenate([np.zeros((n, 1)), np.cumsum(0.5 * dx * (q[:, :-1] + q[:, 1:]), 1)], 1)
    fx = np.clip(x, 0, 1) * (W - 1)
    i = np.minimum(fx.astype(int), W - 2)
    tx = fx - i
    q0, q1 = q[a, i], q[a, i + 1]
    sx = (cum[a, i] + dx * (q0 * tx + 0.5 * (q1 - q0) * tx * tx)) / cum[:, -1]
    return np.clip(sx, 0, 1), np.clip(sy, 0, 1)


class RGL:
    def __init__(self, path):
        f = read_tensor_file(path)
        self.f = f
        self.description = bytes(f["description"]).decode("utf-8")
        self.theta_i = f["theta_i"].astype(float)
        self.phi_i = f["phi_i"].astype(float)
        # an RGB file has `rgb` [Nphi, Ntheta, 3, H, W] instead of `spectra` and no `wavelengths`: its channels
        # R, G, B stand where the wavelengths would (Mitsuba 3's RGB variants look them up as 0, 1, 2)
        self.rgb = "wavelengths" not in f
        if self.rgb and "rgb" not in f:
            raise ValueError("%s: neither wavelengths + spectra nor rgb" % path)
        self.wl = np.arange(3.0) if self.rgb else f["wavelengths"].astype(float)
        self.ndf = f["ndf"].astype(float)
        self.sigma = f["sigma"].astype(float)
        self.spectra = f["rgb" if self.rgb else "spectra"].astype(float)
        self.lum = f["luminance"].astype(float)
        v = f["vndf"].astype(float)
        H, W = v.shape[-2:]
        # normalise each incidence's table to integral 1 under the bilinear rule (trapezoids)
        tot = (0.25 * (v[..., :-1, :-1] + v[..., :-1, 1:] + v[..., 1:, :-1] + v[..., 1:, 1:])).sum((-1, -2)) / (
            (H - 1) * (W - 1))
        self.vndf = v / tot[..., None, None]
        if len(self.phi_i) > 2:
            raise ValueError("anisotropic files are not supported by this reader")
        nphi, nth, nl = self.spectra.shape[:3]
        assert self.vndf.shape[:2] == (nphi, nth) and nl == len(self.wl) and len(self.theta_i) == nth

    def eval(self, wi, wo, table=None, chunk=2048, spread=False, weighted=False):
        """f [n, nwl] (or the luminance [n] with table='luminance') at unit vectors wi, wo [n, 3] above the horizon;
        weighted=True: f cos(theta_o), the value a renderer's eval returns (spectra D/(4 sigma)).
        spread=True also returns the interpolation tolerance of each value, in the same units: the range
        (max - min) of the table at the 8 corners used (4 per incidence node; the first-order change over one
        cell) plus 1/8 of the largest second difference there along the grid and the incidence (the curvature
        term h^2/8 |g''| of linear interpolation, for a peak inside a cell); in the grid's first column, the pole,
        the half vector moves like the square root of the warped coordinate, and that term is |A|/4 of the
        sqrt(t) part instead (see _eval)."""
        wi, wo = np.atleast_2d(wi).astype(float), np.atleast_2d(wo).astype(float)
        parts = [self._eval(wi[a:a + chunk], wo[a:a + chunk], table, weighted) for a in range(0, len(wi), chunk)]
        val = np.concatenate([p[0] for p in parts])
        return (val, np.concatenate([p[1] for p in parts])) if spread else val

    def _eval(self, wi, wo, table, weighted):
        wm = wi + wo
        wm /= np.linalg.norm(wm, axis=1, keepdims=True)
        ti, tm = elevation(wi), elevation(wm)
        pi_, pm = np.arctan2(wi[:, 1], wi[:, 0]), np.arctan2(wm[:, 1], wm[:, 0])
        ui = (np.sqrt(2 * ti / np.pi), (pi_ + np.pi) / (2 * np.pi))
        um_phi = (pm - pi_ + np.pi) / (2 * np.pi)
        um = (np.sqrt(2 * tm / np.pi), um_phi - np.floor(um_phi))
        # incidence: linear between theta nodes (clamped at the ends)
        T = self.theta_i
        k = np.clip(np.searchsorted(T, ti, side="right") - 1, 0, len(T) - 2)
        t = np.clip((ti - T[k]) / (T[k + 1] - T[k]), 0, 1)
        V = (1 - t)[:, None, None] * self.vndf[0, k] + t[:, None, None] * self.vndf[0, k + 1]
        sx, sy = invert(V, um[0], um[1])
        D = bilerp(self.ndf, um[0], um[1])
        S = bilerp(self.sigma, ui[0], ui[1])
        fac = D / (4 * S) if weighted else D / (4 * S * wo[:, 2])
        tab = self.lum[0][:, None] if table == "luminance" else self.spectra[0]   # [nth, nl, H, W]
        H, W = tab.shape[-2:]
        fx, fy = sx * (W - 1), sy * (H - 1)
        i = np.minimum(fx.astype(int), W - 2)
        j = np.minimum(fy.astype(int), H - 2)
        tx, ty = (fx - i)[:, None], (fy - j)[:, None]

        def at(kk):
            return ((1 - ty) * ((1 - tx) * tab[kk, :, j, i] + tx * tab[kk, :, j, i + 1]) +
                    ty * ((1 - tx) * tab[kk, :, j + 1, i] + tx * tab[kk, :, j + 1, i + 1]))   # [n, nl]
        val = ((1 - t)[:, None] * at(k) + t[:, None] * at(k + 1)) * fac[:, None]
        corners = np.stack([tab[kk, :, jj, ii] for kk in (k, k + 1) for jj in (j, j + 1) for ii in (i, i + 1)])
        # second differences at the corners along x, y and the incidence (one-sided cells at the edges): the
        # curvature term h^2/8 |g''| of linear interpolation's error
        K = tab.shape[0]

        def d2(kk, jj, ii, axis):
            lo = [kk, jj, ii]
            hi = [kk, jj, ii]
            lim = (K, H, W)[axis]
            lo[axis] = np.clip(lo[axis] - 1, 0, lim - 1)
            hi[axis] = np.clip(hi[axis] + 1, 0, lim - 1)
            return np.abs(tab[lo[0], :, lo[1], lo[2]] - 2 * tab[kk, :, jj, ii] + tab[hi[0], :, hi[1], hi[2]])
        curv = np.stack([d2(kk, jj, ii, a) for kk in (k, k + 1) for jj in (j, j + 1) for ii in (i, i + 1)
                         for a in range(3)]).max(0)
        # the first column of the warped grid (x = 0) is the pole: all its nodes are the normal, and near it the
        # VNDF's density grows like theta_m (area element), so its conditional CDF s_x ~ theta_m^2 and the
        # half vector moves like sqrt(s_x). A smooth f = f0 + grad f . w_m + O(theta_m^2) is then, across that
        # cell (t = s_x / h), g = g0 + A sqrt(t) + B t: the lerp errs by up to |A|/4 (at t = 1/4), and with
        # the nodes at t = 0, 1, 2, A = -(g0 - 2 g1 + g2)/(2 - sqrt 2). So there the curvature term is the
        # second difference at column 1 times 2/(2 - sqrt 2) (= |A|/4 once divided by 8 below), not 1.
        pole = np.stack([d2(kk, jj, np.ones_like(i), 2) for kk in (k, k + 1) for jj in (j, j + 1)]).max(0)
        curv = np.where((i == 0)[:, None], np.maximum(curv, pole * (2 / (2 - np.sqrt(2)))), curv)
        spr = (corners.max(0) - corners.min(0) + curv / 8) * fac[:, None]
        return (val[:, 0], spr[:, 0]) if table == "luminance" else (val, spr)
