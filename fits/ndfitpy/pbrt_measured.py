"""pbrt-v4's reading of an RGL tabulated BSDF (Dupuy & Jakob 2018), in numpy, vectorized over directions.

Written from pbrt-v4's source (github.com/mmp/pbrt-v4 at 5f7a606, June 2026: src/pbrt/bxdfs.cpp and
src/pbrt/util/sampling.h), never from ndfit's writer, so that agreement with ndfit's references means the
file is read as pbrt reads it:

- `read_tensor`: pbrt's `Tensor` loader (bxdfs.cpp): header `tensor_file\\0`, version 1.0, the field table.
- `PbrtMeasured.__init__`: `MeasuredBxDFData::Create`: the fields pbrt requires (`wavelengths` and `spectra`,
  never `rgb`), its shape checks, `isotropic = len(phi_i) <= 2`, the refusal of a `phi_i` that does not
  span the full turn ("reduction != 1"), and which interpolants are normalized (`vndf`, `luminance`) or
  raw (`ndf`, `sigma`, `spectra`). pbrt reads no `jacobian` flag: it always applies `D / (4 sigma)`.
- `Interpolant`: `PiecewiseLinear2D<Dimension>` (sampling.h): its constructor (per-slice conditional
  and marginal CDFs of the bilinear density, stored as float32), `Evaluate`, `Invert` and `Sample`, with the
  parameters (incident phi, theta and for `spectra` the wavelength) interpolated linearly between the
  nodes found by `FindInterval` (math.h), the weight clamped to [0, 1].
- `PbrtMeasured.f`: `MeasuredBxDF::f(wo, wi)`: pbrt's `wo` (towards the camera) is the table's incident
  direction, the lobe is read two-sided (both directions flipped when `wo.z < 0`), the spectrum is
  clamped at 0, and the value returned is the BRDF itself,
  `max(0, R(s)) D(m) / (4 sigma(wo) cos(theta_wi))`, without the cosine Mitsuba's `eval` includes.
- `PbrtMeasured.pdf`, `PbrtMeasured.sample_f`: `MeasuredBxDF::PDF(wo, wi)` and `Sample_f(wo, u)` (the
  `luminance` warp, then the `vndf` warp, `Interpolant.sample` following `PiecewiseLinear2D::Sample`).

All arithmetic is float64 on the float32 tables pbrt builds; a float32 renderer differs by rounding only.
"""

import itertools

import numpy as np

_TYPES = {1: np.uint8, 2: np.int8, 3: np.uint16, 4: np.int16, 5: np.uint32, 6: np.int32, 7: np.uint64,
          8: np.int64, 9: np.float16, 10: np.float32, 11: np.float64}


def read_tensor(path):
    """The fields of a tensor file as pbrt's `Tensor` reads them: {name: array}."""
    raw = open(path, "rb").read()
    if len(raw) < 18 or raw[:12] != b"tensor_file\0":
        raise ValueError(f"{path}: invalid tensor file: invalid header")
    if raw[12:14] != bytes([1, 0]):
        raise ValueError(f"{path}: invalid tensor file: unknown file version")
    n = int.from_bytes(raw[14:18], "little")
    at, out = 18, {}
    for _ in range(n):
        ln = int.from_bytes(raw[at:at + 2], "little")
        at += 2
        name = raw[at:at + ln].decode()
        at += ln
        ndim = int.from_bytes(raw[at:at + 2], "little")
        dtype = raw[at + 2]
        off = int.from_bytes(raw[at + 3:at + 11], "little")
        at += 11
        if dtype not in _TYPES:
            raise ValueError(f"{path}: invalid tensor file: unknown type {dtype}")
        shape = [int.from_bytes(raw[at + 8 * k:at + 8 * k + 8], "little") for k in range(ndim)]
        at += 8 * ndim
        count = int(np.prod(shape))
        dt = np.dtype(_TYPES[dtype]).newbyteorder("<")
        if off + count * dt.itemsize > len(raw):
            raise ValueError(f"{path}: field {name} runs past the end of the file")
        out[name] = np.frombuffer(raw, dtype=dt, count=count, offset=off).reshape(shape)
    return out


