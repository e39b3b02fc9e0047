//! Bins that respect a rigid slope lattice ([`super::quantum::SlopeLattice`]).
//!
//! Every slope of a quantized scan is a node `s_ij = o + (i step_x, j step_y)`, so a bin's count
//! estimates the mass of the nodes it holds, each node standing for its own lattice cell (its Voronoi
//! cell, `s_ij +- step / 2`), not the mass of the bin's Lambert cell: a bin that holds no node is empty
//! whatever D is there, one that holds two nodes counts twice as much (the comb). The bin's projected
//! solid angle is therefore the sum over its nodes of `integral of m.n dw = integral of (1 + |s|^2)^-2 d^2s`
//! over each node's cell (Heitz eq. 64, `m.n dw = m_z^4 d^2 s`), its solid angle likewise with
//! `(1 + |s|^2)^(-3/2)`, and its direction the image of their `W`-weighted centroid. Then
//! `D_k = c_k / (N W_k)` estimates D without a comb for any grid, and the fit's midpoint rule models
//! exactly the lattice cells the data can populate. The remaining rounding bias is second order
//! ([`super::quantum::MAX_RESOLVED_STEP`]); derivation in `data_formats/objective.md`.
//!
//! Cells that hold many nodes (more than [`NODE_CAP`]) keep their exact Lambert integrals: there the
//! node count follows the area to `~2 / sqrt(NODE_CAP)`, and summing every node would cost more than the
//! histogram. Cells on the rim of the disk (slopes to infinity) always do.

use rayon::prelude::*;

use super::frame::{SlopeFrame, LAMBERT_RADIUS};
use super::grid::BinGrid;
use super::histogram::Block;
use super::quantum::SlopeLattice;

/// Most lattice nodes (estimated from the cell's slope-space area) for which a cell's integrals are
/// summed node by node.
pub const NODE_CAP: f64 = 1024.0;
/// Most nodes enumerated in all (the bounding box of the lattice cells); beyond it every cell keeps its
/// Lambert integrals (a lattice that fine holds more than [`NODE_CAP`] nodes per central bin anyway).
const MAX_NODES: f64 = 3.0e7;
/// Gauss-Legendre nodes on [-1, 1] for the 2 x 2 rule over a node's cell (exact for cubics; the
/// integrands vary on the slope scale 1, the cell is a lattice step wide).
const GL2: f64 = 0.577_350_269_189_625_8;

/// Per-cell sums over the nodes of a lattice: `[W, Omega, W p_x, W p_y]`.
type Sums = [f64; 4];

/// The cells whose integrals are summed node by node, and the nodes to visit.
struct Picks {
    /// Per grid cell, its index in `picked` (`u32::MAX`: not picked).
    slot: Vec<u32>,
    /// The picked cells, as indices into the bins' `cells`.
    picked: Vec<usize>,
    /// Node index ranges along x and y of the box around the picked cells.
    range: [(i64, i64); 2],
}

/// The cells to sum node by node and the box of nodes around them; `None` when there are none, or the
/// box holds more than [`MAX_NODES`].
fn picks(frame: &SlopeFrame, grid: &BinGrid, lat: &SlopeLattice, cells: &[usize], ints: &[(f64, f64, [f64; 2])]) -> Option<Picks> {
    let cell_area = lat.step[0] * lat.step[1];
    if !(cell_area > 0.0 && cell_area.is_finite()) {
        return None;
    }
    // The cells to sum node by node: wholly inside the disk (off the rim zone of infinite slopes), and
    // with few nodes (slope-space area W / m_z^4 at the centroid).
    let inner = LAMBERT_RADIUS * 0.98;
    let mut slot = vec![u32::MAX; grid.cells()];
    let mut picked = Vec::new();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for (k, &c) in cells.iter().enumerate() {
        let [x0, x1, y0, y1] = grid.bounds(c);
        let far = x0.abs().max(x1.abs()).hypot(y0.abs().max(y1.abs()));
        let (w, _, p) = ints[k];
        let mz = frame.normal_at(p).z;
        // (NaN-safe: a cell whose W or direction is not a positive number is skipped.)
        let few_nodes = w > 0.0 && mz > 0.0 && w / mz.powi(4) / cell_area <= NODE_CAP;
        if far >= inner || !few_nodes {
            continue;
        }
        slot[c] = picked.len() as u32;
        picked.push(k);
        // The cell's extent in slope space, from its corners and edge midpoints (padded below: the
        // edges are curved in slope space).
        for (px, py) in [
            (x0, y0),
            (x1, y0),
            (x0, y1),
            (x1, y1),
            (0.5 * (x0 + x1), y0),
            (0.5 * (x0 + x1), y1),
            (x0, 0.5 * (y0 + y1)),
            (x1, 0.5 * (y0 + y1)),
        ] {
            let m = frame.normal_at([px, py]);
            let s = SlopeFrame::slope_of(m);
            for a in 0..2 {
                lo[a] = lo[a].min(s[a]);
                hi[a] = hi[a].max(s[a]);
            }
        }
    }
    if picked.is_empty() {
        return None;
    }
    // Node index ranges of the padded box.
    let mut range = [(0i64, 0i64); 2];
    for a in 0..2 {
        let pad = 0.05 * (hi[a] - lo[a]) + 2.0 * lat.step[a];
        let i0 = ((lo[a] - pad - lat.offset[a]) / lat.step[a]).floor();
        let i1 = ((hi[a] + pad - lat.offset[a]) / lat.step[a]).ceil();
        if !(i0.is_finite() && i1.is_finite()) {
            return None;
        }
        range[a] = (i0 as i64, i1 as i64);
    }
    let count = |r: (i64, i64)| (r.1 - r.0 + 1) as f64;
    (count(range[0]) * count(range[1]) <= MAX_NODES).then_some(Picks { slot, picked, range })
}

