//! `rayOrderKey(ray: Ray) -> (key: u32)`: a sort key that puts rays which
//! walk the same BVH nodes next to each other, for
//! `sortByKey(map<rayOrderKey>(rays), iota(len(rays)))` before tracing them
//! (the prelude's `occludedInOrder`).
//!
//! The key is the Morton code of the cell the origin lies in, above the
//! direction's octant (its three sign bits, x lowest: `-0` counts as
//! negative). Cells are cubes: the scene's box (the `scene.boundsMin` and
//! `scene.boundsMax` uniforms) is split along its longest side into at most
//! 512, the cell size a power of two, so that quantising is a subtraction and
//! an exact multiplication and both backends give the same cell. Origins
//! outside the box go to the nearest cell, ones with a non-finite component
//! to cell 0, and dead rays (`tmax <= 0`, which `occluded` and `intersect`
//! answer without tracing) get the largest key, `4294967295`, behind every
//! live ray.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{vector_module, TwinParts};
use crate::functors::RayColumns;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use glam::{UVec3, Vec3};
use std::sync::Arc;

/// Bits of a cell coordinate per axis: 3 × 9 Morton bits and 3 octant bits
/// leave the dead rays' key above every live one.
const CELL_BITS: u32 = 9;

/// The key of a dead ray.
pub const DEAD_RAY_KEY: u32 = u32::MAX;

