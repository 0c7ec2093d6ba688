//! Volume bricks for data-parallel (distributed) rendering: a k-d split of a
//! volume's cells into parts balanced by cell count, each part (brick) owning a
//! box of cells and holding the samples those cells need plus one ghost layer.
//!
//! Cells `[lo, hi)` need samples `[lo, hi]` (neighbouring bricks share one
//! layer of samples). [`crate::volume::Volume::gradient`] takes central
//! differences, so the gradient at a sample on the brick's face needs the
//! sample beyond it: a brick also holds one ghost layer of samples on every
//! side that is interior to the whole grid. With it, every sample of the
//! brick's own cells has the same gradient in the brick as in the whole volume
//! (one-sided differences happen only at the whole volume's border), so
//! marching cubes makes bit-identical triangles in the brick's own cells. (The
//! brick's outermost cells, between a ghost layer and its own cells, are
//! *ghost cells*: their triangles are not the whole volume's and are dropped;
//! see [`owned_triangles`].)

use glam::UVec3;

/// A box of a volume's cells and the box of samples it needs, in global
/// indices (lo inclusive, hi exclusive).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Brick {
    /// The cells the brick owns: `[cells[0], cells[1])`.
    pub cells: [UVec3; 2],
    /// The samples it must hold: the samples of its cells plus one ghost layer
    /// on every side interior to the whole grid, `[samples[0], samples[1])`.
    /// Empty (`samples[0] == samples[1]`) for a brick without cells.
    pub samples: [UVec3; 2],
}

impl Brick {
    /// The brick owning cells `[cells[0], cells[1])` of a grid of `cell_dims`
    /// cells (`cell_dims + 1` samples), with its samples and ghost layers.
    pub fn new(cells: [UVec3; 2], cell_dims: UVec3) -> Brick {
        let [lo, hi] = cells;
        if lo.cmpge(hi).any() {
            return Brick {
                cells,
                samples: [lo, lo],
            };
        }
        let sample_dims = cell_dims + UVec3::ONE;
        Brick {
            cells,
            samples: [
                lo.saturating_sub(UVec3::ONE),
                (hi + UVec3::splat(2)).min(sample_dims),
            ],
        }
    }

    /// The whole grid as one brick.
    pub fn whole(cell_dims: UVec3) -> Brick {
        Brick::new([UVec3::ZERO, cell_dims], cell_dims)
    }

    /// The number of cells along each axis the brick owns.
    pub fn cell_dims(&self) -> UVec3 {
        self.cells[1].saturating_sub(self.cells[0])
    }

    pub fn cell_count(&self) -> u64 {
        let d = self.cell_dims().as_u64vec3();
        d.x * d.y * d.z
    }

    /// The number of samples along each axis the brick holds.
    pub fn sample_dims(&self) -> UVec3 {
        self.samples[1].saturating_sub(self.samples[0])
    }

    /// Whether the brick owns the cell whose lowest sample is `cell` (global).
    pub fn owns(&self, cell: UVec3) -> bool {
        cell.cmpge(self.cells[0]).all() && cell.cmplt(self.cells[1]).all()
    }
}

/// A k-d split of a grid of `cell_dims` cells into exactly `parts` bricks (at
/// least one), balanced by cell count: a box of `n` parts is cut across its
/// longest axis (the lowest such axis on a tie) into boxes of `n / 2` and
/// `n - n / 2` parts, at the slab nearest to dividing its cells in that
/// proportion, so any `parts` balances, not only powers of two. Brick `i`
/// goes to rank `i`; the split depends only on its arguments.
///
/// With more parts than cells some bricks are empty (no cells, no samples).
pub fn kd_bricks(cell_dims: UVec3, parts: usize) -> Vec<Brick> {
    let mut bricks = Vec::with_capacity(parts.max(1));
    split(
        [UVec3::ZERO, cell_dims],
        parts.max(1),
        cell_dims,
        &mut bricks,
    );
    bricks
}

fn split(cells: [UVec3; 2], parts: usize, cell_dims: UVec3, out: &mut Vec<Brick>) {
    if parts == 1 {
        out.push(Brick::new(cells, cell_dims));
        return;
    }
    let [lo, hi] = cells;
    let extent = hi.saturating_sub(lo);
    let axis = (0..3)
        .max_by_key(|&a| (extent[a], std::cmp::Reverse(a)))
        .unwrap();
    let (left, right) = (parts / 2, parts - parts / 2);
    let length = extent[axis] as u64;
    // Rounded to the nearest slab: length * left / parts.
    let cut = (length * left as u64 * 2 + parts as u64) / (2 * parts as u64);
    let mut middle = hi;
    middle[axis] = lo[axis] + cut as u32;
    let mut upper = lo;
    upper[axis] = middle[axis];
    split([lo, middle], left, cell_dims, out);
    split([upper, hi], right, cell_dims, out);
}