/// Replace the integrals of the cells that hold few lattice nodes by sums over their nodes.
///
/// `cells` are the grid cells of the bins and `ints[k] = (W, Omega, centroid)` their Lambert integrals,
/// replaced in place. Returns how many cells were replaced.
pub(crate) fn respect_lattice(
    frame: &SlopeFrame,
    grid: &BinGrid,
    lat: &SlopeLattice,
    cells: &[usize],
    ints: &mut [(f64, f64, [f64; 2])],
) -> usize {
    let Some(Picks { slot, picked, range }) = picks(frame, grid, lat, cells, ints) else { return 0 };
    // Node rows in fixed chunks, summed in order: the result does not depend on the thread count.
    const CHUNK: i64 = 64;
    let (j0, j1) = range[1];
    let starts: Vec<i64> = (j0..=j1).step_by(CHUNK as usize).collect();
    let partial: Vec<Vec<Sums>> = starts
        .par_iter()
        .map(|&js| {
            let mut acc = vec![[0.0; 4]; picked.len()];
            // The nodes' cells are found a block at a time (the histogram's f32 cells, the same cells as
            // node by node), and the 2 x 2 points of the picked ones mapped a block at a time (the f64
            // map: their Lambert points enter the sums), each point's sums added in node order: the same
            // bits as node by node.
            let (mut nodes, mut points) = (Box::new(Block::new()), Box::new(Block::new()));
            let mut owner = [0u32; Block::LEN];
            let (ni, i0) = ((range[0].1 - range[0].0 + 1) as usize, range[0].0);
            let half = [0.5 * lat.step[0], 0.5 * lat.step[1]];
            for j in js..(js + CHUNK).min(j1 + 1) {
                let sy = lat.offset[1] + j as f64 * lat.step[1];
                for first in (0..ni).step_by(Block::LEN) {
                    let len = Block::LEN.min(ni - first);
                    for k in 0..len {
                        nodes.sx[k] = lat.offset[0] + (i0 + (first + k) as i64) as f64 * lat.step[0];
                        nodes.sy[k] = sy;
                    }
                    nodes.n = len;
                    nodes.cell_each(frame, grid, |[sx, sy], c| {
                        // The data at this node fall in the cell of the node itself.
                        let s = slot[c];
                        if s != u32::MAX {
                            if points.n + GL2_POINTS.len() > Block::LEN {
                                add_points(frame, grid, lat, &mut points, &owner, &mut acc);
                            }
                            for (ux, uy) in GL2_POINTS {
                                let n = points.n;
                                (points.sx[n], points.sy[n], owner[n]) = (sx + ux * half[0], sy + uy * half[1], s);
                                points.n += 1;
                            }
                        }
                    });
                }
            }
            add_points(frame, grid, lat, &mut points, &owner, &mut acc);
            acc
        })
        .collect();
    let mut total = vec![[0.0; 4]; picked.len()];
    for part in &partial {
        for (t, p) in total.iter_mut().zip(part) {
            for v in 0..4 {
                t[v] += p[v];
            }
        }
    }
    for (t, &k) in total.iter().zip(&picked) {
        // A cell that holds no node has W = 0: no data can fall there, and the fit leaves it out.
        let centroid = if t[0] > 0.0 { [t[2] / t[0], t[3] / t[0]] } else { ints[k].2 };
        ints[k] = (t[0], t[1], centroid);
    }
    picked.len()
}