class Interpolant:
    """`PiecewiseLinear2D<len(params)>`: a bilinear density on an `h x w` grid of the unit square (x the
    last axis) per slice of the parameters, the slices interpolated linearly in the parameters.

    `data` has shape `params_shape + (h, w)`; `params` lists each parameter's node values."""

    def __init__(self, data, params=(), normalize=True, build_cdf=True):
        self.params = [np.asarray(p, dtype=np.float64) for p in params]
        assert np.ndim(data) == 2 + len(self.params)  # the tables are kept as float32, as pbrt keeps them
        self.h, self.w = data.shape[-2:]
        self.inv_patch = np.array([self.w - 1, self.h - 1], dtype=np.float64)
        if build_cdf:
            data = np.asarray(data, dtype=np.float64)
            # Conditional CDF per row (trapezoids of unit width, 0 first), marginal CDF over the rows'
            # totals, both normalized by the slice's total; pbrt sums in double and stores float.
            cond = np.zeros_like(data)
            cond[..., 1:] = np.cumsum(0.5 * (data[..., :-1] + data[..., 1:]), axis=-1)
            tot = cond[..., -1]
            marg = np.zeros(data.shape[:-1])
            marg[..., 1:] = np.cumsum(0.5 * (tot[..., :-1] + tot[..., 1:]), axis=-1)
            norm = (1.0 / marg[..., -1].astype(np.float32)).astype(np.float32)
            self.cond = cond.astype(np.float32) * norm[..., None, None]
            self.marg = marg.astype(np.float32) * norm[..., None]
            self.data = data.astype(np.float32) * norm[..., None, None]
        else:
            data = np.asarray(data, dtype=np.float32)
            if normalize:
                avg = 0.25 * (data[..., :-1, :-1] + data[..., :-1, 1:] + data[..., 1:, :-1] + data[..., 1:, 1:])
                norm = 1.0 / avg.sum(axis=(-2, -1), dtype=np.float64)
            else:
                norm = np.full(data.shape[:-2], 1.0 / np.prod(self.inv_patch))
            self.data = data * np.asarray(norm, dtype=np.float32)[..., None, None]
            self.cond = self.marg = None

    def _weights(self, param):
        """Per parameter: the lower node's index and the two weights (pbrt's `FindInterval`, clamped)."""
        out = []
        for values, p in zip(self.params, param):
            p = np.asarray(p, dtype=np.float64)
            if len(values) == 1:
                out.append((np.zeros(p.shape, dtype=np.intp), np.ones(p.shape), np.zeros(p.shape)))
                continue
            idx = np.clip(np.searchsorted(values, p, side="right") - 1, 0, len(values) - 2)
            p0, p1 = values[idx], values[idx + 1]
            w1 = np.clip((p - p0) / (p1 - p0), 0.0, 1.0)
            out.append((idx, 1.0 - w1, w1))
        return out

    def _lookup(self, arr, weights, *cell):
        """`lookup<Dimension>`: `arr[slice][cell]` blended over the 2^Dimension neighbouring slices."""
        total = 0.0
        for corner in itertools.product((0, 1), repeat=len(weights)):
            w, idx = 1.0, []
            for (i, w0, w1), c, values in zip(weights, corner, self.params):
                idx.append(np.minimum(i + c, len(values) - 1))
                w = w * (w1 if c else w0)
            total = total + w * arr[tuple(idx) + cell]
        return total

    def evaluate(self, pos, *param):
        """`Evaluate(pos, params...)`: `pos = (x, y)` in [0, 1]^2, arrays broadcast together."""
        weights = self._weights(param)
        x = np.asarray(pos[0], dtype=np.float64) * self.inv_patch[0]
        y = np.asarray(pos[1], dtype=np.float64) * self.inv_patch[1]
        ox = np.minimum(x.astype(np.intp), self.w - 2)
        oy = np.minimum(y.astype(np.intp), self.h - 2)
        wx, wy = x - ox, y - oy
        v00 = self._lookup(self.data, weights, oy, ox)
        v10 = self._lookup(self.data, weights, oy, ox + 1)
        v01 = self._lookup(self.data, weights, oy + 1, ox)
        v11 = self._lookup(self.data, weights, oy + 1, ox + 1)
        return ((1 - wy) * ((1 - wx) * v00 + wx * v10) + wy * ((1 - wx) * v01 + wx * v11)) * np.prod(self.inv_patch)

    def _find_interval(self, size, pred):
        """pbrt's `FindInterval(size, pred)`, one binary search per element: the last index whose
        predicate holds, clamped to [0, size - 2]."""
        n = np.shape(pred(np.zeros(1, dtype=np.intp)))
        first = np.ones(n, dtype=np.intp)
        length = np.full(n, size - 2, dtype=np.intp)
        while np.any(length > 0):
            half = length >> 1
            middle = first + half
            ok = pred(np.minimum(middle, size - 1)) & (length > 0)
            first = np.where(ok, middle + 1, first)
            length = np.where(ok, length - (half + 1), np.where(length > 0, half, 0))
        return np.clip(first - 1, 0, size - 2)

    def sample(self, u, *param):
        """`Sample(u, params...)`: the point of the unit square for the uniform `u = (u0, u1)`, and the
        density there (the row by the marginal CDF, then the column by the row's conditional CDF)."""
        one_minus_eps = float(np.nextafter(np.float32(1), np.float32(0)))
        ux = np.clip(np.asarray(u[0], dtype=np.float64), 1 - one_minus_eps, one_minus_eps)
        uy = np.clip(np.asarray(u[1], dtype=np.float64), 1 - one_minus_eps, one_minus_eps)
        ux, uy = np.broadcast_arrays(ux, uy)
        param = [np.broadcast_to(np.asarray(p, dtype=np.float64), ux.shape) for p in param]
        weights = self._weights(param)
        lk = lambda arr, *cell: self._lookup(arr, weights, *cell)  # noqa: E731
        row = self._find_interval(self.h, lambda i: lk(self.marg, np.broadcast_to(i, ux.shape)) < uy)
        uy = uy - lk(self.marg, row)
        last = np.full_like(row, self.w - 1)
        r0, r1 = lk(self.cond, row, last), lk(self.cond, row + 1, last)
        const = np.abs(r0 - r1) < 1e-4 * (r0 + r1)
        with np.errstate(divide="ignore", invalid="ignore"):
            sy = np.where(const, 2 * uy / (r0 + r1),
                          (r0 - np.sqrt(np.maximum(0, r0 * r0 - 2 * uy * (r0 - r1)))) / (r0 - r1))
        ux = ux * ((1 - sy) * r0 + sy * r1)

        def cond_at(i):
            i = np.broadcast_to(i, ux.shape)
            return (1 - sy) * lk(self.cond, row, i) + sy * lk(self.cond, row + 1, i)

        col = self._find_interval(self.w, lambda i: cond_at(i) < ux)
        ux = ux - cond_at(col)
        v00, v10 = lk(self.data, row, col), lk(self.data, row, col + 1)
        v01, v11 = lk(self.data, row + 1, col), lk(self.data, row + 1, col + 1)
        c0, c1 = (1 - sy) * v00 + sy * v01, (1 - sy) * v10 + sy * v11
        const = np.abs(c0 - c1) < 1e-4 * (c0 + c1)
        with np.errstate(divide="ignore", invalid="ignore"):
            sx = np.where(const, 2 * ux / (c0 + c1),
                          (c0 - np.sqrt(np.maximum(0, c0 * c0 - 2 * ux * (c0 - c1)))) / (c0 - c1))
        pos = ((col + sx) / self.inv_patch[0], (row + sy) / self.inv_patch[1])
        return pos, ((1 - sx) * c0 + sx * c1) * np.prod(self.inv_patch)

    def invert(self, sample, *param):
        """`Invert(sample, params...)`: the point of the unit square that `Sample` sends to `sample`, and
        the density there."""
        weights = self._weights(param)
        sx = np.asarray(sample[0], dtype=np.float64) * self.inv_patch[0]
        sy = np.asarray(sample[1], dtype=np.float64) * self.inv_patch[1]
        px = np.minimum(sx.astype(np.intp), self.w - 2)
        py = np.minimum(sy.astype(np.intp), self.h - 2)
        sx, sy = sx - px, sy - py
        lk = lambda arr, y, x: self._lookup(arr, weights, y, x)  # noqa: E731
        v00, v10 = lk(self.data, py, px), lk(self.data, py, px + 1)
        v01, v11 = lk(self.data, py + 1, px), lk(self.data, py + 1, px + 1)
        c0, c1 = (1 - sy) * v00 + sy * v01, (1 - sy) * v10 + sy * v11
        pdf = (1 - sx) * c0 + sx * c1
        # X: the integral across the patch, plus the conditional CDF at its left edge, over the row total.
        ux = sx * (c0 + 0.5 * sx * (c1 - c0))
        ux = ux + (1 - sy) * lk(self.cond, py, px) + sy * lk(self.cond, py + 1, px)
        last = np.full_like(px, self.w - 1)
        r0, r1 = lk(self.cond, py, last), lk(self.cond, py + 1, last)
        ux = ux / ((1 - sy) * r0 + sy * r1)
        # Y: the integral of the row totals, plus the marginal CDF at the patch's lower edge.
        uy = sy * (r0 + 0.5 * sy * (r1 - r0)) + self._lookup(self.marg, weights, py)
        return (ux, uy), pdf * np.prod(self.inv_patch)