// ---------------------------------------------------------------------------
// A brick's isosurface triangles: which to keep, and their ids in the whole
// volume's numbering.

/// The global cell (its lowest sample's global index) of cell `local_cell` of
/// `brick_volume` (cells numbered x fastest over the brick volume's own
/// `cell_dims`, as marching cubes numbers them; `first` places it).
pub fn brick_cell_to_global(local_cell: u32, brick_volume: &super::Volume) -> UVec3 {
    let dims = brick_volume.cell_dims().max(UVec3::ONE);
    let (x, rest) = (local_cell % dims.x, local_cell / dims.x);
    brick_volume.first + UVec3::new(x, rest % dims.y, rest / dims.y)
}

/// The index of global cell `cell` in a grid of `whole_cell_dims` cells (x
/// fastest, then y, then z), as a single process numbers cells.
pub fn global_cell_index(cell: UVec3, whole_cell_dims: UVec3) -> u64 {
    let d = whole_cell_dims.as_u64vec3();
    let c = cell.as_u64vec3();
    c.x + d.x * (c.y + d.y * c.z)
}

/// The triangles of a brick that belong to it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct OwnedTriangles {
    /// The indices (in the brick's triangle output) of the triangles whose
    /// cell the brick owns, in order.
    pub indices: Vec<u32>,
    /// The global cell of each kept triangle.
    pub global_cells: Vec<UVec3>,
}

/// Which of a brick's marching-cubes triangles to keep: those whose cell
/// (`owner_cells[t]`, the brick-local cell index of triangle `t`, as the
/// isosurface pipeline's `cells` output gives it) lies in `brick.cells`. The
/// others are in ghost cells, whose triangles another brick makes (with the
/// whole volume's gradients). Every triangle of the whole volume is kept by
/// exactly one brick, bit-identical.
pub fn owned_triangles(
    owner_cells: &[u32],
    brick_volume: &super::Volume,
    brick: &Brick,
) -> OwnedTriangles {
    let mut kept = OwnedTriangles::default();
    for (t, &cell) in owner_cells.iter().enumerate() {
        let global = brick_cell_to_global(cell, brick_volume);
        if brick.owns(global) {
            kept.indices.push(t as u32);
            kept.global_cells.push(global);
        }
    }
    kept
}

/// Words of a [`triangle_summary`] before the row counts.
const SUMMARY_HEADER: usize = 6;

/// What a rank tells every other so that each can number its triangles as
/// the whole volume would: its brick's cell box (6 words: lo.xyz, hi.xyz),
/// then the number of its kept triangles in each row `(y, z)` of its cells
/// (z outer, y inner; `(hi.y - lo.y) * (hi.z - lo.z)` words). The caller
/// all-gathers these (one `Vec<u32>` per rank, in rank order) for
/// [`global_triangle_ids`].
///
/// `kept_global_cells` are the global cells of the brick's kept triangles
/// ([`OwnedTriangles::global_cells`]); each must lie in `brick.cells`.
pub fn triangle_summary(brick: &Brick, kept_global_cells: &[UVec3]) -> Vec<u32> {
    let [lo, hi] = brick.cells;
    let rows = brick.cell_dims();
    let mut summary = Vec::with_capacity(SUMMARY_HEADER + (rows.y * rows.z) as usize);
    summary.extend(lo.to_array());
    summary.extend(hi.to_array());
    summary.resize(SUMMARY_HEADER + (rows.y * rows.z) as usize, 0);
    for cell in kept_global_cells {
        debug_assert!(brick.owns(*cell));
        let row = (cell.y - lo.y) + rows.y * (cell.z - lo.z);
        summary[SUMMARY_HEADER + row as usize] += 1;
    }
    summary
}

/// Why [`global_triangle_ids`] cannot number a brick's triangles.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TriangleIdError {
    #[error("rank {rank} is not among the {ranks} summaries")]
    NoSuchRank { rank: usize, ranks: usize },
    #[error("the summary of rank {rank} is malformed: {what}")]
    BadSummary { rank: usize, what: String },
    #[error(
        "kept triangle {index} lies in cell {cell}, outside this rank's cells or out of order"
    )]
    BadCell { index: usize, cell: UVec3 },
    #[error("the whole surface has {count} triangles; ids are u32 and u32::MAX marks a miss")]
    TooManyTriangles { count: u64 },
}

