"""`ndfit export ... --to rgl --spectral` in pbrt-v4's reading of the format: the tables' tails as
`test_mitsuba_rgl.py::test_table_tails` checks them in Mitsuba 3, with pbrt-v4's `MeasuredBxDF::f` as
`ndfitpy.pbrt_measured` implements it from pbrt-v4's source (pbrt itself is not a Python package).

The same lobes, incidences, azimuths and outgoing directions as test_table_tails and the same bounds. The
references: the closed forms of Mitsuba's roughconductor (GGX; Beckmann with its rational Smith G1) turned
into the scan frame, checked here against roughconductor itself; ndfit's own D with Smith G1 (`ndfit
eval`) for the Student-t and the mixture. The numpy reading is checked against Mitsuba's `measured` in
its spectral variant on the same files, which read the format with the same interpolants.

Runs the ndfit binary (`NDFIT` or target/release/ndfit) and needs the mitsuba package; skips without either.
"""

import math
import subprocess
import time

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="SKIP: the mitsuba package is absent (pip install 'fits[render]')")

from ndfitpy.pbrt_measured import PbrtMeasured  # noqa: E402
from test_mitsuba_rgl import (NDFIT, TAIL_AZIMUTHS, TAIL_INCIDENCES, TAIL_LOBES, fibonacci_hemisphere,  # noqa: E402
                              frame, ndfit, ndfit_smith_brdf, roughconductor, sph)

pytestmark = pytest.mark.skipif(
    not __import__("os").access(NDFIT, __import__("os").X_OK),
    reason=f"SKIP: no ndfit binary at {NDFIT} (cargo build --release, or set NDFIT)")

# pbrt-v4 samples wavelengths over 360-830 nm (SampleVisibleWavelengths); the spectra's nodes are 380-780.
WAVELENGTHS = [360.0, 401.3, 555.0, 612.7, 780.0, 812.0]


def table_pairs():
    """test_table_tails's pairs: (incidence, azimuth) groups of 1500 outgoing directions each."""
    wos = fibonacci_hemisphere(1500)
    wi = np.array([sph(math.radians(t), p) for t in TAIL_INCIDENCES for p in TAIL_AZIMUTHS])
    return np.repeat(wi, len(wos), axis=0), np.tile(wos, (len(wi), 1)), len(wos)


