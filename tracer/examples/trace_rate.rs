//! Times the wide traversal alone on one thread: a scene's primary rays for
//! each standard view, in Morton order and in chunks of 4096 as
//! `map<intersect>` hands them over, each chunk's hits written field by field
//! as it writes them, traced `rounds` times; prints the fastest
//! round, which a shared, noisy machine disturbs least. To compare two builds
//! of the traversal, run both binaries in turn.
//!
//! `cargo run --release -p dpp-tracer --example trace_rate -- [builtin[:RES] | MESH.ply[.gz]] [rounds] [WxH]`

use dpp_tracer::builtin_scene::{builtin_scene, DEFAULT_RESOLUTION};
use dpp_tracer::bvh::{Bvh, HitPlaces, Ray, MISS_PRIM};
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
        let mut columns = HitColumns::with_capacity(CHUNK);
        for _ in 0..rounds {
            hits = 0;
            let start = Instant::now();
            for chunk in rays.chunks(CHUNK) {
                hits += columns.trace(&bvh, chunk);
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

/// A chunk's hits, one column per field of the `Hit` record.
struct HitColumns {
    t: Vec<f32>,
    prim: Vec<u32>,
    u: Vec<f32>,
    v: Vec<f32>,
}

impl HitColumns {
    fn with_capacity(len: usize) -> HitColumns {
        HitColumns {
            t: Vec::with_capacity(len),
            prim: Vec::with_capacity(len),
            u: Vec::with_capacity(len),
            v: Vec::with_capacity(len),
        }
    }

    /// Traces `rays` (at most the capacity) into the columns; how many hit.
    fn trace(&mut self, bvh: &Bvh, rays: &[Ray]) -> usize {
        self.t.clear();
        self.prim.clear();
        self.u.clear();
        self.v.clear();
        bvh.intersect_closest_into(
            rays.len(),
            |i| rays[i],
            HitPlaces {
                t: self.t.spare_capacity_mut(),
                prim: self.prim.spare_capacity_mut(),
                u: self.u.spare_capacity_mut(),
                v: self.v.spare_capacity_mut(),
            },
        );
        // SAFETY: `intersect_closest_into` wrote the first `rays.len()` places.
        unsafe {
            self.t.set_len(rays.len());
            self.prim.set_len(rays.len());
            self.u.set_len(rays.len());
            self.v.set_len(rays.len());
        }
        self.prim.iter().filter(|&&prim| prim != MISS_PRIM).count()
    }
}
