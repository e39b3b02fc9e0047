//! Spike removal (`data_formats/objective.md`, "Spikes"): isolated height outliers (optical spikes, single
//! bad pixels) are masked (set invalid), never replaced.
//!
//! A valid point with all 8 neighbours valid ([`MIN_NEIGHBOURS`]; the rim of the data is not tested, where a smooth surface ends steeply) is a spike when its
//! height departs from the median `m` of those neighbours by more than [`SPIKE_THRESHOLD`] times their
//! own spread, `1.4826 median |h_n - m|` (the Gaussian-consistent MAD), floored by the scan's typical
//! departure (the same statistic's median over the scan) and by the height quantum (where none is known,
//! by the typical nonzero departure, at least `0.74` of any lattice step): a departure of one lattice
//! step is never a spike. A smooth surface,
//! however steep, keeps every point: on a quadratic patch the departure is at most about twice the
//! neighbours' spread, and a plane's is zero. The median of 8 neighbours is unmoved by a second spike
//! among them, so pairs are found too.

use rayon::prelude::*;

use crate::scan::bands::{bands_of, Band, BandSource, HeightRows};
use crate::scan::{DespikeReport, Scan};

use super::form::FormModel;

/// Departure from the neighbours' median, in units of their spread, beyond which a point is a spike.
pub const SPIKE_THRESHOLD: f64 = 30.0;
/// Fewest valid neighbours (of 8) for a point to be tested.
pub const MIN_NEIGHBOURS: usize = 8;
/// Gaussian-consistent MAD factor.
const MAD_NORMAL: f64 = 1.482_602_218_505_602;

/// Whether to remove spikes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Despike {
    /// The median test of this module (default).
    #[default]
    Median,
    /// Keep every point.
    None,
}

impl std::str::FromStr for Despike {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        match s {
            "median" => Ok(Despike::Median),
            "none" => Ok(Despike::None),
            other => Err(crate::Error::invalid(format!("unknown despike {other:?}: use median or none"))),
        }
    }
}

/// Per point: `Some((departure, spread))` when the point is valid with enough valid neighbours.
fn departure(z: &Band<'_, f64>, nx: usize, ny: usize, i: usize, j: usize) -> Option<(f64, f64)> {
    let c = z.row(i)[j];
    if !c.is_finite() {
        return None;
    }
    if i >= 1 && j >= 1 && i + 1 < ny && j + 1 < nx {
        // An interior point: its 8 neighbours straight from the three rows, in the order of the loop
        // below; with any of them invalid it takes the general path.
        let (r0, r1, r2) = (z.row(i - 1), z.row(i), z.row(i + 1));
        let nb = [r0[j - 1], r0[j], r0[j + 1], r1[j - 1], r1[j + 1], r2[j - 1], r2[j], r2[j + 1]];
        if nb.iter().all(|v| v.is_finite()) {
            return Some(departure8(c, nb));
        }
    }
    let mut nb = [0.0f64; 8];
    let mut k = 0;
    for di in -1i64..=1 {
        for dj in -1i64..=1 {
            if di == 0 && dj == 0 {
                continue;
            }
            let (ii, jj) = (i as i64 + di, j as i64 + dj);
            if ii < 0 || jj < 0 || ii >= ny as i64 || jj >= nx as i64 {
                continue;
            }
            let v = z.row(ii as usize)[jj as usize];
            if v.is_finite() {
                nb[k] = v;
                k += 1;
            }
        }
    }
    if k < MIN_NEIGHBOURS {
        return None;
    }
    if k == 8 {
        // All eight neighbours (every point the scan tests): the same order statistics from a sorting
        // network instead of a comparison sort.
        return Some(departure8(c, nb));
    }
    let nb = &mut nb[..k];
    nb.sort_by(|a, b| a.total_cmp(b));
    let med = if k % 2 == 1 { nb[k / 2] } else { 0.5 * (nb[k / 2 - 1] + nb[k / 2]) };
    let mut dev: [f64; 8] = [0.0; 8];
    for (d, v) in dev.iter_mut().zip(nb.iter()) {
        *d = (v - med).abs();
    }
    let dev = &mut dev[..k];
    dev.sort_by(|a, b| a.total_cmp(b));
    let mad = if k % 2 == 1 { dev[k / 2] } else { 0.5 * (dev[k / 2 - 1] + dev[k / 2]) };
    Some((c - med, MAD_NORMAL * mad))
}

/// The departure and spread of a point `c` with all 8 neighbours `nb` valid (finite).
#[inline(always)]
fn departure8(c: f64, mut nb: [f64; 8]) -> (f64, f64) {
    sort8(&mut nb);
    let med = 0.5 * (nb[3] + nb[4]);
    let mut dev = nb.map(|v| (v - med).abs());
    sort8(&mut dev);
    (c - med, MAD_NORMAL * (0.5 * (dev[3] + dev[4])))
}

/// [`departure`] of the middle of a 3 x 3 patch of an interior point (rows of 3 values).
#[inline]
fn patch_departure(p: &[[f64; 3]; 3]) -> Option<(f64, f64)> {
    let nb = [p[0][0], p[0][1], p[0][2], p[1][0], p[1][2], p[2][0], p[2][1], p[2][2]];
    (p[1][1].is_finite() && nb.iter().all(|v| v.is_finite())).then(|| departure8(p[1][1], nb))
}