pub fn functor(ray: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("rayOrderKey")
        .input("ray", ElemType::Record(ray))
        .output("key", ElemType::U32)
        .doc("a sort key for coherent tracing: the Morton code of the origin's cell in the scene's box above the direction's octant; 4294967295 for a dead ray");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`: the same cells, from the bits of the same floats.
fn twin_parts(_: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    Ok(TwinParts {
        constants: vec![("CELL_BITS", format!("{CELL_BITS}u"))],
        modules: vec![vector_module()],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let bound = |field| {
        ctx.uniforms
            .get("scene", field)
            .and_then(|value| value.as_vec3())
            .ok_or_else(|| {
                FunctorError::bad_input(format!(
                    "rayOrderKey: the scene.{field} uniform is missing (no scene loaded?)"
                ))
            })
    };
    let grid = CellGrid::new(bound("boundsMin")?, bound("boundsMax")?);
    let rays = RayColumns::new(&inputs[0]);
    outputs[0].as_u32_mut().extend((0..rays.len()).map(|i| {
        if rays.tmax[i] > 0.0 {
            grid.morton_code(rays.origin[i]) << 3 | octant(rays.dir[i])
        } else {
            DEAD_RAY_KEY
        }
    }));
    Ok(())
}

/// The cubic cells of a box: its lower corner and the power of two that
/// scales offsets from it to cell coordinates.
struct CellGrid {
    min: Vec3,
    scale: f32,
}

impl CellGrid {
    fn new(min: Vec3, max: Vec3) -> CellGrid {
        let extent = (max - min).max_element();
        let bits = extent.to_bits();
        // A box that is empty, flat in every direction or inverted is one cell.
        let scale = if bits as i32 <= 0 {
            0.0
        } else {
            // `extent < 2^(e - 126)` for the biased exponent `e`, so cells of
            // `2^(e - 126 - CELL_BITS)` number at most `2^CELL_BITS` along it;
            // the scale's own biased exponent, `127 + 126 + CELL_BITS - e`, is
            // kept in the normal range (a box below 2^-119 has fewer cells).
            let exponent = (bits >> 23).max(CELL_BITS - 1);
            f32::from_bits((253 + CELL_BITS - exponent) << 23)
        };
        CellGrid { min, scale }
    }

    /// The Morton code (x in bits 0, 3, 6, …) of the cell that holds `point`.
    fn morton_code(&self, point: Vec3) -> u32 {
        if !point.is_finite() {
            return 0;
        }
        let last = ((1u32 << CELL_BITS) - 1) as f32;
        // Finite minus finite times a power of two: exact on both backends, and
        // never NaN, so the clamp sees a number.
        let cell = ((point - self.min) * self.scale).clamp(Vec3::ZERO, Vec3::splat(last));
        let cell = UVec3::new(cell.x as u32, cell.y as u32, cell.z as u32);
        spread_bits(cell.x) | spread_bits(cell.y) << 1 | spread_bits(cell.z) << 2
    }
}

/// The low 10 bits of `x` moved to bits 0, 3, 6, …, 27.
fn spread_bits(x: u32) -> u32 {
    let x = x & 0x3ff;
    let x = (x | x << 16) & 0x0300_00ff;
    let x = (x | x << 8) & 0x0300_f00f;
    let x = (x | x << 4) & 0x030c_30c3;
    (x | x << 2) & 0x0924_9249
}

/// The direction's sign bits: x in bit 0, y in bit 1, z in bit 2.
fn octant(dir: Vec3) -> u32 {
    dir.x.to_bits() >> 31 | (dir.y.to_bits() >> 31) << 1 | (dir.z.to_bits() >> 31) << 2
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::functors::test_support::{ray, Fixture};
    use crate::functors::RayRecord;

    fn keys(fixture: &Fixture, rays: &[RayRecord]) -> Vec<u32> {
        let rays = fixture.rays(rays);
        let out = fixture.run("rayOrderKey", &[], 0, &[rays.view()]).unwrap();
        out[0].view().as_u32().to_vec()
    }

    #[test]
    fn spreading_bits_interleaves() {
        assert_eq!(spread_bits(0b1011), 0b001_000_001_001);
        assert_eq!(spread_bits(0x1ff), 0x0924_9249 & 0x07ff_ffff);
    }

    #[test]
    fn cells_are_cubes_of_a_power_of_two_covering_the_box() {
        // The fixture's box is 10 × 10 × 1: cells of 2^-5 (512 of them would be
        // 16 long, 10 needs 2^9 × 2^-5 = 16).
        let grid = CellGrid::new(Vec3::new(-5.0, -5.0, -1.0), Vec3::new(5.0, 5.0, 0.0));
        assert_eq!(grid.scale, 32.0);
        assert_eq!(grid.morton_code(Vec3::new(-5.0, -5.0, -1.0)), 0);
        assert_eq!(
            grid.morton_code(Vec3::new(-5.0 + 1.0 / 32.0, -5.0, -1.0)),
            1
        );
        assert_eq!(
            grid.morton_code(Vec3::new(-5.0, -5.0, -1.0 + 1.0 / 32.0)),
            4
        );
        // The far corner is cell 320 along x and y, 32 along z, and outside
        // points clamp to the last cell.
        let far = grid.morton_code(Vec3::new(5.0, 5.0, 0.0));
        assert_eq!(
            far,
            spread_bits(320) | spread_bits(320) << 1 | spread_bits(32) << 2
        );
        assert_eq!(
            grid.morton_code(Vec3::new(1e30, -1e30, 0.0)),
            spread_bits(511) | spread_bits(32) << 2
        );
        assert_eq!(grid.morton_code(Vec3::new(f32::NAN, 0.0, 0.0)), 0);
        // A flat box is one cell.
        let flat = CellGrid::new(Vec3::ONE, Vec3::ONE);
        assert_eq!(flat.morton_code(Vec3::new(3.0, -2.0, 7.0)), 0);
    }

    #[test]
    fn keys_order_by_cell_then_octant_with_dead_rays_last() {
        let fixture = Fixture::new();
        let origin = Vec3::new(-5.0, -5.0, -1.0);
        let next_cell = origin + Vec3::new(1.0 / 32.0, 0.0, 0.0);
        let keys = keys(
            &fixture,
            &[
                ray(origin, Vec3::new(1.0, 1.0, 1.0), 1.0, 0),
                ray(origin, Vec3::new(-1.0, 1.0, -0.0), 1.0, 1),
                ray(next_cell, Vec3::new(1.0, 1.0, 1.0), 1.0, 2),
                RayRecord::dead(3, 0),
            ],
        );
        assert_eq!(keys, [0, 0b101, 1 << 3, DEAD_RAY_KEY]);
    }
}
