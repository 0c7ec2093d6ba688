//! Times the wide traversal alone on one thread: a scene's primary rays for
//! each standard view, in Morton order and in chunks of 4096 as
//! `map<intersect>` hands them over, traced `rounds` times; prints the fastest
//! round, which a shared, noisy machine disturbs least. To compare two builds
//! of the traversal, run both binaries in turn.
//!
//! `cargo run --release -p dpp-tracer --example trace_rate -- [builtin[:RES] | MESH.ply[.gz]] [rounds] [WxH]`

use dpp_tracer::builtin_scene::{builtin_scene, DEFAULT_RESOLUTION};
use dpp_tracer::bvh::Bvh;
use dpp_tracer::camera::{Camera, CameraSetup, StandardView};
use dpp_tracer::ply::load_ply;
use std::path::Path;
use std::time::Instant;

const CHUNK: usize = 4096;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene = args.first().map_or("builtin", String::as_str);
    let rounds: usize = args.get(1).map_or(Ok(9), |a| a.parse())?;
    let (width, height) = match args.get(2) {
        Some(size) => {
            let (w, h) = size.split_once('x').ok_or("size is WxH")?;
            (w.parse()?, h.parse()?)
        }
        None => (1920u32, 1080u32),
    };
    let mesh = match scene.strip_prefix("builtin") {
        Some(rest) => {
            let resolution = match rest.strip_prefix(':') {
                Some(r) => r.parse()?,
                None => DEFAULT_RESOLUTION,
            };
            builtin_scene(resolution)?
        }
        None => load_ply(Path::new(scene))?,
    };
    let bvh = Bvh::build(&mesh)?;
    let bounds = mesh.bounds().ok_or("empty mesh")?;
    for view in [StandardView::Front, StandardView::Back, StandardView::Zoom] {
        let setup = CameraSetup::new(Camera::standard(view, &bounds, width, height)?);
        let rays = setup.pixel_centre_rays();
        let mut fastest = f64::INFINITY;
        let mut hits = 0usize;
        for _ in 0..rounds {
            hits = 0;
            let start = Instant::now();
            for chunk in rays.chunks(CHUNK) {
                bvh.intersect_closest_batch(
                    chunk.len(),
                    |i| chunk[i],
                    |hit| hits += usize::from(hit.is_some()),
                );
            }
            fastest = fastest.min(start.elapsed().as_secs_f64());
        }
        println!(
            "{scene} {view:?}: {hits} hits, fastest of {rounds} {:.1} ms, {:.2} Mrays/s",
            fastest * 1e3,
            rays.len() as f64 / fastest / 1e6
        );
    }
    Ok(())
}