/// The spike test of the interior point `j` of the middle row of `rows` ([`departure`] and the threshold,
/// same arithmetic):
/// `Some(above)` for a spike. The neighbours' spread is only computed when the departure exceeds
/// `limit`, the threshold's least value.
#[inline(always)]
fn interior_spike(rows: [&[f64]; 3], j: usize, limit: f64, floor: f64) -> Option<bool> {
    let c = rows[1][j];
    let (a, b, e) = (&rows[0][j - 1..j + 2], &rows[1][j - 1..j + 2], &rows[2][j - 1..j + 2]);
    let mut nb = [a[0], a[1], a[2], b[0], b[2], e[0], e[1], e[2]];
    if !c.is_finite() || !nb.iter().all(|v| v.is_finite()) {
        return None;
    }
    sort8(&mut nb);
    let med = 0.5 * (nb[3] + nb[4]);
    let d = c - med;
    if d.abs() <= limit {
        return None;
    }
    let mut dev = nb.map(|v| (v - med).abs());
    sort8(&mut dev);
    let s = MAD_NORMAL * (0.5 * (dev[3] + dev[4]));
    (d.abs() > SPIKE_THRESHOLD * s.max(floor) && d.abs() > 0.0).then_some(d > 0.0)
}

/// Exact pre-screen of the interior point `j` of the middle row of `rows`: whether at least 5 of its 8 neighbours lie at most `half`
/// above it and at least 5 at most `half` below it. Then the neighbours' 4th and 5th smallest, and so
/// their median, lie within `half` of the point, so its departure is at most `half` (plus rounding) and
/// below the spike threshold (at least `2 half`). Non-finite values compare false; a point passed with
/// a non-finite neighbour is one the full test skips too (it needs all 8 neighbours).
#[inline(always)]
fn near_median(rows: [&[f64]; 3], j: usize, half: f64) -> bool {
    let c = rows[1][j];
    let (hi, lo) = (c + half, c - half);
    let (mut below, mut above) = (0u32, 0u32);
    for (r, row) in rows.iter().enumerate() {
        for (k, &v) in row[j - 1..j + 2].iter().enumerate() {
            if r == 1 && k == 1 {
                continue;
            }
            below += u32::from(v <= hi);
            above += u32::from(v >= lo);
        }
    }
    below >= 5 && above >= 5
}

/// Exact pre-screen of every interior point of the middle row of `rows` (`pass[j - 1]` for point `j`):
/// whether each of the four sums of opposite neighbours, `h(j-d) + h(j+d)` over the four directions, lies
/// within `limit` of twice the point, `2 h(j)`.
///
/// The median of 8 values made of 4 pairs lies between the least and the greatest pair midpoint (were
/// the 4th plus 5th smallest above twice the greatest midpoint, each of the 4 values from the 5th up
/// would have its partner strictly below the 4th smallest, and only 3 values are there). So a passed
/// point's neighbours' median is within `limit / 2` of it and its departure below the threshold (at
/// least `limit`). A plane adds opposite offsets to opposite neighbours, which cancel in each sum: the
/// screen passes the points of a smooth surface of any slope, where [`near_median`] passes only the
/// gentle ones. The rounding of the sums, of their distances from `2 h(j)` and of the median is
/// relative to the point's height, so a point is passed only when its height is below `2^40 limit`
/// (then the rounding stays far below `limit / 2`) and below `f64::MAX / 4`; non-finite values compare
/// false and are left to the full test, as is every point of a scan whose `limit` is 0.
/// The loop is compiled for AVX2 and AVX-512 as well, selected at run time (the same IEEE operations: the binary
/// stays portable and the decisions do not change).
fn pair_screen(rows: [&[f64]; 3], limit: f64, pass: &mut Vec<bool>) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512vl")
            && std::arch::is_x86_feature_detected!("avx512bw")
        {
            // SAFETY: the CPU supports these AVX-512 subsets (checked just above); the body is safe Rust.
            return unsafe { pair_screen_avx512(rows, limit, pass) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above); the body is safe Rust.
            return unsafe { pair_screen_avx2(rows, limit, pass) };
        }
    }
    pair_screen_body(rows, limit, pass)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx512bw")]
unsafe fn pair_screen_avx512(rows: [&[f64]; 3], limit: f64, pass: &mut Vec<bool>) {
    pair_screen_body(rows, limit, pass)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn pair_screen_avx2(rows: [&[f64]; 3], limit: f64, pass: &mut Vec<bool>) {
    pair_screen_body(rows, limit, pass)
}

#[inline(always)]
fn pair_screen_body(rows: [&[f64]; 3], limit: f64, pass: &mut Vec<bool>) {
    let n = rows[1].len();
    pass.clear();
    if n < 3 {
        return;
    }
    let m = n - 2;
    // Below `f64::MAX / 4` too, so that twice the point and the passed sums are finite.
    let cap = (limit * (1u64 << 40) as f64).min(f64::MAX / 4.0);
    let (a0, a1, a2) = (&rows[0][..m], &rows[0][1..m + 1], &rows[0][2..m + 2]);
    let (b0, b1, b2) = (&rows[1][..m], &rows[1][1..m + 1], &rows[1][2..m + 2]);
    let (e0, e1, e2) = (&rows[2][..m], &rows[2][1..m + 1], &rows[2][2..m + 2]);
    pass.resize(m, false);
    let pass = &mut pass[..m];
    for j in 0..m {
        let c = b1[j];
        let two = c + c;
        // Each sum's distance from twice the point: one comparison of its magnitude (a NaN compares
        // false) instead of two against `two -+ limit`.
        let near = |a: f64, b: f64| ((a + b) - two).abs() <= limit;
        // Non-short-circuit `&` so that the loop has no branches and vectorizes.
        pass[j] = near(a0[j], e2[j]) & near(a1[j], e1[j]) & near(a2[j], e0[j]) & near(b0[j], b2[j]) & (c.abs() < cap);
    }
}

/// The positions that `pass` marks false, in order. Most points pass: each run of [`PASS_RUN`] points is
/// packed into a word of failure bits, eight at a time ([`failed8`]), and only the set bits are visited.
fn not_passed(pass: &[bool]) -> impl Iterator<Item = usize> + '_ {
    pass.chunks(PASS_RUN).enumerate().flat_map(|(k, run)| {
        let eights = run.chunks_exact(8);
        // The flags after the last whole eight (none in a full run, whose whole eights fill the word).
        let n = run.len() - run.len() % 8;
        let tail = eights.remainder().iter().enumerate().fold(0u64, |w, (b, &p)| w | u64::from(!p) << (n + b));
        let failed = eights.enumerate().fold(tail, |w, (q, e)| w | failed8(e) << (8 * q));
        SetBits(failed).map(move |b| k * PASS_RUN + b)
    })
}