def roughconductor_brdf(dist, alpha_u, alpha_v, wi, wo):
    """Mitsuba's roughconductor (material none, F = 1) as a BRDF, in its own frame: D G1(wi) G1(wo) /
    (4 cos_i cos_o) with its D and its Smith G1 (microfacet.h: GGX exact, Beckmann's rational fit)."""
    m = wi + wo
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    c2 = m[:, 2] ** 2
    q = (m[:, 0] / alpha_u) ** 2 + (m[:, 1] / alpha_v) ** 2
    if dist == "beckmann":
        d = np.exp(-q / c2) / (math.pi * alpha_u * alpha_v * c2 * c2)
    else:
        d = 1.0 / (math.pi * alpha_u * alpha_v * (q + c2) ** 2)

    def g1(v):
        t2 = ((alpha_u * v[:, 0]) ** 2 + (alpha_v * v[:, 1]) ** 2) / v[:, 2] ** 2
        if dist == "beckmann":
            a = 1.0 / np.sqrt(np.maximum(t2, 1e-300))
            g = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a))
        else:
            g = 2.0 / (1.0 + np.sqrt(1.0 + t2))
        return np.where(np.sum(v * m, axis=1) * v[:, 2] > 0, g, 0.0)

    return d * g1(wi) * g1(wo) / (4.0 * wi[:, 2] * wo[:, 2])


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    """The four tail lobes as spectral tables (default resolution), exported two at a time."""
    d = tmp_path_factory.mktemp("pbrt")
    jobs, out = [], {}
    for model, params, dist in TAIL_LOBES:
        fit = d / f"{model}.json"
        fit.write_text(__import__("json").dumps({"model": model, "params": params}))
        path = d / f"{model}.bsdf"
        cmd = [NDFIT, "export", str(fit), "--to", "rgl", "--spectral", "--material", "none", "-o", str(path)]
        jobs.append(cmd)
        out[model] = (fit, path, dist)
    t0 = time.time()
    for k in range(0, len(jobs), 2):
        procs = [subprocess.Popen(c, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for c in jobs[k:k + 2]]
        for p in procs:
            _, err = p.communicate()
            assert p.returncode == 0, err
    print(f"\n{len(jobs)} spectral tables exported in {time.time() - t0:.1f} s")
    return out


def reference(fit, dist, wi, wo):
    """The lobe's BRDF at each pair (reciprocal: the order of wi and wo does not matter)."""
    if dist is not None:
        ex = __import__("json").loads(ndfit("export", fit, "--to", "mitsuba", "--json")[0])
        rot = frame(ex["tangent_angle"])
        return roughconductor_brdf(dist, ex["alpha_u"], ex["alpha_v"], wi @ rot.T, wo @ rot.T)
    return ndfit_smith_brdf(fit, list(zip(wi, wo))) / wo[:, 2]


def figures(got, ref, keep, wo_z):
    rel = np.abs(got[keep] - ref[keep]) / ref[keep]
    inner = rel[wo_z[keep] >= math.cos(math.radians(80.0))]
    return (float(np.median(rel)), float(np.percentile(rel, 90)), float(np.percentile(rel, 99)),
            float(np.median(inner)), float(np.percentile(inner, 90)), len(rel), len(inner))


@pytest.mark.parametrize("model", [m for m, _, _ in TAIL_LOBES])
def test_pbrt_table_tails(tables, model):
    """pbrt-v4's f(wo = the camera's direction, wi = the light's) against the lobe's BRDF wherever that is at
    least 1e-3 of its peak (per incidence), incidences 0-70 degrees: the bounds of test_table_tails."""
    fit, path, dist = tables[model]
    t0 = time.time()
    table = PbrtMeasured(path)
    wi, wo, per = table_pairs()
    # pbrt's wo (towards the camera) is the table's incident direction: Mitsuba's si.wi.
    got = table.f(wi, wo, 555.0)
    t_eval = time.time() - t0
    ref = reference(fit, dist, wi, wo)
    keep = ((ref >= 1e-3 * ref.reshape(-1, per).max(axis=1).repeat(per)) & (ref > 0))
    med, p90, p99, med_in, p90_in, n, n_in = figures(got, ref, keep, wo[:, 2])
    # The reverse reading: the light's direction as the table's incident one (pbrt's MeasuredBxDF ignores
    # TransportMode, so a light subpath of BDPT/MLT reads it so), held to the same bounds.
    rev = table.f(wo, wi, 555.0)
    r_med, r_p90, r_p99, r_med_in, r_p90_in, _, _ = figures(rev, ref, keep, wo[:, 2])
    print(f"\npbrt-v4 reading, {model}: {n} pairs >= 1e-3 of peak, median {med:.4f}, 90th pct {p90:.4f}, "
          f"99th pct {p99:.3f}; outgoing within 80 deg ({n_in}): median {med_in:.4f}, 90th pct {p90_in:.4f} "
          f"[load + eval {t_eval:.2f} s]")
    print(f"  roles swapped (light as the table's incident): median {r_med:.4f}, 90th pct {r_p90:.4f}, "
          f"99th pct {r_p99:.3f}; outgoing within 80 deg: median {r_med_in:.4f}, 90th pct {r_p90_in:.4f}")
    assert med <= 0.01 and p90 <= 0.03 and p90_in <= 0.01, (med, p90, p90_in)
    assert r_med <= 0.01 and r_p90 <= 0.03 and r_p90_in <= 0.01, (r_med, r_p90, r_p90_in)
    # Every wavelength pbrt samples reads the same value for F = 1 (the spectra's ends held beyond them).
    few = slice(0, len(wi), 97)
    spec = table.f(wi[few], wo[few], WAVELENGTHS)
    assert np.allclose(spec, spec[:, :1], rtol=1e-6, atol=0), np.abs(spec / spec[:, :1] - 1).max()


def test_closed_forms_are_roughconductor():
    """The GGX and Beckmann references above are Mitsuba's roughconductor, turned frame included."""
    mi.set_variant("scalar_rgb")
    rng = np.random.default_rng(3)
    wi = np.array([sph(math.radians(t), rng.uniform(-math.pi, math.pi)) for t in rng.uniform(0, 80, 200)])
    wo = np.array([sph(math.radians(t), rng.uniform(-math.pi, math.pi)) for t in rng.uniform(0, 85, 200)])
    for dist in ["ggx", "beckmann"]:
        bsdf, rot = roughconductor(dist, 0.355, 0.25), frame(-0.6)
        ours = roughconductor_brdf(dist, 0.355, 0.25, wi @ rot.T, wo @ rot.T) * wo[:, 2]
        theirs = []
        for a, b in zip(wi, wo):
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*map(float, rot @ a))
            theirs.append(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*map(float, rot @ b)))[0])
        theirs = np.array(theirs)
        big = theirs > 1e-6 * theirs.max()
        rel = np.abs(ours[big] / theirs[big] - 1)
        print(f"\n{dist} closed form vs roughconductor: {big.sum()} pairs, max rel. diff {rel.max():.2e}")
        assert big.sum() > 100 and rel.max() <= 1e-4, rel.max()
        assert np.all(ours[~big] <= 1e-5 * theirs.max())