def _theta2u(theta):
    return np.sqrt(theta * (2.0 / np.pi))


def _phi2u(phi):
    return phi * (1.0 / (2.0 * np.pi)) + 0.5


class PbrtMeasured:
    """A `.bsdf` file as pbrt-v4's `measured` material reads it (`MeasuredBxDFData::Create`)."""

    def __init__(self, path):
        t = read_tensor(path)
        need = ["theta_i", "phi_i", "ndf", "sigma", "vndf", "spectra", "luminance", "wavelengths", "description",
                "jacobian"]
        missing = [k for k in need if k not in t]
        if missing:  # pbrt's Tensor::field CHECK-fails on a missing field
            raise ValueError(f"{path}: pbrt-v4 requires the fields {missing}")
        f32, u8 = np.dtype(np.float32), np.dtype(np.uint8)
        th, ph, lam = t["theta_i"], t["phi_i"], t["wavelengths"]
        ndf, sigma, vndf, lum, spec = t["ndf"], t["sigma"], t["vndf"], t["luminance"], t["spectra"]
        ok = (t["description"].ndim == 1 and t["description"].dtype == u8
              and th.ndim == 1 and th.dtype == f32 and ph.ndim == 1 and ph.dtype == f32
              and lam.ndim == 1 and lam.dtype == f32
              and ndf.ndim == 2 and ndf.dtype == f32 and sigma.ndim == 2 and sigma.dtype == f32
              and vndf.ndim == 4 and vndf.dtype == f32 and vndf.shape[:2] == (len(ph), len(th))
              and lum.ndim == 4 and lum.dtype == f32 and lum.shape[:2] == (len(ph), len(th))
              and lum.shape[2] == lum.shape[3]
              and spec.ndim == 5 and spec.dtype == f32 and spec.shape[:3] == (len(ph), len(th), len(lam))
              and spec.shape[3] == spec.shape[4] and lum.shape[2:] == spec.shape[3:]
              and t["jacobian"].shape == (1,) and t["jacobian"].dtype == u8)
        if not ok:
            raise ValueError(f"{path}: invalid BRDF file structure")
        self.isotropic = len(ph) <= 2
        if not self.isotropic:
            reduction = int(np.rint(2 * np.float32(np.pi) / (ph[-1] - ph[0])))
            if reduction != 1:
                raise ValueError(f"{path}: reduction {reduction} (!= 1) not supported")
        self.description = bytes(t["description"]).decode(errors="replace")
        self.wavelengths = lam.astype(np.float64)
        self.ndf = Interpolant(ndf, normalize=False, build_cdf=False)
        self.sigma = Interpolant(sigma, normalize=False, build_cdf=False)
        self.vndf = Interpolant(vndf, (ph, th))
        self.luminance = Interpolant(lum, (ph, th))
        self.spectra = Interpolant(spec, (ph, th, lam), normalize=False, build_cdf=False)

    def _frame(self, wo, wi):
        wo, wi = np.atleast_2d(np.asarray(wo, dtype=np.float64)), np.atleast_2d(np.asarray(wi, dtype=np.float64))
        valid = wo[:, 2] * wi[:, 2] > 0  # SameHemisphere
        flip = np.where(wo[:, 2] < 0, -1.0, 1.0)[:, None]
        wo, wi = wo * flip, wi * flip
        wm = wi + wo
        n2 = np.sum(wm * wm, axis=1)
        valid &= n2 > 0
        wm = wm / np.sqrt(np.where(n2 > 0, n2, 1.0))[:, None]
        theta_o, phi_o = np.arccos(np.clip(wo[:, 2], -1, 1)), np.arctan2(wo[:, 1], wo[:, 0])
        theta_m, phi_m = np.arccos(np.clip(wm[:, 2], -1, 1)), np.arctan2(wm[:, 1], wm[:, 0])
        u_wo = (_theta2u(theta_o), _phi2u(phi_o))
        uy = _phi2u(phi_m - phi_o if self.isotropic else phi_m)
        u_wm = (_theta2u(theta_m), uy - np.floor(uy))
        return wo, wi, wm, valid, theta_o, phi_o, u_wo, u_wm

    def f(self, wo, wi, wavelengths=550.0):
        """`MeasuredBxDF::f(wo, wi)` for `n` direction pairs (local frame, `wo` towards the camera):
        the BRDF at each wavelength, shape `(n,)` for one wavelength or `(n, k)` for `k` of them."""
        wo, wi, _, valid, theta_o, phi_o, u_wo, u_wm = self._frame(wo, wi)
        ui, _ = self.vndf.invert(u_wm, phi_o, theta_o)
        lam = np.atleast_1d(np.asarray(wavelengths, dtype=np.float64))
        fr = np.stack([np.maximum(0.0, self.spectra.evaluate(ui, phi_o, theta_o, np.full_like(phi_o, l)))
                       for l in lam], axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = self.ndf.evaluate(u_wm) / (4.0 * self.sigma.evaluate(u_wo) * wi[:, 2])
        out = np.where(valid[:, None], fr * np.where(valid, scale, 0.0)[:, None], 0.0)
        return out[:, 0] if np.ndim(wavelengths) == 0 else out

    def sample_f(self, wo, u, wavelengths=550.0):
        """`MeasuredBxDF::Sample_f(wo, u)` for `n` directions `wo` and `n` uniform pairs `u` (shape
        `(n, 2)`): the sampled `wi`, its value f (as `f`) and its pdf; `wi` is 0 and both are 0 where
        no direction above the surface was drawn."""
        wo = np.atleast_2d(np.asarray(wo, dtype=np.float64))
        flip = np.where(wo[:, 2] <= 0, -1.0, 1.0)[:, None]
        wo = wo * flip
        theta_o, phi_o = np.arccos(np.clip(wo[:, 2], -1, 1)), np.arctan2(wo[:, 1], wo[:, 0])
        u = np.asarray(u, dtype=np.float64)
        s, lum_pdf = self.luminance.sample((u[:, 0], u[:, 1]), phi_o, theta_o)
        u_wm, pdf = self.vndf.sample(s, phi_o, theta_o)
        phi_m, theta_m = (2 * u_wm[1] - 1) * np.pi, u_wm[0] ** 2 * (np.pi / 2)
        if self.isotropic:
            phi_m = phi_m + phi_o
        sin_m, cos_m = np.sin(theta_m), np.cos(theta_m)
        wm = np.stack([sin_m * np.cos(phi_m), sin_m * np.sin(phi_m), cos_m], axis=1)
        wi = -wo + 2 * np.sum(wo * wm, axis=1)[:, None] * wm
        ok = wi[:, 2] > 0
        lam = np.atleast_1d(np.asarray(wavelengths, dtype=np.float64))
        fr = np.stack([np.maximum(0.0, self.spectra.evaluate(s, phi_o, theta_o, np.full_like(phi_o, l)))
                       for l in lam], axis=1)
        u_wo = (_theta2u(theta_o), _phi2u(phi_o))
        with np.errstate(divide="ignore", invalid="ignore"):
            fr = fr * (self.ndf.evaluate(u_wm) / (4 * self.sigma.evaluate(u_wo) * np.abs(wi[:, 2])))[:, None]
            pdf = pdf / (4 * np.sum(wo * wm, axis=1) * np.maximum(2 * np.pi ** 2 * u_wm[0] * sin_m, 1e-6))
        fr = np.where(ok[:, None], fr, 0.0)
        return np.where(ok[:, None], wi * flip, 0.0), fr[:, 0] if np.ndim(wavelengths) == 0 else fr, \
            np.where(ok, pdf * lum_pdf, 0.0)

    def pdf(self, wo, wi):
        """`MeasuredBxDF::PDF(wo, wi)`: the solid-angle density with which `Sample_f` picks `wi`."""
        wo, wi, wm, valid, theta_o, phi_o, _, u_wm = self._frame(wo, wi)
        sample, vndf_pdf = self.vndf.invert(u_wm, phi_o, theta_o)
        lum = self.luminance.evaluate(sample, phi_o, theta_o)
        sin_m = np.sqrt(wm[:, 0] ** 2 + wm[:, 1] ** 2)
        jac = 4.0 * np.sum(wo * wm, axis=1) * np.maximum(2 * np.pi ** 2 * u_wm[0] * sin_m, 1e-6)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(valid, vndf_pdf * lum / jac, 0.0)