/// The 2 x 2 Gauss-Legendre points over a node's cell, in units of half a step.
const GL2_POINTS: [(f64, f64); 4] = [(-GL2, -GL2), (GL2, -GL2), (-GL2, GL2), (GL2, GL2)];

/// Add the points queued in `points` (their nodes' slots in `owner`) to the integrals over their nodes'
/// lattice cells, in order (2 x 2 Gauss-Legendre, [`GL2_POINTS`]), and empty the block.
fn add_points(frame: &SlopeFrame, grid: &BinGrid, lat: &SlopeLattice, points: &mut Block, owner: &[u32], acc: &mut [Sums]) {
    let wt = (0.5 * lat.step[0]) * (0.5 * lat.step[1]);
    points.map_each(frame, grid, |k, [x, y], p, _| {
        let t = 1.0 + x * x + y * y;
        let dw = wt / (t * t);
        let a = &mut acc[owner[k] as usize];
        a[0] += dw;
        a[1] += wt / (t * t.sqrt());
        a[2] += dw * p[0];
        a[3] += dw * p[1];
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ndf::cells::cell_integrals;

    /// The blocked sums equal sums taken node by node with the scalar map (`to_lambert`, `cell_of`), bit
    /// for bit, in the same node order and the same chunks of node rows: on a skewed, anisotropic frame with
    /// an off-centre lattice, for cells that hold from one node to the cap.
    #[test]
    fn blocked_sums_match_node_by_node() {
        let frame = SlopeFrame::new([0.013, -0.021], [[0.012, 0.004], [0.004, 0.006]]);
        let grid = BinGrid::new(41);
        let lat = SlopeLattice { offset: [0.0031, -0.0007], step: [0.0042, 0.0061] };
        let rim = frame.rim_shape();
        let cells: Vec<usize> = (0..grid.cells()).filter(|&c| grid.meets_disk(c)).collect();
        let ints: Vec<_> = cells.iter().map(|&c| cell_integrals(&frame, &rim, &grid, c)).collect();
        let mut got = ints.clone();
        let picked = respect_lattice(&frame, &grid, &lat, &cells, &mut got);
        assert!(picked > 100 && picked < cells.len(), "{picked} of {} cells summed node by node", cells.len());
        // The reference: the same picks, then every node of the same box, one at a time.
        let Picks { slot, picked: chosen, range } = picks(&frame, &grid, &lat, &cells, &ints).expect("cells to sum");
        assert_eq!(chosen.len(), picked);
        let mut total = vec![[0.0f64; 4]; cells.len()];
        let is_chosen: Vec<bool> = (0..cells.len()).map(|k| chosen.contains(&k)).collect();
        let (hx, hy) = (0.5 * lat.step[0], 0.5 * lat.step[1]);
        for js in (range[1].0..=range[1].1).step_by(64) {
            let mut part = vec![[0.0f64; 4]; cells.len()];
            for j in js..(js + 64).min(range[1].1 + 1) {
                let sy = lat.offset[1] + j as f64 * lat.step[1];
                for i in range[0].0..=range[0].1 {
                    let sx = lat.offset[0] + i as f64 * lat.step[0];
                    let Some(&k) = chosen.get(slot[grid.cell_of(frame.to_lambert(sx, sy))] as usize) else { continue };
                    for (ux, uy) in GL2_POINTS {
                        let (x, y) = (sx + ux * hx, sy + uy * hy);
                        let t = 1.0 + x * x + y * y;
                        let p = frame.to_lambert(x, y);
                        let a = &mut part[k];
                        a[0] += hx * hy / (t * t);
                        a[1] += hx * hy / (t * t.sqrt());
                        a[2] += hx * hy / (t * t) * p[0];
                        a[3] += hx * hy / (t * t) * p[1];
                    }
                }
            }
            for (t, p) in total.iter_mut().zip(&part) {
                for v in 0..4 {
                    t[v] += p[v];
                }
            }
        }
        for k in 0..cells.len() {
            let t = total[k];
            let want = if !is_chosen[k] { ints[k] } else { (t[0], t[1], if t[0] > 0.0 { [t[2] / t[0], t[3] / t[0]] } else { ints[k].2 }) };
            assert_eq!(got[k], want, "cell {}", cells[k]);
        }
    }
}