/// The failure bits of eight flags (bit `b` set when `e[b]` is false): the flags read as one word of
/// bytes 0 and 1, flipped, and gathered into its top byte by one multiplication (each byte's bit lands
/// in its own place of the top byte, and no two products overlap there or carry into it).
#[inline(always)]
fn failed8(e: &[bool]) -> u64 {
    let mut b = [0u8; 8];
    for (d, &p) in b.iter_mut().zip(e) {
        *d = u8::from(!p);
    }
    u64::from_le_bytes(b).wrapping_mul(0x0102_0408_1020_4080) >> 56
}

/// The positions of the set bits of a word, lowest first.
struct SetBits(u64);

impl Iterator for SetBits {
    type Item = usize;
    #[inline]
    fn next(&mut self) -> Option<usize> {
        (self.0 != 0).then(|| {
            let b = self.0.trailing_zeros() as usize;
            // Clear the lowest set bit.
            self.0 &= self.0 - 1;
            b
        })
    }
}

/// Points [`not_passed`] packs into one word of failure bits (a `u64`: at most 64).
const PASS_RUN: usize = 64;
const _: () = assert!(PASS_RUN <= 64);

/// Sort 8 finite values ascending with the optimal 19-comparator network (Knuth, TAOCP vol. 3, 5.3.4).
#[inline(always)]
fn sort8(v: &mut [f64; 8]) {
    let [mut x0, mut x1, mut x2, mut x3, mut x4, mut x5, mut x6, mut x7] = *v;
    // One comparator on two locals: plain selects (no NaN handling: the values are finite), so that they
    // compile to min/max instructions; a loop over a table of index pairs kept the values in memory and
    // compiled to branches.
    macro_rules! cx {
        ($a:ident, $b:ident) => {
            let (x, y) = ($a, $b);
            $a = if y < x { y } else { x };
            $b = if y < x { x } else { y };
        };
    }
    cx!(x0, x2);
    cx!(x1, x3);
    cx!(x4, x6);
    cx!(x5, x7);
    cx!(x0, x4);
    cx!(x1, x5);
    cx!(x2, x6);
    cx!(x3, x7);
    cx!(x0, x1);
    cx!(x2, x3);
    cx!(x4, x5);
    cx!(x6, x7);
    cx!(x2, x4);
    cx!(x3, x5);
    cx!(x1, x4);
    cx!(x3, x6);
    cx!(x1, x2);
    cx!(x3, x4);
    cx!(x5, x6);
    *v = [x0, x1, x2, x3, x4, x5, x6, x7];
}

/// Points sampled (strided) for the scan's typical departure, the spread floor.
const FLOOR_SAMPLE: usize = 1 << 16;

/// Sample strides from which the floor's sample takes each point's 3 x 3 patch of residuals alone
/// (below, the sample is dense enough that whole residual bands cost less).
const SPARSE_STRIDE: usize = 64;

/// Samples ahead of the one being taken whose rows are prefetched.
const PREFETCH_AHEAD: usize = 8;

/// Mask the spikes of `hf` (module documentation). Returns the report; `Despike::None` does nothing.
pub fn despike(hf: &mut Scan<'_>, how: Despike) -> Option<DespikeReport> {
    let (spikes, report) = find_spikes(&*hf, how, hf.meta.height_quantum)?;
    for k in spikes {
        hf.z[k] = f64::NAN;
    }
    Some(report)
}

/// The heights as read and the plane form that `src` of [`find_spikes_over`] subtracts from them. A plane
/// cancels in the pair screen's sums of opposite neighbours, so the test screens the heights as read
/// (no residual band is made) and computes residuals ([`FormModel::residual_at`], bit for bit those of
/// `src`) only around the points the screen does not pass, and for the floor's sparse sample.
#[derive(Clone, Copy)]
pub struct RawPlane<'p> {
    /// The heights as read.
    pub raw: &'p Scan<'p>,
    /// The plane fitted to `raw` (a [`FormModel`] of order 1).
    pub form: &'p FormModel,
}

impl RawPlane<'_> {
    /// Hint the cache to load rows `i - 1 ..= i + 1` (within the grid) around column `j`.
    #[inline(always)]
    fn prefetch(&self, i: usize, j: usize) {
        #[cfg(target_arch = "x86_64")]
        for ii in i.saturating_sub(1)..=i + 1 {
            let p: *const f64 = &self.raw.row(ii)[j];
            // SAFETY: a prefetch is a hint: it reads no data into the program and cannot fault.
            unsafe { std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p.cast()) };
        }
    }

    /// The residuals of rows `i - 1 ..= i + 1`, columns `j - 1 ..= j + 1` (an interior point).
    #[inline]
    fn patch(&self, i: usize, j: usize) -> [[f64; 3]; 3] {
        std::array::from_fn(|a| {
            let (ii, row) = (i + a - 1, self.raw.row(i + a - 1));
            std::array::from_fn(|b| self.form.residual_at(ii, j + b - 1, row[j + b - 1]))
        })
    }
}

