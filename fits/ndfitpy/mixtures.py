"""Two-lobe mixtures in numpy, written from the definition (not from the Rust code):
``D = w D1 + (1 - w) D2``, each lobe normalized (Heitz eq. 9), ``w`` the first (core) lobe's share.

- ``ggx2`` / ``beckmann2``: two anisotropic GGX / Beckmann lobes sharing ``theta_z``:
  ``alpha_x1, alpha_y1, alpha_x2, alpha_y2, theta_z, weight``;
- ``ellipsoid+ggx``: an ellipsoid core and an isotropic GGX tail:
  ``alpha_x1, alpha_y1, theta_x, theta_y, theta_z, alpha2, weight``.

Canonical form: for ggx2/beckmann2 the lobe with the smaller ``alpha_x alpha_y`` first (``w -> 1 - w`` on a
swap), then ``alpha_x1 >= alpha_y1`` (or the tail's, for a round core) with both lobes' alphas swapped together
and ``theta_z + pi/2``, ``theta_z`` in (-pi/2, pi/2]; for ellipsoid+ggx the core by the ellipsoid's rules.
"""

from __future__ import annotations

import math

import numpy as np

PARAM_NAMES = {
    "ggx2": ("alpha_x1", "alpha_y1", "alpha_x2", "alpha_y2", "theta_z", "weight"),
    "beckmann2": ("alpha_x1", "alpha_y1", "alpha_x2", "alpha_y2", "theta_z", "weight"),
    "ellipsoid+ggx": ("alpha_x1", "alpha_y1", "theta_x", "theta_y", "theta_z", "alpha2", "weight"),
}

#: The single lobe each mixture extends (its fit starts the mixture's).
PARENT = {"ggx2": "ggx-aniso", "beckmann2": "beckmann-aniso", "ellipsoid+ggx": "ellipsoid"}


def lobes(model: str, p: np.ndarray):
    """((model1, params1), (model2, params2), w) of a mixture."""
    if model == "ggx2":
        return ("ggx-aniso", np.array([p[0], p[1], p[4]])), ("ggx-aniso", np.array([p[2], p[3], p[4]])), p[5]
    if model == "beckmann2":
        return ("beckmann-aniso", np.array([p[0], p[1], p[4]])), ("beckmann-aniso", np.array([p[2], p[3], p[4]])), p[5]
    if model == "ellipsoid+ggx":
        return ("ellipsoid", np.array(p[:5])), ("ggx", np.array([p[5]])), p[6]
    raise ValueError(f"'{model}' is not a mixture")


def log_d_and_grad(model: str, p: np.ndarray, m: np.ndarray, want_grad: bool, single):
    """ln D of a mixture and its gradient in the natural parameters; ``single`` is models.log_d_and_grad.

    ln D = logaddexp(ln w + ln D1, ln(1 - w) + ln D2); with the responsibilities p_i = w_i D_i / D, the gradient in
    a lobe's parameters is p_i times the lobe's, and d ln D / d w = (D1 - D2) / D = p1 / w - p2 / (1 - w).
    """
    (m1, p1), (m2, p2), w = lobes(model, p)
    if not (0.0 < w < 1.0):
        raise ValueError(f"model '{model}': weight must lie in (0, 1), got {w}")
    l1, g1 = single(m1, p1, m, want_grad)
    l2, g2 = single(m2, p2, m, want_grad)
    a = math.log(w) + l1
    b = math.log1p(-w) + l2
    logd = np.logaddexp(a, b)
    if not want_grad:
        return logd, None
    with np.errstate(invalid="ignore"):
        r1 = np.where(np.isfinite(logd), np.exp(a - logd), 0.0)
        r2 = np.where(np.isfinite(logd), np.exp(b - logd), 0.0)
    g = np.zeros((m.shape[0], len(p)))
    if model in ("ggx2", "beckmann2"):
        g[:, 0] = r1 * g1[:, 0]
        g[:, 1] = r1 * g1[:, 1]
        g[:, 2] = r2 * g2[:, 0]
        g[:, 3] = r2 * g2[:, 1]
        g[:, 4] = r1 * g1[:, 2] + r2 * g2[:, 2]
        g[:, 5] = r1 / w - r2 / (1.0 - w)
    else:
        g[:, :5] = r1[:, None] * g1
        g[:, 5] = r2 * g2[:, 0]
        g[:, 6] = r1 / w - r2 / (1.0 - w)
    return logd, g