/// The id in the whole volume's numbering of each of rank `rank`'s kept
/// triangles (their global cells in the order the brick made them,
/// [`OwnedTriangles::global_cells`]), given every rank's
/// [`triangle_summary`] (`summaries[r]` is rank `r`'s).
///
/// A single process numbers triangles by global cell index (x fastest, then
/// y, then z) and lane within the cell. The cells of one row `(y, z)` are
/// split among the bricks covering the row by disjoint x ranges, and a brick
/// makes a row's triangles in x order then lane order, so a triangle's id is:
/// the triangles of every earlier row (all bricks), plus those of the same
/// row in bricks whose x range comes first, plus the brick's own earlier
/// triangles in the row.
pub fn global_triangle_ids(
    summaries: &[Vec<u32>],
    rank: usize,
    whole_cell_dims: UVec3,
    kept_global_cells: &[UVec3],
) -> Result<Vec<u32>, TriangleIdError> {
    if rank >= summaries.len() {
        return Err(TriangleIdError::NoSuchRank {
            rank,
            ranks: summaries.len(),
        });
    }
    // Parse and check each summary.
    let mut boxes = Vec::with_capacity(summaries.len());
    for (r, summary) in summaries.iter().enumerate() {
        let bad = |what: String| TriangleIdError::BadSummary { rank: r, what };
        if summary.len() < SUMMARY_HEADER {
            return Err(bad(format!("{} words", summary.len())));
        }
        let lo = UVec3::from_slice(&summary[0..3]);
        let hi = UVec3::from_slice(&summary[3..6]);
        if lo.cmpgt(hi).any() || hi.cmpgt(whole_cell_dims).any() {
            return Err(bad(format!(
                "cells [{lo}, {hi}) outside the grid {whole_cell_dims}"
            )));
        }
        let rows = hi - lo;
        if summary.len() != SUMMARY_HEADER + (rows.y as usize * rows.z as usize) {
            return Err(bad(format!(
                "{} words for cells [{lo}, {hi})",
                summary.len()
            )));
        }
        boxes.push([lo, hi]);
    }
    let count_in = |r: usize, y: u32, z: u32| -> u64 {
        let [lo, hi] = boxes[r];
        if lo.x == hi.x || y < lo.y || y >= hi.y || z < lo.z || z >= hi.z {
            return 0;
        }
        let rows = hi - lo;
        summaries[r][SUMMARY_HEADER + ((y - lo.y) + rows.y * (z - lo.z)) as usize] as u64
    };
    // Triangles per global row, and before each row.
    let (cy, cz) = (whole_cell_dims.y as usize, whole_cell_dims.z as usize);
    let mut before_row = vec![0u64; cy * cz + 1];
    {
        let mut per_row = vec![0u64; cy * cz];
        for (r, summary) in summaries.iter().enumerate() {
            let [lo, hi] = boxes[r];
            let rows = hi - lo;
            for z in lo.z..hi.z {
                for y in lo.y..hi.y {
                    let local = ((y - lo.y) + rows.y * (z - lo.z)) as usize;
                    per_row[y as usize + cy * z as usize] += summary[SUMMARY_HEADER + local] as u64;
                }
            }
        }
        for row in 0..cy * cz {
            before_row[row + 1] = before_row[row] + per_row[row];
        }
    }
    let total = before_row[cy * cz];
    if total >= u32::MAX as u64 {
        return Err(TriangleIdError::TooManyTriangles { count: total });
    }
    let [lo, hi] = boxes[rank];
    let mut ids = Vec::with_capacity(kept_global_cells.len());
    // Within the current row: where this rank's triangles start, how many so far.
    let mut current: Option<(u32, u32, u64)> = None;
    let mut last_cell: Option<u64> = None;
    for (index, &cell) in kept_global_cells.iter().enumerate() {
        let order = global_cell_index(cell, whole_cell_dims);
        let inside = cell.cmpge(lo).all() && cell.cmplt(hi).all();
        if !inside || last_cell.is_some_and(|last| order < last) {
            return Err(TriangleIdError::BadCell { index, cell });
        }
        last_cell = Some(order);
        let next = match current {
            Some((y, z, next)) if (y, z) == (cell.y, cell.z) => next,
            _ => {
                let row = cell.y as usize + cy * cell.z as usize;
                let earlier_bricks: u64 = (0..boxes.len())
                    .filter(|&r| r != rank && boxes[r][0].x < lo.x)
                    .map(|r| count_in(r, cell.y, cell.z))
                    .sum();
                before_row[row] + earlier_bricks
            }
        };
        ids.push(next as u32);
        current = Some((cell.y, cell.z, next + 1));
    }
    Ok(ids)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cases() -> Vec<UVec3> {
        vec![
            UVec3::new(16, 12, 10),
            UVec3::new(7, 3, 5),
            UVec3::new(1, 1, 9),
            UVec3::new(100, 1, 1),
            UVec3::new(33, 64, 17),
        ]
    }

    #[test]
    fn bricks_partition_the_cells_exactly() {
        for dims in cases() {
            for parts in 1..=13 {
                let bricks = kd_bricks(dims, parts);
                assert_eq!(bricks.len(), parts);
                let mut owner = vec![usize::MAX; (dims.x * dims.y * dims.z) as usize];
                for (b, brick) in bricks.iter().enumerate() {
                    assert!(brick.cells[1].cmple(dims).all());
                    for z in brick.cells[0].z..brick.cells[1].z {
                        for y in brick.cells[0].y..brick.cells[1].y {
                            for x in brick.cells[0].x..brick.cells[1].x {
                                let i = (x + dims.x * (y + dims.y * z)) as usize;
                                assert_eq!(
                                    owner[i],
                                    usize::MAX,
                                    "{dims} {parts}: cell owned twice"
                                );
                                owner[i] = b;
                            }
                        }
                    }
                }
                assert!(owner.iter().all(|&o| o != usize::MAX), "{dims} {parts}");
                assert_eq!(bricks, kd_bricks(dims, parts), "deterministic");
            }
        }
    }

    #[test]
    fn cell_counts_are_balanced_within_a_slab() {
        for dims in cases() {
            let total = (dims.x * dims.y * dims.z) as f64;
            // The largest slab of the whole grid across any axis.
            let slab = [dims.y * dims.z, dims.x * dims.z, dims.x * dims.y]
                .into_iter()
                .max()
                .unwrap() as f64;
            for parts in 1..=13 {
                if (parts as f64) > total {
                    continue;
                }
                let ideal = total / parts as f64;
                for brick in kd_bricks(dims, parts) {
                    let count = brick.cell_count() as f64;
                    assert!(
                        (count - ideal).abs() <= slab,
                        "{dims} into {parts}: {count} cells, ideal {ideal}, slab {slab}"
                    );
                }
            }
        }
        // Non-powers of two balance exactly where they divide evenly.
        let counts: Vec<u64> = kd_bricks(UVec3::new(30, 4, 4), 3)
            .iter()
            .map(Brick::cell_count)
            .collect();
        assert_eq!(counts, [160, 160, 160]);
    }

    #[test]
    fn samples_cover_the_cells_and_a_ghost_layer_inside_the_grid() {
        for dims in cases() {
            let samples = dims + UVec3::ONE;
            for parts in 1..=9 {
                for brick in kd_bricks(dims, parts) {
                    if brick.cell_count() == 0 {
                        assert_eq!(
                            brick.sample_dims().x * brick.sample_dims().y * brick.sample_dims().z,
                            0
                        );
                        continue;
                    }
                    for a in 0..3 {
                        let (lo, hi) = (brick.cells[0][a], brick.cells[1][a]);
                        let want_lo = if lo == 0 { 0 } else { lo - 1 };
                        let want_hi = if hi == dims[a] { samples[a] } else { hi + 2 };
                        assert_eq!(brick.samples[0][a], want_lo, "{brick:?}");
                        assert_eq!(brick.samples[1][a], want_hi, "{brick:?}");
                    }
                }
            }
        }
        let whole = Brick::whole(UVec3::new(4, 5, 6));
        assert_eq!(whole.samples, [UVec3::ZERO, UVec3::new(5, 6, 7)]);
        assert!(whole.owns(UVec3::new(3, 4, 5)) && !whole.owns(UVec3::new(4, 0, 0)));
    }

    #[test]
    fn more_parts_than_cells_leaves_empty_bricks() {
        let bricks = kd_bricks(UVec3::new(2, 1, 1), 3);
        assert_eq!(bricks.iter().map(Brick::cell_count).sum::<u64>(), 2);
        assert_eq!(bricks.iter().filter(|b| b.cell_count() == 0).count(), 1);
    }

    /// A triangle's corners: position, normal and scalar bits.
    type Corners = [[u32; 7]; 3];

    /// Marching cubes over every cell of `volume` in cell order, as the
    /// isosurface pipeline numbers triangles: `(local cell, corners)`.
    fn march(volume: &crate::volume::Volume, level: f32) -> Vec<(u32, Corners)> {
        use crate::functors::isosurface::{case_index, cell_origin, corner_values, edge_vertex};
        let tables = crate::marching_cubes_tables::tables();
        let mut out = Vec::new();
        for cell in 0..volume.cell_count() as u32 {
            let origin = cell_origin(volume, cell, "test").unwrap();
            let values = corner_values(volume, origin);
            for edges in tables.case_triangles(case_index(&values, level)) {
                let corners = edges.map(|edge| {
                    let (p, n, s) = edge_vertex(volume, origin, &values, edge, level);
                    let [px, py, pz] = p.to_array().map(f32::to_bits);
                    let [nx, ny, nz] = n.to_array().map(f32::to_bits);
                    [px, py, pz, nx, ny, nz, s.to_bits()]
                });
                out.push((cell, corners));
            }
        }
        out
    }

    #[test]
    fn bricks_keep_exactly_the_whole_surface_with_its_triangle_ids() {
        use crate::volume::generate::Dataset;
        let dims = UVec3::new(17, 13, 11);
        let cell_dims = dims - UVec3::ONE;
        for dataset in [
            Dataset::Sphere,
            Dataset::RichtmyerMeshkov,
            Dataset::LeadTelluride,
        ] {
            let level = dataset.default_level();
            let whole = march(&dataset.generate(dims).unwrap(), level);
            assert!(whole.len() > 100, "{dataset:?}: {}", whole.len());
            for parts in 1..=5 {
                let bricks = kd_bricks(cell_dims, parts);
                let mut kept = Vec::new();
                let mut summaries = Vec::new();
                for brick in &bricks {
                    let volume = dataset.generate_brick(dims, brick).unwrap();
                    let triangles = march(&volume, level);
                    let cells: Vec<u32> = triangles.iter().map(|t| t.0).collect();
                    let owned = owned_triangles(&cells, &volume, brick);
                    summaries.push(triangle_summary(brick, &owned.global_cells));
                    kept.push((triangles, owned));
                }
                let mut numbered = vec![None; whole.len()];
                for (rank, (triangles, owned)) in kept.iter().enumerate() {
                    let ids = global_triangle_ids(&summaries, rank, cell_dims, &owned.global_cells)
                        .unwrap();
                    assert_eq!(ids.len(), owned.indices.len());
                    for ((&id, &t), &cell) in
                        ids.iter().zip(&owned.indices).zip(&owned.global_cells)
                    {
                        let slot = &mut numbered[id as usize];
                        assert!(slot.is_none(), "{dataset:?} {parts}: id {id} twice");
                        *slot = Some((
                            global_cell_index(cell, cell_dims) as u32,
                            triangles[t as usize].1,
                        ));
                    }
                }
                let numbered: Vec<_> = numbered
                    .into_iter()
                    .map(|t| t.expect("every id is given"))
                    .collect();
                assert_eq!(numbered, whole, "{dataset:?} in {parts} bricks");
            }
        }
    }

    #[test]
    fn malformed_summaries_and_cells_are_errors() {
        let cell_dims = UVec3::new(4, 3, 2);
        let bricks = kd_bricks(cell_dims, 2);
        let summaries: Vec<Vec<u32>> = bricks.iter().map(|b| triangle_summary(b, &[])).collect();
        assert!(global_triangle_ids(&summaries, 0, cell_dims, &[])
            .unwrap()
            .is_empty());
        assert!(matches!(
            global_triangle_ids(&summaries, 2, cell_dims, &[]),
            Err(TriangleIdError::NoSuchRank { .. })
        ));
        let mut bad = summaries.clone();
        bad[1].pop();
        assert!(matches!(
            global_triangle_ids(&bad, 0, cell_dims, &[]),
            Err(TriangleIdError::BadSummary { rank: 1, .. })
        ));
        let outside = bricks[1].cells[0];
        assert!(matches!(
            global_triangle_ids(&summaries, 0, cell_dims, &[outside]),
            Err(TriangleIdError::BadCell { index: 0, .. })
        ));
        let lo = bricks[0].cells[0];
        assert!(matches!(
            global_triangle_ids(&summaries, 0, cell_dims, &[lo + UVec3::Y, lo]),
            Err(TriangleIdError::BadCell { index: 1, .. })
        ));
    }
}