def mitsuba_spectral(path, wi, wo, nm):
    """Mitsuba's `measured` eval (f cos theta_o) and pdf in scalar_spectral at four wavelengths."""
    mi.set_variant("scalar_spectral")
    try:
        bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
        ev, pdf = [], []
        for a, b in zip(wi, wo):
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*map(float, a))
            si.wavelengths = mi.Spectrum(nm)
            v = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*map(float, b)))
            ev.append([v[k] for k in range(4)])
            pdf.append(bsdf.pdf(mi.BSDFContext(), si, mi.Vector3f(*map(float, b))))
        return np.array(ev), np.array(pdf)
    finally:
        mi.set_variant("scalar_rgb")


def agree(ours, theirs):
    """Largest relative difference where Mitsuba's value is above 1e-6 of its peak; the rest near 0 in both."""
    big = theirs > 1e-6 * theirs.max()
    assert np.all(np.abs(ours[~big]) <= 1e-5 * theirs.max())
    return float(np.max(np.abs(ours[big] / theirs[big] - 1))), int(big.sum())


def test_numpy_reading_matches_mitsuba_measured(tables, tmp_path):
    """The numpy reading against Mitsuba's `measured` on the same files: pbrt-v4 and Mitsuba 3 read the
    format with the same interpolants (`PiecewiseLinear2D` is Mitsuba 2's `Marginal2D`), so pbrt's f times
    cos(theta_wi) is Mitsuba's eval and their PDFs are equal, to float32 rounding. A copper table, whose
    spectrum is not flat, checks the interpolation in wavelength, between and beyond the nodes."""
    fit, _, _ = tables["ggx2"]
    cu = tmp_path / "cu.bsdf"
    ndfit("export", fit, "--to", "rgl", "--spectral", "--material", "Cu", "--warp-res", "24", "--theta-i", "7",
          "--phi-i", "9", "-o", cu)
    wi_all, wo_all, _ = table_pairs()
    rng = np.random.default_rng(9)
    pick = rng.choice(len(wi_all), 400, replace=False)
    wi, wo = wi_all[pick], wo_all[pick]
    # Plus pairs at random, over every incidence and the lower hemisphere (0 in both readers).
    z = rng.uniform(-0.2, 1.0, (2, 200))
    ph = rng.uniform(-math.pi, math.pi, (2, 200))
    r = np.sqrt(1 - z * z)
    wi = np.vstack([wi, np.stack([r[0] * np.cos(ph[0]), r[0] * np.sin(ph[0]), np.abs(z[0])], axis=1)])
    wo = np.vstack([wo, np.stack([r[1] * np.cos(ph[1]), r[1] * np.sin(ph[1]), z[1]], axis=1)])
    cos_o = np.maximum(wo[:, 2], 0.0)
    for name, path, nm in [("ggx2", tables["ggx2"][1], [555.0, 555.0, 555.0, 555.0]),
                           ("Cu", cu, [365.0, 401.3, 612.7, 812.0])]:
        table = PbrtMeasured(path)
        ours = table.f(wi, wo, nm) * cos_o[:, None]
        ours_pdf = table.pdf(wi, wo)
        theirs, theirs_pdf = mitsuba_spectral(path, wi, wo, nm)
        e, n = agree(ours.ravel(), theirs.ravel())
        p, _ = agree(ours_pdf, theirs_pdf)
        print(f"\n{name}: numpy pbrt-v4 reading vs Mitsuba measured (scalar_spectral) at {nm} nm, {n} values: "
              f"max rel. diff f cos {e:.2e}, pdf {p:.2e}")
        assert e <= 1e-4 and p <= 1e-3, (e, p)
    # Copper's red over its blue: the wavelength is read, not one channel for all.
    lit = theirs[:, 1] > 1e-3 * theirs[:, 1].max()
    assert np.median(theirs[lit, 2] / theirs[lit, 1]) > 1.3