def starts(model: str, parent: np.ndarray):
    """Starting points from the parent's fit: a core narrower and a tail wider than the one lobe, the tail's share
    from a tenth to a third, and a narrow spike (chosen here independently of the Rust fitter's starts)."""
    out = []
    # The last: a spike of a few percent five times narrower than the one lobe (a specular patch on a rough scan).
    for kc, kt, w in ((0.8, 2.5, 0.8), (0.6, 4.0, 0.9), (0.9, 1.8, 0.6), (0.2, 1.05, 0.03)):
        if model == "ellipsoid+ggx":
            ax, ay = parent[0], parent[1]
            out.append(np.array([kc * ax, kc * ay, parent[2], parent[3], parent[4], kt * math.sqrt(ax * ay), w]))
        else:
            ax, ay, tz = parent
            out.append(np.array([kc * ax, kc * ay, kt * ax, kt * ay, tz, w]))
    return out


def _wrap(t: float) -> float:
    w = math.fmod(t + 0.5 * math.pi, math.pi)
    if w <= 0.0:
        w += math.pi
    return w - 0.5 * math.pi


def canonical(model: str, p: np.ndarray, ellipsoid_canonical) -> np.ndarray:
    """Canonical parameters (module notes); ``ellipsoid_canonical`` maps the five ellipsoid parameters."""
    p = np.array(p, dtype=float)
    if model == "ellipsoid+ggx":
        p[:5] = ellipsoid_canonical(p[:5])
        return p
    ax1, ay1, ax2, ay2, tz, w = p
    if ax2 * ay2 < ax1 * ay1:
        ax1, ay1, ax2, ay2, w = ax2, ay2, ax1, ay1, 1.0 - w
    tie = lambda a, b: abs(a - b) <= 1e-9 * max(a, b)  # noqa: E731
    swap = (ax1 < ay1) if not tie(ax1, ay1) else (not tie(ax2, ay2) and ax2 < ay2)
    if swap:
        ax1, ay1, ax2, ay2, tz = ay1, ax1, ay2, ax2, tz + 0.5 * math.pi
    tz = 0.0 if tie(ax1, ay1) and tie(ax2, ay2) else _wrap(tz)
    return np.array([ax1, ay1, ax2, ay2, tz, w])


#: The models' roughness floor: the Rust library raises every alpha below it (a mirror there), so the mixtures, whose
#: spikes can otherwise shrink below any bin and hide between the bins' centres, are searched from it up.
ALPHA_FLOOR = 1e-4

#: The largest roughness of a mixture lobe, on every axis: the same bound as the Rust fitter's (data_formats/objective.md,
#: "Mixtures and the ladder"). Beyond it a lobe is flat over the fitted slopes (GGX's (1 + s^2/alpha^2)^-2 is within
#: 2 s^2/alpha^2 = 1.5e-5 of its alpha -> infinity limit at s = tan 70 deg), so its weight and width are no longer told
#: apart; without a bound the two fitters stop anywhere along that flat valley.
LOBE_ALPHA_MAX = 1e3

def price(model: str, n: float) -> float:
    """The deviance a mixture must remove below its parent to be reported: its added parameters' price in the ladder,
    (p - p_parent) ln N, N the normals in the region, at overdispersion 1. A mixture that removes less is reported as
    the parent (as_parent): the deviance does not tell its second lobe from noise, and there the optimum is not unique
    (a lobe between the bins' centres, a sub-percent lobe free in its width, one of several sub-percent spikes on the
    noise of a one-lobe scan). The Rust fitter applies the same rule."""
    return ADDED_PARAMS[model] * math.log(max(n, 1.0))


#: Parameters each mixture adds to its parent (ggx-aniso and beckmann-aniso have 3, the ellipsoid 5).
ADDED_PARAMS = {"ggx2": 3, "beckmann2": 3, "ellipsoid+ggx": 2}


#: The core's weight when ellipsoid+ggx stands for its parent (the isotropic tail cannot copy the ellipsoid).
PARENT_CORE_WEIGHT = 1.0 - 1e-13


def as_parent(model: str, parent: np.ndarray) -> np.ndarray:
    """The parent written as the mixture: the same lobe twice at weight 1/2, or for ellipsoid+ggx the ellipsoid with
    all but PARENT_CORE_WEIGHT's remainder."""
    p = np.asarray(parent, dtype=float)
    if model == "ellipsoid+ggx":
        return np.array([*p[:5], math.sqrt(p[0] * p[1]), PARENT_CORE_WEIGHT])
    return np.array([p[0], p[1], p[0], p[1], p[2], 0.5])