/// The spikes of the heights `src` ([`despike`]) as sorted flat indices `i * nx + j`, with the report,
/// without writing the heights: the heights are read in bands of rows (each with the rows around it),
/// so they can be a mapped file or residuals computed band by band. `quantum`: the height quantum (a
/// floor of the spread).
pub fn find_spikes<S: BandSource<T = f64>>(src: &S, how: Despike, quantum: Option<f64>) -> Option<(Vec<usize>, DespikeReport)> {
    find_spikes_over(src, None, how, quantum)
}

/// [`find_spikes`] of residual heights `src` that are `raw`'s heights as read less its plane: the same
/// spikes and report, with the residuals mostly not made at all.
pub fn find_spikes_over<S: BandSource<T = f64>>(
    src: &S,
    raw: Option<RawPlane<'_>>,
    how: Despike,
    quantum: Option<f64>,
) -> Option<(Vec<usize>, DespikeReport)> {
    let shape = src.shape();
    let (nx, ny) = (shape.nx, shape.ny);
    if how == Despike::None {
        return None;
    }
    if nx < 3 || ny < 3 {
        return profile_spikes(src, quantum);
    }
    let raw = raw.filter(|r| r.form.plane_magnitude().is_some() && (r.raw.nx, r.raw.ny) == (nx, ny));
    let bands: Vec<std::ops::Range<usize>> = bands_of(0..ny, src.band_rows()).collect();
    // The floor: the median departure (Gaussian-consistent) over a strided sample of the scan (its
    // relative standard error is about 1 / sqrt(2^16): the threshold moves by under 1%), and the quantum.
    let stride = ((nx * ny) / FLOOR_SAMPLE).max(1);
    let mut all: Vec<f64> = match raw {
        // Not on a tiled scan: reading its rows outside a band would keep their pages.
        Some(rp) if stride >= SPARSE_STRIDE && !rp.raw.is_tiled() => (0..(nx * ny).div_ceil(stride))
            .into_par_iter()
            .with_min_len(1024)
            .filter_map(|s| {
                // The sample is sparse: its rows are far apart in memory, and the hardware prefetcher
                // does not follow them. Ask for the rows of a sample some way ahead.
                let ahead = (s + PREFETCH_AHEAD) * stride;
                if ahead / nx + 1 < ny {
                    rp.prefetch(ahead / nx, ahead % nx);
                }
                let (i, j) = (s * stride / nx, s * stride % nx);
                // Only an interior point has its 8 neighbours ([`departure`] gives `None` elsewhere).
                let interior = i >= 1 && j >= 1 && i + 1 < ny && j + 1 < nx;
                interior.then(|| patch_departure(&rp.patch(i, j))).flatten().map(|d| d.0.abs())
            })
            .collect(),
        _ => bands
            .par_iter()
            .flat_map_iter(|b| {
                let mut buf = Vec::new();
                let z = src.band(b.start.saturating_sub(1), (b.end + 1).min(ny), &mut buf);
                let first = (b.start * nx).next_multiple_of(stride);
                (first..b.end * nx)
                    .step_by(stride)
                    .filter_map(|k| departure(&z, nx, ny, k / nx, k % nx))
                    .map(|d| d.0.abs())
                    .collect::<Vec<f64>>()
            })
            .collect(),
    };
    let floor = spread_floor(&mut all, quantum);
    let limit = SPIKE_THRESHOLD * floor;
    let spikes: Vec<(usize, bool)> = bands
        .par_iter()
        .flat_map_iter(|b| {
            let (mut out, mut buf, mut pass) = (Vec::new(), Vec::new(), Vec::new());
            let (lo, hi) = (b.start.saturating_sub(1), (b.end + 1).min(ny));
            let rows = b.start.max(1)..b.end.min(ny - 1);
            if let Some(rp) = raw {
                let z = rp.raw.band(lo, hi, &mut buf);
                if !raw_screen_holds(&rp, z.values(), limit) {
                    return screen_band(src, lo, hi, rows, limit, floor);
                }
                // Screen the heights as read; test the few points it does not pass on their residual
                // patches, or on the residual band when there are many.
                let mut todo = Vec::new();
                for i in rows.clone() {
                    let (r0, r1, r2) = (z.row(i - 1), z.row(i), z.row(i + 1));
                    pair_screen([r0, r1, r2], limit, &mut pass);
                    // A hole is never tested (the residual of a NaN is NaN).
                    todo.extend(not_passed(&pass).map(|p| p + 1).filter(|&j| !r1[j].is_nan()).map(|j| i * nx + j));
                }
                if todo.len() * 8 > rows.len() * nx {
                    let mut rbuf = Vec::new();
                    let z = src.band(lo, hi, &mut rbuf);
                    for k in todo {
                        let (i, j) = (k / nx, k % nx);
                        if let Some(high) = tested([z.row(i - 1), z.row(i), z.row(i + 1)], j, limit, floor) {
                            out.push((k, high));
                        }
                    }
                } else {
                    for k in todo {
                        let p = rp.patch(k / nx, k % nx);
                        if let Some(high) = tested([&p[0], &p[1], &p[2]], 1, limit, floor) {
                            out.push((k, high));
                        }
                    }
                }
                return out;
            }
            screen_band(src, lo, hi, rows, limit, floor)
        })
        .collect();
    let high = spikes.iter().filter(|s| s.1).count();
    let report = DespikeReport {
        method: "median".into(),
        masked: spikes.len(),
        masked_high: high,
        rule: format!(
            "a height more than {SPIKE_THRESHOLD} times the spread of its 8 neighbours (1.4826 MAD, at least {floor:.3e} m) from their median"
        ),
        floor,
    };
    Some((spikes.into_iter().map(|s| s.0).collect(), report))
}

