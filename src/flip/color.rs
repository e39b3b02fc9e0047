//! The colour spaces of FLIP's colour pipeline (HPG 2020, section 4.1): linear sRGB <-> CIE XYZ (D65) <->
//! YCxCz (the opponent space the CSF filters in) and CIE L*a*b* (where the colour difference is taken),
//! the Hunt adjustment and the HyAB distance, with the constants of the reference implementation.

/// Linear sRGB -> CIE XYZ, D65 white (the sRGB primaries, IEC 61966-2-1, in the exact rational form the
/// reference uses).
const RGB_TO_XYZ: [[f64; 3]; 3] = [
    [10135552.0 / 24577794.0, 8788810.0 / 24577794.0, 4435075.0 / 24577794.0],
    [2613072.0 / 12288897.0, 8788810.0 / 12288897.0, 887015.0 / 12288897.0],
    [1425312.0 / 73733382.0, 8788810.0 / 73733382.0, 70074185.0 / 73733382.0],
];

/// CIE XYZ (D65) -> linear sRGB, to nine digits as in the reference.
const XYZ_TO_RGB: [[f64; 3]; 3] =
    [[3.241003275, -1.537398934, -0.498615861], [-0.969224334, 1.875930071, 0.041554224], [0.055639423, -0.204011202, 1.057148933]];

/// The D65 reference white in XYZ (Y = 1) and its reciprocal, as the reference writes them.
const WHITE: [f64; 3] = [0.950428545, 1.0, 1.088900371];
const INV_WHITE: [f64; 3] = [1.052156925, 1.0, 0.918357670];

fn mul(m: &[[f64; 3]; 3], c: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| m[i][0] * c[0] + m[i][1] * c[1] + m[i][2] * c[2])
}

/// Linear sRGB -> YCxCz: CIE L*a*b* without its cube root (linear in XYZ, so a linear filter on it is a
/// linear filter on light), `Y = 116 y - 16`, `Cx = 500 (x - y)`, `Cz = 200 (y - z)` with XYZ over the white.
pub(crate) fn linear_rgb_to_ycxcz(rgb: [f64; 3]) -> [f64; 3] {
    let xyz = mul(&RGB_TO_XYZ, rgb);
    let [x, y, z] = [xyz[0] * INV_WHITE[0], xyz[1] * INV_WHITE[1], xyz[2] * INV_WHITE[2]];
    [116.0 * y - 16.0, 500.0 * (x - y), 200.0 * (y - z)]
}

/// YCxCz -> linear sRGB, the inverse of [`linear_rgb_to_ycxcz`] (not clamped).
pub(crate) fn ycxcz_to_linear_rgb(c: [f64; 3]) -> [f64; 3] {
    let y = (c[0] + 16.0) / 116.0;
    let xyz = [(y + c[1] / 500.0) * WHITE[0], y * WHITE[1], (y - c[2] / 200.0) * WHITE[2]];
    mul(&XYZ_TO_RGB, xyz)
}

/// Linear sRGB -> CIE L*a*b* (D65), with the CIE's linear segment below (6/29)^3.
pub(crate) fn linear_rgb_to_lab(rgb: [f64; 3]) -> [f64; 3] {
    const DELTA: f64 = 6.0 / 29.0;
    let f = |t: f64| if t > DELTA * DELTA * DELTA { t.cbrt() } else { t / (3.0 * DELTA * DELTA) + 4.0 / 29.0 };
    let xyz = mul(&RGB_TO_XYZ, rgb);
    let [fx, fy, fz] = [f(xyz[0] * INV_WHITE[0]), f(xyz[1] * INV_WHITE[1]), f(xyz[2] * INV_WHITE[2])];
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// The Hunt adjustment (HPG 2020, section 4.1): chroma scaled by lightness, `a' = 0.01 L a`,
/// `b' = 0.01 L b`, so that colours look less colourful as they darken.
pub(crate) fn hunt(lab: [f64; 3]) -> [f64; 3] {
    [lab[0], 0.01 * lab[0] * lab[1], 0.01 * lab[0] * lab[2]]
}

/// The HyAB distance (Abasi, Amani Tehran and Fairchild 2019; HPG 2020, section 4.1): city-block in
/// lightness plus Euclidean in chroma, `|dL| + sqrt(da^2 + db^2)`, better than Euclidean for large
/// differences.
pub(crate) fn hyab(p: [f64; 3], q: [f64; 3]) -> f64 {
    (p[0] - q[0]).abs() + (p[1] - q[1]).hypot(p[2] - q[2])
}

/// The largest colour difference FLIP remaps against: HyAB between Hunt-adjusted pure green and pure
/// blue, to the power `q_c` (HPG 2020, section 4.1, "c_max").
pub(crate) fn max_distance(qc: f64) -> f64 {
    let green = hunt(linear_rgb_to_lab([0.0, 1.0, 0.0]));
    let blue = hunt(linear_rgb_to_lab([0.0, 0.0, 1.0]));
    hyab(green, blue).powf(qc)
}
