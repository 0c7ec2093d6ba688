//! Times scene generation, BVH build and single-threaded primary-ray tracing of the
//! built-in scene, and writes the normal-coloured picture.
//!
//! `cargo run --release -p dpp-tracer --example primary_rays -- [resolution] [width height] [out.png] [front|back|zoom]`

use dpp_tracer::builtin_scene::{builtin_scene, DEFAULT_RESOLUTION};
use dpp_tracer::bvh::Bvh;
use dpp_tracer::camera::{Camera, CameraSetup, StandardView};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let resolution = args.first().map_or(Ok(DEFAULT_RESOLUTION), |a| a.parse())?;
    let width = args.get(1).map_or(Ok(1920), |a| a.parse())?;
    let height = args.get(2).map_or(Ok(1080), |a| a.parse())?;
    let output = args
        .get(3)
        .cloned()
        .unwrap_or_else(|| "primary_rays.png".into());
    let view: StandardView = args.get(4).map_or("front", String::as_str).parse()?;

    let start = Instant::now();
    let mesh = builtin_scene(resolution)?;
    println!(
        "scene: {} triangles, {} vertices in {:.0} ms",
        mesh.triangles.len(),
        mesh.positions.len(),
        start.elapsed().as_secs_f64() * 1e3
    );
    let start = Instant::now();
    let bvh = Bvh::build(&mesh)?;
    println!(
        "bvh: {} nodes, stack depth {} in {:.0} ms",
        bvh.nodes().len(),
        bvh.stack_depth(),
        start.elapsed().as_secs_f64() * 1e3
    );

    let bounds = mesh.bounds().ok_or("empty mesh")?;
    println!("bounds: {} .. {}", bounds.min, bounds.max);
    let camera = Camera::standard(view, &bounds, width, height)?;
    let setup = CameraSetup::new(camera);
    let rays = setup.pixel_centre_rays();

    let start = Instant::now();
    let hits: Vec<_> = rays.iter().map(|ray| bvh.intersect_closest(ray)).collect();
    let seconds = start.elapsed().as_secs_f64();
    let hit_count = hits.iter().filter(|h| h.is_some()).count();
    println!(
        "closest: {} rays ({} hits) in {:.0} ms: {:.2} Mrays/s single-threaded",
        rays.len(),
        hit_count,
        seconds * 1e3,
        rays.len() as f64 / seconds / 1e6
    );
    let start = Instant::now();
    let blocked = rays
        .iter()
        .filter(|ray| bvh.occluded(ray, f32::INFINITY))
        .count();
    let seconds = start.elapsed().as_secs_f64();
    println!(
        "occluded: {} blocked in {:.0} ms: {:.2} Mrays/s single-threaded",
        blocked,
        seconds * 1e3,
        rays.len() as f64 / seconds / 1e6
    );

    let mut image = image::RgbImage::new(width, height);
    for (&pixel, hit) in setup.morton_pixels.iter().zip(&hits) {
        let colour = match hit {
            Some(hit) => {
                let normal = mesh.face_normal(hit.prim as usize).normalize();
                (normal * 0.5 + 0.5).to_array()
            }
            None => [0.1, 0.1, 0.12],
        };
        image.put_pixel(
            pixel % width,
            pixel / width,
            image::Rgb(colour.map(|c| (c * 255.0).round() as u8)),
        );
    }
    image.save(&output)?;
    println!("wrote {output}");
    Ok(())
}