def data_starts(model: str, parent: np.ndarray, bins, log_expected, tilt_for_centre):
    """Starts from where the counts exceed the parent's expectation E (``log_expected(model, params, bins)`` gives the
    region and ln E): excess x_k = c_k - E_k, in slope space s = -(m_x, m_y) / m_z.

    - ggx2 / beckmann2: a spike at the normal: the positive excess within half the parent's width of s = 0 gives the
      spike's share, its root-mean-square slope along the parent's two axes its alphas (at least ALPHA_FLOOR); the tail
      is the parent.
    - ggx2 / beckmann2, a wide tail: the parent holds all but the excess beyond two parent widths of s = 0 (at most a
      tenth of the normals), which a round lobe as wide as that excess's root-mean-square slope per axis takes.
    - ellipsoid+ggx: up to three excess peaks, each at least two parent widths from the others: the core, half the
      parent's alphas, is centred (``tilt_for_centre(alphas_and_theta_z, slope)`` gives the tilts) at the excess-weighted
      mean slope within two widths of the peak, with the excess there as its share; the tail is the parent's width.
    - ellipsoid+ggx, tails: the core is the parent and the (untilted, isotropic) tail takes the excess within half the
      parent's width of s = 0 (a narrow tail), or beyond two widths (a wide tail, at most a tenth of the normals), its
      alpha the excess's root-mean-square slope per axis there.
    """
    p = np.asarray(parent, dtype=float)
    pm = PARENT[model]
    b, ln_e = log_expected(pm, p, bins)[:2]
    x = b.count - np.exp(ln_e)
    z = np.maximum(b.m[:, 2], 1e-12)
    s = np.column_stack([-b.m[:, 0] / z, -b.m[:, 1] / z])
    n = float(b.count.sum())
    if model in ("ggx2", "beckmann2"):
        ax, ay, tz = p
        a = math.sqrt(ax * ay)
        u = np.array([math.cos(tz), -math.sin(tz)])
        v = np.array([math.sin(tz), math.cos(tz)])
        su, sv = s @ u, s @ v
        out = []
        sel = (np.hypot(s[:, 0], s[:, 1]) <= 0.5 * a) & (x > 0)
        if np.any(sel):
            wx = x[sel]
            cx = max(math.sqrt(float(wx @ su[sel] ** 2) / wx.sum()), ALPHA_FLOOR * 1.5)
            cy = max(math.sqrt(float(wx @ sv[sel] ** 2) / wx.sum()), ALPHA_FLOOR * 1.5)
            w = min(max(float(wx.sum()) / n, 0.005), 0.5)
            out.append(np.array([cx, cy, ax, ay, tz, w]))
        far = (np.hypot(s[:, 0], s[:, 1]) > 2.0 * a) & (x > 0)
        if np.any(far):
            held = float(x[far].sum())
            r = np.hypot(s[far, 0], s[far, 1])
            a2 = max(math.sqrt(0.5 * float(x[far] @ r**2) / held), 1.5 * ALPHA_FLOOR)
            out.append(np.array([ax, ay, a2, a2, tz, 1.0 - min(max(held / n, 1e-4), 0.1)]))
        return out
    a = math.sqrt(p[0] * p[1])
    out = []
    centres = []
    order = np.argsort(-x)
    for k in order:
        if x[k] <= 0 or len(out) == 3:
            break
        if any(np.hypot(*(s[k] - c)) < 2.0 * a for c in centres):
            continue
        centres.append(s[k])
        sel = (np.hypot(s[:, 0] - s[k, 0], s[:, 1] - s[k, 1]) <= 2.0 * a) & (x > 0)
        wx = x[sel]
        c = (wx @ s[sel]) / wx.sum()
        w = min(max(float(wx.sum()) / n, 0.01), 0.5)
        tx, ty = tilt_for_centre(np.array([0.5 * p[0], 0.5 * p[1], p[4]]), c)
        out.append(np.array([0.5 * p[0], 0.5 * p[1], tx, ty, p[4], a, w]))
    r = np.hypot(s[:, 0], s[:, 1])
    for sel, most in (((r <= 0.5 * a) & (x > 0), 0.5), ((r > 2.0 * a) & (x > 0), 0.1)):
        if not np.any(sel):
            continue
        held = float(x[sel].sum())
        a2 = max(math.sqrt(0.5 * float(x[sel] @ r[sel] ** 2) / held), 1.5 * ALPHA_FLOOR)
        share = min(max(held / n, 1e-4), most)
        out.append(np.array([*p, a2, 1.0 - share]))
    return out