/// The spikes of a profile (a grid under three samples across one axis; `pipeline::Profile`): the test of
/// [`find_spikes_over`] along each line, a point against its four nearest neighbours on it (two on each
/// side, all valid), the same threshold and floors. The median of four is unmoved by one spike among them,
/// not by two: a pair of adjacent spikes is kept. `None` for lines under five samples.
fn profile_spikes<S: BandSource<T = f64>>(src: &S, quantum: Option<f64>) -> Option<(Vec<usize>, DespikeReport)> {
    let g = src.shape();
    let (along_x, count, samples) = if g.ny < 3 { (true, g.ny, g.nx) } else { (false, g.nx, g.ny) };
    if samples < 5 {
        return None;
    }
    let mut buf = Vec::new();
    let band = src.band(0, g.ny, &mut buf);
    let z = band.values();
    let at = |p: usize, k: usize| if along_x { p * g.nx + k } else { k * g.nx + p };
    // (flat index, departure from the neighbours' median, their spread)
    let mut tests: Vec<(usize, f64, f64)> = Vec::new();
    for p in 0..count {
        for k in 2..samples - 2 {
            let c = z[at(p, k)];
            let mut nb = [z[at(p, k - 2)], z[at(p, k - 1)], z[at(p, k + 1)], z[at(p, k + 2)]];
            if !c.is_finite() || !nb.iter().all(|v| v.is_finite()) {
                continue;
            }
            nb.sort_by(f64::total_cmp);
            let med = 0.5 * (nb[1] + nb[2]);
            let mut dev = nb.map(|v| (v - med).abs());
            dev.sort_by(f64::total_cmp);
            tests.push((at(p, k), c - med, MAD_NORMAL * 0.5 * (dev[1] + dev[2])));
        }
    }
    let mut all: Vec<f64> = tests.iter().map(|t| t.1.abs()).collect();
    let floor = spread_floor(&mut all, quantum);
    let spikes: Vec<(usize, bool)> =
        tests.iter().filter(|t| t.1.abs() > SPIKE_THRESHOLD * t.2.max(floor) && t.1.abs() > 0.0).map(|t| (t.0, t.1 > 0.0)).collect();
    let report = DespikeReport {
        method: "median".into(),
        masked: spikes.len(),
        masked_high: spikes.iter().filter(|s| s.1).count(),
        rule: format!(
            "a height more than {SPIKE_THRESHOLD} times the spread of its 4 neighbours along the profile (1.4826 MAD, at least {floor:.3e} m) from their median"
        ),
        floor,
    };
    let mut at: Vec<usize> = spikes.into_iter().map(|s| s.0).collect();
    at.sort_unstable();
    Some((at, report))
}

/// The floor of the neighbours' spread: the typical departure (Gaussian-consistent median of the `|departure|`s
/// in `all`, reordered), and the height quantum, or where none is known the typical nonzero departure.
fn spread_floor(all: &mut [f64], quantum: Option<f64>) -> f64 {
    let typical = if all.is_empty() {
        0.0
    } else {
        let mid = all.len() / 2;
        MAD_NORMAL * *all.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
    };
    typical.max(quantum.unwrap_or_else(|| typical_nonzero(all)))
}

/// The typical nonzero departure (Gaussian-consistent median of the nonzero `|departure|`s; 0 for none):
/// the floor of a scan whose height lattice is not known. On a lattice of step `q` a departure is a
/// multiple of `q / 2`, so this is at least `0.74 q` and a departure of one step stays far below the
/// threshold even where most departures are 0 (the coarsest lattices); on continuous heights no
/// departure is 0 and it is the typical departure itself.
fn typical_nonzero(all: &[f64]) -> f64 {
    let mut nz: Vec<f64> = all.iter().copied().filter(|&v| v > 0.0).collect();
    if nz.is_empty() {
        return 0.0;
    }
    let mid = nz.len() / 2;
    MAD_NORMAL * *nz.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
}

/// The spikes `(flat index, above)` of `rows` of `src`, read as the band `lo..hi` (the rows and one more
/// on either side within the grid): every point the pair screen does not pass is tested.
fn screen_band<S: BandSource<T = f64>>(
    src: &S,
    lo: usize,
    hi: usize,
    rows: std::ops::Range<usize>,
    limit: f64,
    floor: f64,
) -> Vec<(usize, bool)> {
    let nx = src.shape().nx;
    let (mut buf, mut pass, mut out) = (Vec::new(), Vec::new(), Vec::new());
    let z = src.band(lo, hi, &mut buf);
    for i in rows {
        let (r0, r1, r2) = (z.row(i - 1), z.row(i), z.row(i + 1));
        pair_screen([r0, r1, r2], limit, &mut pass);
        for j in not_passed(&pass).map(|p| p + 1) {
            if let Some(high) = tested([r0, r1, r2], j, limit, floor) {
                out.push((i * nx + j, high));
            }
        }
    }
    out
}

/// Whether the pair screen of the heights as read, `z` (a band), clears the points it passes in the
/// residual too: the plane cancels in each sum of opposite neighbours up to the rounding of the
/// residuals, at most a few ulps of the band's largest height plus the plane's magnitude; with both
/// below `2^36 limit` that is under `2^-13 limit`, far inside the screen's margin (a passed point
/// departs by at most about `limit / 2`, the threshold is at least `limit`). A NaN height only makes
/// the maximum smaller: the screen never passes a point beside one.
fn raw_screen_holds(rp: &RawPlane<'_>, z: &[f64], limit: f64) -> bool {
    let plane = rp.form.plane_magnitude().unwrap_or(f64::INFINITY);
    let bound = limit * (1u64 << 36) as f64;
    // The scan's largest height (the fit's first pass found it) bounds the band's: when it holds, so
    // does the band, with no pass over the band.
    rp.form.largest_height() + plane < bound || largest_magnitude(z) + plane < bound
}

