//! Times camera packets whose rays run along a slab: columns of rays from
//! one origin each, with a direction whose x component is exactly 0, so that
//! a packet's frustum bounds only y and z (an infinite inverse bounds
//! nothing). One thread, the built-in scene, fastest of five rounds; run it
//! on two builds to compare them.
//!
//! `cargo run --release -p dpp-tracer --example slab_packets`

use dpp_tracer::builtin_scene::{builtin_scene, DEFAULT_RESOLUTION};
use dpp_tracer::bvh::{Bvh, Ray};
use glam::Vec3;
use std::time::Instant;

const COLUMNS: usize = 256;
const ROWS: usize = 2048;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mesh = builtin_scene(DEFAULT_RESOLUTION)?;
    let bvh = Bvh::build(&mesh)?;
    let bounds = mesh.bounds().ok_or("empty mesh")?;
    let (low, high) = (bounds.min, bounds.max);
    let centre = (low + high) * 0.5;
    let eye_z = high.z + (high - low).length();
    let mut rays = Vec::with_capacity(COLUMNS * ROWS);
    for column in 0..COLUMNS {
        let x = low.x + (high.x - low.x) * (column as f32 + 0.5) / COLUMNS as f32;
        let origin = Vec3::new(x, centre.y, eye_z);
        for row in 0..ROWS {
            let y = low.y + (high.y - low.y) * (row as f32 + 0.5) / ROWS as f32;
            rays.push(Ray {
                origin,
                direction: Vec3::new(0.0, y - centre.y, centre.z - eye_z),
                tmax: f32::INFINITY,
            });
        }
    }
    let mut fastest = f64::INFINITY;
    let mut hits = 0usize;
    for _ in 0..5 {
        hits = 0;
        let start = Instant::now();
        for chunk in rays.chunks(4096) {
            bvh.intersect_closest_batch(
                chunk.len(),
                |i| chunk[i],
                |hit| hits += usize::from(hit.is_some()),
            );
        }
        fastest = fastest.min(start.elapsed().as_secs_f64());
    }
    println!(
        "{} rays along a slab: {hits} hits, fastest of 5 {:.1} ms",
        rays.len(),
        fastest * 1e3
    );
    Ok(())
}