def ridge_starts(model: str, parent: np.ndarray, bins, log_expected, log_d=None):
    """The ridges of ggx2 / beckmann2 (arguments as data_starts): per parent axis, a lobe at the floor across that axis
    holding the excess in the band of slopes within half the parent's alpha across it, its width along the axis the
    excess's root-mean-square slope there (over the whole band, and over its part within half the parent's alpha
    along it); the other lobe is the parent. A quantized or striated scan piles its slopes up on such lines, which the
    splits (scaled copies of the parent) do not reach.

    With ``log_d`` (models.log_d), a third start per axis: the band's lobe flat along the axis, at LOBE_ALPHA_MAX. Over
    the region such a lobe is a line of constant density, and only its weight over its width is measured, so the fit
    can slide along that flat valley without end; from the root-mean-square width a local optimizer stalls partway
    (objective changes of 1e-8 relative). The start is the valley's end: its weight puts the band's excess share h of
    the region's normals in the lobe, odds w / (1 - w) = h / (1 - h) * P_parent / P_lobe with P the share of each lobe's
    mass in the region (sum of D W over the region's bins)."""
    if model not in ("ggx2", "beckmann2"):
        return []
    p = np.asarray(parent, dtype=float)
    b, ln_e = log_expected(PARENT[model], p, bins)[:2]
    x = b.count - np.exp(ln_e)
    z = np.maximum(b.m[:, 2], 1e-12)
    s = np.column_stack([-b.m[:, 0] / z, -b.m[:, 1] / z])
    n = float(b.count.sum())
    ax, ay, tz = p
    su = s @ np.array([math.cos(tz), -math.sin(tz)])
    sv = s @ np.array([math.sin(tz), math.cos(tz)])
    lobe_model = PARENT[model]

    def in_region(q):
        return float(np.exp(log_d(lobe_model, q, b.m)) @ b.proj_solid_angle)

    out = []
    for along, across, a_along, a_across, first in ((su, sv, ax, ay, True), (sv, su, ay, ax, False)):
        for reach in (math.inf, 0.5 * a_along):
            band = (np.abs(across) <= 0.5 * a_across) & (np.abs(along) <= reach) & (x > 0)
            if not np.any(band):
                continue
            held = float(x[band].sum())
            width = max(math.sqrt(float(x[band] @ along[band] ** 2) / held), 1.5 * ALPHA_FLOOR)
            lobe = (width, 1.5 * ALPHA_FLOOR) if first else (1.5 * ALPHA_FLOOR, width)
            out.append(np.array([*lobe, ax, ay, tz, min(max(held / n, 0.005), 0.5)]))
            if log_d is None or reach != math.inf:
                continue
            flat = (LOBE_ALPHA_MAX, 1.5 * ALPHA_FLOOR) if first else (1.5 * ALPHA_FLOOR, LOBE_ALPHA_MAX)
            p_lobe, p_parent = in_region(np.array([*flat, tz])), in_region(p)
            h = min(held / n, 0.5)
            if not (p_lobe > 0.0 and p_parent > 0.0 and h > 0.0):
                continue
            odds = h / (1.0 - h) * p_parent / p_lobe
            w = min(max(odds / (1.0 + odds), 0.005), 1.0 - 1e-6)
            out.append(np.array([*flat, ax, ay, tz, w]))
    return out


#: alpha / s_max beyond which a lobe is flat to 1% over slopes up to s_max: 2 s_max^2 / alpha^2 <= 0.01.
FLAT_LOBE = 10.0 * math.sqrt(2.0)


def valley_end(model: str, p: np.ndarray, s_max: float):
    """The point at the end of a flat lobe's valley, or None: every roughness flat to 1% over the region (at least
    FLAT_LOBE times s_max, the region's steepest slope) and not yet at LOBE_ALPHA_MAX (within 1e-3 relative) set to
    the bound, the lobe's odds scaled to keep its density over the region (a lobe flat along an axis has density
    w / alpha there; an isotropic tail w / alpha^2). Over the region only the lobe's weight over its width is measured,
    and a local optimizer stalls anywhere along that valley; the fit refits from here and keeps it when the objective
    is not higher (data_formats/objective.md, "The lobes' roughness bound")."""
    q = np.array(p, dtype=float)
    slots = (0, 1, 5) if model == "ellipsoid+ggx" else (0, 1, 2, 3)
    wi = len(q) - 1
    v = math.log(q[wi]) - math.log1p(-q[wi])
    moved = False
    for i in slots:
        if q[i] >= FLAT_LOBE * s_max and q[i] < LOBE_ALPHA_MAX * (1.0 - 1e-3):
            first = i < 2
            shift = (2.0 if model == "ellipsoid+ggx" and not first else 1.0) * math.log(LOBE_ALPHA_MAX / q[i])
            v += shift if first else -shift
            q[i] = LOBE_ALPHA_MAX
            moved = True
    if not moved:
        return None
    q[wi] = 1.0 / (1.0 + math.exp(-v))
    return q