/// The largest `|v|` of the non-NaN values of `z` (0 for none), in lanes that vectorize: a maximum
/// taken in any order is the same value, and `max` skips a NaN.
fn largest_magnitude(z: &[f64]) -> f64 {
    const L: usize = 8;
    let mut lanes = [0.0f64; L];
    let chunks = z.chunks_exact(L);
    for q in chunks.clone() {
        for l in 0..L {
            lanes[l] = lanes[l].max(q[l].abs());
        }
    }
    chunks.remainder().iter().chain(&lanes).fold(0.0, |m, v| m.max(v.abs()))
}

/// The exact tests of the interior point `j` of the middle row of `rows` after the pair screen, cheapest
/// first: `Some(above)` for a spike. The median lies between the neighbours' extremes, so a point within
/// `limit` of both cannot depart by more than the threshold (which is at least `limit`); then
/// [`near_median`]; then the full test. A hole is never tested (nor a point beside one, which the full
/// test skips).
#[inline]
fn tested(rows: [&[f64]; 3], j: usize, limit: f64, floor: f64) -> Option<bool> {
    let c = rows[1][j];
    if !c.is_finite() {
        return None;
    }
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for r in rows {
        for v in &r[j - 1..j + 2] {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    if c - lo <= limit && hi - c <= limit {
        return None;
    }
    if near_median(rows, j, 0.5 * limit) {
        return None;
    }
    interior_spike(rows, j, limit, floor)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scan::bands::GridShape;

    /// The whole grid `z` as one band.
    fn whole(z: &[f64], nx: usize, ny: usize) -> Band<'_, f64> {
        Band::new(z, 0, GridShape { nx, ny, dx: 1e-6, dy: 1e-6, quantum: None })
    }

    /// Uniform values in `[-0.5, 0.5)` from a seeded generator.
    fn uniform(seed: u64) -> impl FnMut() -> f64 {
        use rand::{RngExt, SeedableRng};
        let mut r = rand::rngs::StdRng::seed_from_u64(seed);
        move || r.random::<f64>() - 0.5
    }

    /// The 0-1 principle (Knuth 5.3.4, theorem Z): a network sorting all 256 inputs of zeros and ones
    /// sorts every input. Then random finite values against the comparison sort, value for value.
    #[test]
    fn sort8_is_a_sorting_network() {
        for m in 0u32..256 {
            let mut v: [f64; 8] = std::array::from_fn(|i| f64::from((m >> i) & 1));
            sort8(&mut v);
            assert!(v.windows(2).all(|w| w[0] <= w[1]), "{m:08b}: {v:?}");
        }
        let mut rnd = uniform(0x2545_f491_4f6c_dd1d);
        for _ in 0..2000 {
            let mut v: [f64; 8] = std::array::from_fn(|_| rnd());
            let mut want = v;
            want.sort_by(f64::total_cmp);
            sort8(&mut v);
            assert_eq!(v.map(f64::to_bits), want.map(f64::to_bits));
        }
    }

    /// The pre-screens only skip work: on a sloped, curved, noisy surface with spikes and holes, the
    /// masked points are exactly those the full test (departure of every interior point against the
    /// threshold, no screening) finds with the same floor.
    #[test]
    fn screened_spikes_equal_the_brute_force_test() {
        let (nx, ny) = (97, 83);
        let mut rnd = uniform(0x9e37_79b9_7f4a_7c15);
        let mut z = vec![0.0; nx * ny];
        for i in 0..ny {
            for j in 0..nx {
                let (u, v) = (j as f64 * 1e-6, i as f64 * 1e-6);
                z[i * nx + j] = 0.3 * u - 0.7 * v + 2e3 * (u - 4e-5) * (v - 3e-5) + 4e-9 * rnd();
            }
        }
        for k in (0..nx * ny).step_by(211) {
            // Spikes from well below to well above 30 neighbour spreads (~2e-5 m on these slopes).
            let m = 5e-6 * (1 + k % 13) as f64;
            z[k] += if k % 2 == 0 { m } else { -m };
        }
        for k in (0..nx * ny).step_by(389) {
            z[k] = f64::NAN;
        }
        let mut scan = Scan::from_view(ndarray::ArrayView2::from_shape((ny, nx), &z).unwrap(), 1e-6, 1e-6).unwrap();
        let rep = despike(&mut scan, Despike::Median).unwrap();
        let mut want = Vec::new();
        for i in 1..ny - 1 {
            for j in 1..nx - 1 {
                if let Some((d, s)) = departure(&whole(&z, nx, ny), nx, ny, i, j) {
                    if d.abs() > SPIKE_THRESHOLD * s.max(rep.floor) && d.abs() > 0.0 {
                        want.push(i * nx + j);
                    }
                }
            }
        }
        let got: Vec<usize> = (0..nx * ny).filter(|&k| scan.z[k].is_nan() && !z[k].is_nan()).collect();
        assert!(want.len() > 20, "{} spikes found by the full test", want.len());
        assert_eq!(got, want);
        assert_eq!(rep.masked, want.len());
    }

    /// Screening the heights as read (the plane cancels in the pair sums) and sampling the floor from
    /// residual patches find exactly the spikes, floor and report of the residual heights themselves:
    /// a tilted, curved, noisy surface with spikes and holes, large enough for the sparse floor sample
    /// (stride 64 and more); a large height offset (the screen of the heights as read is then refused
    /// and the residual bands are made); a half-rough grid where most points of some bands fail the
    /// screen (their bands are remade); 1- and 3-row bands.
    #[test]
    fn raw_screen_finds_the_residual_spikes() {
        let cases = [
            (2100, 2050, 4e-9, 0.0, false, None),
            (2100, 2050, 4e-9, 5e4, false, None),
            (301, 173, 1e-15, 0.0, true, Some(1)),
            (97, 83, 4e-9, 0.0, false, Some(3)),
        ];
        for (nx, ny, noise, offset, half_rough, band) in cases {
            let mut rnd = uniform(0x5851_f42d_4c95_7f2d ^ nx as u64);
            let mut z = vec![0.0; nx * ny];
            for i in 0..ny {
                for j in 0..nx {
                    let (u, v) = (j as f64 * 1e-6, i as f64 * 1e-6);
                    let rough = if half_rough && j > nx / 3 && i % 40 < 25 { 1e-6 * rnd() } else { 0.0 };
                    z[i * nx + j] = offset + 0.3 * u - 0.7 * v + 2e3 * (u - 4e-5) * (v - 3e-5) + noise * rnd() + rough;
                }
            }
            for k in (0..nx * ny).step_by(211) {
                let m = 5e-6 * (1 + k % 13) as f64;
                z[k] += if k % 2 == 0 { m } else { -m };
            }
            for k in (0..nx * ny).step_by(389) {
                z[k] = f64::NAN;
            }
            let raw = Scan::from_view(ndarray::ArrayView2::from_shape((ny, nx), &z).unwrap(), 1e-6, 1e-6).unwrap();
            let form = super::super::form::fit_polynomial(&raw, 1).unwrap();
            let rz = form.residual(&raw);
            let residual = Scan::from_view(ndarray::ArrayView2::from_shape((ny, nx), &rz).unwrap(), 1e-6, 1e-6).unwrap();
            crate::scan::bands::set_band_rows(band);
            let want = find_spikes(&residual, Despike::Median, None).unwrap();
            let got = find_spikes_over(&residual, Some(RawPlane { raw: &raw, form: &form }), Despike::Median, None).unwrap();
            crate::scan::bands::set_band_rows(None);
            assert!(want.0.len() > 20, "{nx} x {ny}: {} spikes", want.0.len());
            assert_eq!(got.0, want.0, "{nx} x {ny}, offset {offset}");
            assert_eq!(got.1, want.1);
            // And against the full test of every interior point of the residual, no screen at all.
            let brute: Vec<usize> = (1..ny - 1)
                .flat_map(|i| (1..nx - 1).map(move |j| (i, j)))
                .filter(|&(i, j)| {
                    departure(&whole(&rz, nx, ny), nx, ny, i, j)
                        .is_some_and(|(d, s)| d.abs() > SPIKE_THRESHOLD * s.max(got.1.floor) && d.abs() > 0.0)
                })
                .map(|(i, j)| i * nx + j)
                .collect();
            assert_eq!(got.0, brute, "{nx} x {ny}, offset {offset}: against the full test");
        }
    }

    /// Heights rounded to a lattice so coarse that most neighbours are equal (the spread of the 8 is 0)
    /// and the rest one step away: no point is masked, whether the quantum is known or not; a point
    /// raised by 100 steps still is.
    #[test]
    fn one_lattice_step_is_never_a_spike() {
        let (nx, ny) = (257, 211);
        let q = 5e-7;
        let mut z: Vec<f64> = (0..nx * ny)
            .map(|k| {
                let (i, j) = ((k / nx) as f64, (k % nx) as f64);
                q * ((4e-6 * (0.05 * j).sin() * (0.04 * i).cos() + 3e-6 * (0.031 * (i + j)).sin()) / q).round()
            })
            .collect();
        // One-step departures from the 8 neighbours' median where those neighbours agree exactly.
        let one_step = {
            let whole_z = whole(&z, nx, ny);
            (1..ny - 1)
                .flat_map(|i| (1..nx - 1).map(move |j| (i, j)))
                .filter(|&(i, j)| departure(&whole_z, nx, ny, i, j).is_some_and(|(d, s)| s == 0.0 && (d.abs() / q - 1.0).abs() < 1e-9))
                .count()
        };
        assert!(one_step >= 10, "{one_step} one-step departures from flat neighbours");
        for quantum in [None, Some(q)] {
            let s = Scan::from_view(ndarray::ArrayView2::from_shape((ny, nx), &z).unwrap(), 1e-6, 1e-6).unwrap();
            let (spikes, rep) = find_spikes(&s, Despike::Median, quantum).unwrap();
            assert!(spikes.is_empty(), "quantum {quantum:?}: {} masked, floor {:e}", spikes.len(), rep.floor);
        }
        let k = 100 * nx + 100;
        z[k] += 100.0 * q;
        let s = Scan::from_view(ndarray::ArrayView2::from_shape((ny, nx), &z).unwrap(), 1e-6, 1e-6).unwrap();
        assert_eq!(find_spikes(&s, Despike::Median, None).unwrap().0, vec![k]);
    }

    /// The bound [`pair_screen`] rests on, checked against sorting: the median of 4 pairs lies between
    /// the least and the greatest pair midpoint, for pairs of any spread (random, and nearly equal
    /// midpoints with wide pairs).
    #[test]
    fn median_of_pairs_lies_between_their_midpoints() {
        let mut rnd = uniform(0x51_7cc1_b727_220a);
        for t in 0..20000 {
            let spread = if t % 2 == 0 { 1.0 } else { 1e3 };
            let mut v = [0.0; 8];
            let mut mids = [0.0; 4];
            for k in 0..4 {
                let (m, h) = (rnd(), spread * rnd().abs());
                v[2 * k] = m - h;
                v[2 * k + 1] = m + h;
                mids[k] = 0.5 * (v[2 * k] + v[2 * k + 1]);
            }
            v.sort_by(f64::total_cmp);
            let med = 0.5 * (v[3] + v[4]);
            let (lo, hi) = mids.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &m| (l.min(m), h.max(m)));
            let tol = 1e-12 * spread;
            assert!(med >= lo - tol && med <= hi + tol, "{v:?}: median {med} outside [{lo}, {hi}]");
        }
    }

    /// Every point [`pair_screen`] passes is one the full test clears, on steep planes in every
    /// direction (where the neighbours' extremes are far from the point) with curvature, noise, spikes,
    /// holes and large heights; the screen passes most points there.
    #[test]
    fn pair_screen_passes_only_points_the_full_test_clears() {
        let (nx, ny) = (41, 37);
        let mut rnd = uniform(0x2545_f491_4f6c_dd1d);
        let mut passed = 0usize;
        let mut total = 0usize;
        for (case, (gx, gy, base)) in [(3.0, -7.0, 0.0), (-50.0, 20.0, 0.076), (0.5, 0.5, -1.0), (1e3, 1e3, 10.0)].into_iter().enumerate() {
            let mut z = vec![0.0; nx * ny];
            for i in 0..ny {
                for j in 0..nx {
                    let (u, v) = (j as f64 * 1e-6, i as f64 * 1e-6);
                    z[i * nx + j] = base + gx * u + gy * v + 5e2 * (u * u - 0.5 * v * v) + 4e-9 * rnd();
                }
            }
            for k in (0..nx * ny).step_by(97 + case) {
                z[k] += 3e-7 * (1 + k % 7) as f64 * if k % 2 == 0 { 1.0 } else { -1.0 };
            }
            z[5 * nx + 5] = f64::NAN;
            let floor = 4e-9;
            let limit = SPIKE_THRESHOLD * floor;
            let band = whole(&z, nx, ny);
            let mut pass = Vec::new();
            for i in 1..ny - 1 {
                pair_screen([band.row(i - 1), band.row(i), band.row(i + 1)], limit, &mut pass);
                for j in 1..nx - 1 {
                    total += 1;
                    if pass[j - 1] {
                        passed += 1;
                        let (d, _) = departure(&band, nx, ny, i, j).expect("a passed point has 8 finite neighbours");
                        assert!(d.abs() <= 0.5 * limit * (1.0 + 1e-6), "case {case} ({i}, {j}): departure {d:e} passed");
                    }
                }
            }
        }
        assert!(passed * 10 > total * 8, "{passed} of {total} passed");
    }

    /// [`not_passed`] lists exactly the positions a plain filter finds, in order, on rows of every
    /// length around the run size, sparse and dense failures, all passed and none passed.
    #[test]
    fn not_passed_lists_every_failed_position() {
        let mut rnd = uniform(0x9e37_79b9_7f4a_7c15);
        // Every pattern of eight flags: at a run's start, inside it, at its end and across two runs.
        for pattern in 0..256u32 {
            for shift in [0, 8, 56, 61] {
                let pass: Vec<bool> = (0..70).map(|j| !(shift..shift + 8).contains(&j) || pattern >> (j - shift) & 1 == 0).collect();
                let want: Vec<usize> = (0..70).filter(|&j| !pass[j]).collect();
                assert_eq!(not_passed(&pass).collect::<Vec<_>>(), want, "pattern {pattern:08b} at {shift}");
            }
        }
        for n in [0, 1, 63, 64, 65, 127, 128, 129, 1000] {
            for share in [0.0, 0.002, 0.3, 1.0] {
                let pass: Vec<bool> = (0..n).map(|_| rnd() + 0.5 >= share).collect();
                let want: Vec<usize> = (0..n).filter(|&j| !pass[j]).collect();
                assert_eq!(not_passed(&pass).collect::<Vec<_>>(), want, "n {n}, share {share}");
            }
        }
    }

    /// The lanes' largest magnitude is the serial maximum of `|v|` over the non-NaN values, whatever the
    /// length, the signs and the holes.
    #[test]
    fn largest_magnitude_is_the_serial_maximum() {
        let mut rnd = uniform(0x1234_5678_9abc_def1);
        for n in [0, 1, 7, 8, 9, 17, 100] {
            let z: Vec<f64> = (0..n).map(|k| if k % 5 == 3 { f64::NAN } else { (rnd() - 0.1) * 10f64.powi(k % 7 - 3) }).collect();
            let want = z.iter().filter(|v| !v.is_nan()).fold(0.0f64, |m, v| if v.abs() > m { v.abs() } else { m });
            assert_eq!(largest_magnitude(&z).to_bits(), want.to_bits(), "n {n}");
        }
        assert_eq!(largest_magnitude(&[f64::NAN, -3.0, f64::NAN, 2.0, -0.0, 1.0, 0.5, 0.25, -7.5]), 7.5);
    }

    /// An interior point's departure and spread from the network agree bit for bit with the median and
    /// MAD computed by sorting (the path points with fewer neighbours take).
    #[test]
    fn departure_matches_the_sorted_median_and_mad() {
        let (nx, ny) = (5, 4);
        let z: Vec<f64> = (0..nx * ny).map(|k| ((k * 37 % 11) as f64 - 5.0) * 1e-7 + (k as f64).sin() * 3e-8).collect();
        for i in 1..ny - 1 {
            for j in 1..nx - 1 {
                let mut nb: Vec<f64> = Vec::new();
                for r in [i - 1, i, i + 1] {
                    for c in [j - 1, j, j + 1] {
                        if (r, c) != (i, j) {
                            nb.push(z[r * nx + c]);
                        }
                    }
                }
                nb.sort_by(f64::total_cmp);
                let med = 0.5 * (nb[3] + nb[4]);
                let mut dev: Vec<f64> = nb.iter().map(|v| (v - med).abs()).collect();
                dev.sort_by(f64::total_cmp);
                let want = (z[i * nx + j] - med, MAD_NORMAL * (0.5 * (dev[3] + dev[4])));
                let got = departure(&whole(&z, nx, ny), nx, ny, i, j).unwrap();
                assert_eq!((got.0.to_bits(), got.1.to_bits()), (want.0.to_bits(), want.1.to_bits()), "({i}, {j})");
            }
        }
    }
}