@pytest.mark.parametrize("theta", [35.0, 65.0])
def test_pbrt_sample_matches_pdf_and_f(tables, theta):
    """pbrt-v4's Sample_f on the GGX table: its value and pdf are f and PDF at the sampled direction, and
    its directions fall in cells of equal solid angle as the PDF integrated over them says (test_mitsuba_rgl's
    sampling check, pbrt's reading)."""
    table = PbrtMeasured(tables["ggx-aniso"][1])
    n, nt, nphi, q = 20000, 12, 24, 8
    wo = np.tile(sph(math.radians(theta), 0.7), (n, 1))
    wi, f, pdf = table.sample_f(wo, np.random.default_rng(11).random((n, 2)))
    ok = pdf > 0
    assert ok.mean() > 0.9, ok.mean()
    assert np.allclose(f[ok], table.f(wo[ok], wi[ok]), rtol=1e-4, atol=0)
    assert np.allclose(pdf[ok], table.pdf(wo[ok], wi[ok]), rtol=1e-4, atol=0)
    i = np.minimum((wi[ok, 2] * nt).astype(int), nt - 1)
    j = ((np.arctan2(wi[ok, 1], wi[ok, 0]) % (2 * math.pi)) / (2 * math.pi) * nphi).astype(int) % nphi
    counts = np.zeros((nt, nphi))
    np.add.at(counts, (i, j), 1)
    # The pdf integrated over each cell by a q x q midpoint rule in (cos theta, phi).
    z = (np.arange(nt)[:, None] + (np.arange(q)[None, :] + 0.5) / q).ravel() / nt
    ph = (np.arange(nphi)[:, None] + (np.arange(q)[None, :] + 0.5) / q).ravel() / nphi * 2 * math.pi
    zz, pp = np.meshgrid(z, ph, indexing="ij")
    r = np.sqrt(1 - zz ** 2)
    d = np.stack([r * np.cos(pp), r * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    dens = table.pdf(np.tile(wo[0], (len(d), 1)), d).reshape(nt, q, nphi, q).sum(axis=(1, 3))
    expected = n * dens * (1.0 / nt) * (2 * math.pi / nphi) / (q * q)
    zs = (counts - expected) / np.sqrt(np.maximum(expected, 1.0))
    print(f"\npbrt-v4 Sample_f at {theta:.0f} deg: {int(ok.sum())} samples, expected {expected.sum():.0f}, "
          f"max |z| {np.abs(zs).max():.2f}")
    assert abs(expected.sum() - ok.sum()) <= 0.02 * n
    assert np.abs(zs).max() <= 5.0, np.abs(zs).max()


def test_pbrt_refuses_what_it_cannot_read(tables, tmp_path):
    """pbrt-v4 needs `wavelengths` and `spectra`: the default RGB file is refused (pbrt's Tensor::field
    CHECK-fails); the spectral one loads."""
    fit, path, _ = tables["ggx-aniso"]
    rgb = tmp_path / "rgb.bsdf"
    ndfit("export", fit, "--to", "rgl", "--material", "none", "--warp-res", "8", "--theta-i", "3", "--phi-i", "3",
          "-o", rgb)
    with pytest.raises(ValueError, match="wavelengths"):
        PbrtMeasured(rgb)
    assert not PbrtMeasured(path).isotropic
