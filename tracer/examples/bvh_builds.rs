//! Times the three BVH builders side by side on one mesh: each round builds
//! with each builder in turn (the first one rotating), and the report gives
//! each builder's median and least time over the rounds.
//!
//! `cargo run --release -p dpp-tracer --example bvh_builds -- MESH.ply|MESH.obj|builtin:N [ROUNDS] [THREADS]`

use dpp_tracer::builtin_scene::builtin_scene;
use dpp_tracer::bvh::{Bvh, BvhBuilder};
use dpp_tracer::mesh::TriangleMesh;
use std::path::Path;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene = args
        .first()
        .ok_or("usage: bvh_builds MESH [ROUNDS] [THREADS]")?;
    let rounds: usize = args.get(1).map_or(Ok(5), |a| a.parse())?;
    if let Some(threads) = args.get(2) {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads.parse()?)
            .build_global()?;
    }
    let mesh = load(scene)?;
    let builders = [BvhBuilder::BinnedSah, BvhBuilder::Ploc, BvhBuilder::Lbvh];
    let mut times = vec![Vec::new(); builders.len()];
    for round in 0..rounds {
        for k in 0..builders.len() {
            let which = (round + k) % builders.len();
            let start = Instant::now();
            let bvh = Bvh::build_with(&mesh, builders[which])?;
            times[which].push(start.elapsed().as_secs_f64() * 1e3);
            drop(bvh);
        }
    }
    println!(
        "{scene}: {} triangles, {rounds} rounds",
        mesh.triangles.len()
    );
    for (builder, mut ms) in builders.iter().zip(times) {
        ms.sort_by(f64::total_cmp);
        println!(
            "{builder:?}: median {:.1} ms, least {:.1} ms",
            ms[ms.len() / 2],
            ms[0]
        );
    }
    Ok(())
}

fn load(scene: &str) -> Result<TriangleMesh, Box<dyn std::error::Error>> {
    if let Some(resolution) = scene.strip_prefix("builtin:") {
        return Ok(builtin_scene(resolution.parse()?)?);
    }
    let path = Path::new(scene);
    Ok(if scene.ends_with(".obj") || scene.ends_with(".obj.gz") {
        dpp_tracer::obj::load_obj(path)?
    } else {
        dpp_tracer::ply::load_ply(path)?
    })
}
