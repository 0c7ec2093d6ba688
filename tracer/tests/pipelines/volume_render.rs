//! `pipelines/volume.dpp` against an independent reference: a brute-force
//! ray marcher in f64 written here from the definition in
//! `tracer/src/functors/volume_render/mod.rs` (world-space slabs, trilinear
//! interpolation of the analytic fields' samples, the `grey` map's colour and
//! its 0-to-1 opacity ramp, opacity correction, front-to-back compositing,
//! early termination, the background), on a sphere's distance field, a
//! Gaussian blob and a linear ramp; on the CPU and GPU backends, fused and
//! not, with empty-space skipping (blocks of 2 cells, of which the fields'
//! transparent parts make many empty) and without. A constant field checks
//! one pixel by hand: `1 - (1 - a)^(n·dt/unit)`.

use dpp_gpu::{gpu_for_tests, run_plan_gpu, GpuRunContext};
use dpp_runtime::compile::{compile_file, CompileOptions};
use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::exec::{run_plan, RunContext};
use dpp_runtime::interpret::{OutputValue, RunResult};
use dpp_tracer::volume::Volume;
use dpp_tracer::{Camera, CameraSetup, TraceResources, TraceScene, TriangleMesh};
use glam::{DVec3, UVec3, Vec3};
use std::path::Path;
use std::sync::Arc;

const WIDTH: u32 = 40;
const HEIGHT: u32 = 30;
/// The pipeline's params as the test sets them.
const STEP: f64 = 0.25;
const CUTOFF: f64 = 0.99;
/// Display (sRGB) background and its linear value.
const BACKGROUND: [f32; 3] = [0.2, 0.3, 0.4];

/// A volume of `f` at the samples of an anisotropic grid over about the unit cube.
fn volume(f: impl Fn(DVec3) -> f64) -> Volume {
    let dims = UVec3::new(17, 15, 13);
    let spacing = Vec3::new(1.0 / 16.0, 1.0 / 14.0, 1.2 / 12.0);
    Volume::from_fn(dims, Vec3::new(-0.5, -0.5, -0.6), spacing, |p, _| {
        f(p.as_dvec3()) as f32
    })
}

fn camera() -> Camera {
    Camera::new(
        Vec3::new(0.3, 0.4, 2.2),
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::Y,
        50.0,
        WIDTH,
        HEIGHT,
    )
    .unwrap()
}

fn resources(volume: Volume, range: [f32; 2]) -> TraceResources {
    // The pipeline traces nothing: any scene will do.
    let mesh = TriangleMesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        triangles: vec![[0, 1, 2]],
        normals: None,
        scalars: None,
    };
    let mut resources = TraceResources::new(
        Arc::new(TraceScene::new(mesh).unwrap()),
        Arc::new(CameraSetup::new(camera())),
    );
    let shading = Arc::make_mut(&mut resources.shading);
    shading.set_transfer("grey").unwrap();
    shading.set_scalar_range(range[0], range[1]).unwrap();
    shading.set_background(BACKGROUND).unwrap();
    resources.volume = Some(Arc::new(volume));
    resources
}

/// `(image, alpha)`: the pipeline's sRGB image and its opacity per pixel.
fn render(resources: &TraceResources, fuse: bool, gpu: bool, block: u32) -> (Vec<Vec3>, Vec<f32>) {
    let library = dpp_tracer::functor_library();
    let options = CompileOptions {
        fuse,
        overrides: vec![
            ("step".into(), format!("{STEP:?}")),
            ("cutoff".into(), format!("{CUTOFF:?}")),
            ("block".into(), block.to_string()),
        ],
    };
    let pipeline = Path::new(env!("CARGO_MANIFEST_DIR")).join("../pipelines/volume.dpp");
    let plan = compile_file(&pipeline, &library, &options)
        .map_err(|failure| failure.render(false))
        .unwrap();
    let uniforms = resources.uniforms();
    let result: RunResult = if gpu {
        let context = GpuRunContext {
            gpu: gpu_for_tests().expect("a GPU"),
            library: &library,
            uniforms: &uniforms,
            resources,
            profile: false,
        };
        run_plan_gpu(&plan, &context).unwrap_or_else(|e| panic!("{e}"))
    } else {
        let context = RunContext {
            library: &library,
            uniforms: &uniforms,
            resources,
            chunk: 256,
            column_pool: &ColumnPool::new(),
            elementwise: dpp_runtime::cpu::compiled::Elementwise::default(),
        };
        run_plan(&plan, &context).unwrap()
    };
    let output = |name: &str| match result.outputs.iter().find(|(n, _)| n == name) {
        Some((_, OutputValue::Array(array))) => array.clone(),
        _ => panic!("no `{name}` output"),
    };
    let image = output("image").view().as_vec3().to_vec();
    let alpha = output("alpha").view().as_f32().to_vec();
    (image, alpha)
}

fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn linear_to_srgb(c: f64) -> f64 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// The reference: every pixel marched in f64. `(srgb colour, alpha)`.
fn reference(volume: &Volume, range: [f32; 2]) -> Vec<(DVec3, f64)> {
    let dims = volume.dims.as_dvec3();
    let spacing = volume.spacing.as_dvec3();
    let origin = volume.origin.as_dvec3();
    let (box_min, box_max) = (origin, origin + spacing * (dims - DVec3::ONE));
    let unit = spacing.min_element();
    let dt = STEP * unit;
    let value = |i: usize, j: usize, k: usize| {
        f64::from(volume.values[i + volume.dims.x as usize * (j + volume.dims.y as usize * k)])
    };
    let trilinear = |p: DVec3| {
        let g = ((p - origin) / spacing).clamp(DVec3::ZERO, dims - DVec3::ONE);
        let cell = g.floor().min(dims - DVec3::splat(2.0));
        let f = g - cell;
        let (i, j, k) = (cell.x as usize, cell.y as usize, cell.z as usize);
        let mut sum = 0.0;
        for (dx, dy, dz) in (0..8).map(|c| (c & 1, c >> 1 & 1, c >> 2 & 1)) {
            let w = |d: usize, f: f64| if d == 1 { f } else { 1.0 - f };
            sum += w(dx, f.x) * w(dy, f.y) * w(dz, f.z) * value(i + dx, j + dy, k + dz);
        }
        sum
    };
    let background = DVec3::from(BACKGROUND.map(|c| srgb_to_linear(f64::from(c))));
    let camera = camera();
    let eye = camera.eye.as_dvec3();
    let mut pixels = Vec::new();
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            let dir = camera.direction(x, y, 0.5, 0.5).as_dvec3().normalize();
            let t0 = (box_min - eye) / dir;
            let t1 = (box_max - eye) / dir;
            let near = t0.min(t1).max_element().max(0.0);
            let far = t0.max(t1).min_element();
            let (mut color, mut alpha) = (DVec3::ZERO, 0.0);
            let mut n = 0;
            while near <= far && near + n as f64 * dt <= far && alpha < CUTOFF {
                let s = trilinear(eye + dir * (near + n as f64 * dt));
                let u =
                    ((s - f64::from(range[0])) / f64::from(range[1] - range[0])).clamp(0.0, 1.0);
                let c = DVec3::splat(srgb_to_linear(u));
                let a = 1.0 - (1.0 - u).powf(dt / unit);
                color += (1.0 - alpha) * a * c;
                alpha += (1.0 - alpha) * a;
                n += 1;
            }
            let rgb = color + (1.0 - alpha) * background;
            pixels.push((rgb.to_array().map(linear_to_srgb).into(), alpha));
        }
    }
    pixels
}

/// The fields, each with its scalar range.
fn fields() -> Vec<(&'static str, Volume, [f32; 2])> {
    vec![
        (
            "sphere distance",
            volume(|p| 0.45 - p.length()),
            [0.0, 0.45],
        ),
        (
            "Gaussian blob",
            volume(|p| (-(p - DVec3::new(0.1, 0.0, -0.1)).length_squared() / 0.08).exp()),
            [0.1, 1.0],
        ),
        ("linear ramp", volume(|p| p.x + 0.5 * p.y), [-0.8, 0.8]),
    ]
}

/// The largest and the mean difference of the pipeline's image and alpha from the reference.
fn compare(what: &str, (image, alpha): &(Vec<Vec3>, Vec<f32>), expected: &[(DVec3, f64)]) {
    let mut largest: f64 = 0.0;
    let mut sum = 0.0;
    for (i, (rgb, a)) in expected.iter().enumerate() {
        let d = (image[i].as_dvec3() - *rgb)
            .abs()
            .max_element()
            .max((f64::from(alpha[i]) - a).abs());
        largest = largest.max(d);
        sum += d;
    }
    let mean = sum / expected.len() as f64;
    // f32 sample positions drift from f64's by about an ULP of t per step, so
    // a ray can gain or lose its last sample at the box's far side (a
    // quarter cell's opacity); the mean stays tiny.
    assert!(
        largest < 0.03 && mean < 2e-3,
        "{what}: largest {largest}, mean {mean}"
    );
}

#[test]
fn the_volume_pipeline_matches_a_brute_force_marcher() {
    for (name, volume, range) in fields() {
        let expected = reference(&volume, range);
        let resources = resources(volume, range);
        assert!(
            expected.iter().any(|(_, a)| *a > 0.3),
            "{name}: the volume is seen"
        );
        for (fuse, block) in [(true, 0), (false, 0), (true, 2), (false, 2)] {
            let what = format!("{name}, fuse {fuse}, block {block}");
            compare(&what, &render(&resources, fuse, false, block), &expected);
        }
    }
}

#[test]
fn the_gpu_backend_renders_the_same_volume() {
    if gpu_for_tests().is_none() {
        return;
    }
    for (name, volume, range) in fields() {
        let expected = reference(&volume, range);
        let resources = resources(volume, range);
        let (cpu, gpu) = (
            render(&resources, true, false, 2),
            render(&resources, true, true, 2),
        );
        compare(&format!("{name} on the GPU"), &gpu, &expected);
        let largest = (cpu.0.iter().zip(&gpu.0))
            .map(|(a, b)| (*a - *b).abs().max_element())
            .fold(0.0, f32::max);
        assert!(
            largest < 1e-3,
            "{name}: CPU and GPU images differ by {largest}"
        );
    }
}

#[test]
fn a_constant_field_has_the_opacity_of_its_depth() {
    // Opacity 0.2 per cell everywhere; the centre pixel of a camera looking
    // straight down -z crosses the whole depth, 1.2, in n samples dt apart.
    let volume = volume(|_| 0.2);
    let mut resources = resources(volume, [0.0, 1.0]);
    let camera = Camera::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, Vec3::Y, 10.0, 3, 3).unwrap();
    resources.camera = Arc::new(CameraSetup::new(camera));
    let (_, alpha) = render(&resources, true, false, 0);
    let unit: f64 = 1.0 / 16.0;
    let dt = STEP * unit;
    let n = (1.2 / dt + 1e-9).floor() + 1.0;
    let expected = 1.0 - 0.8f64.powf(n * dt / unit);
    assert!(
        (f64::from(alpha[4]) - expected).abs() < 2e-3,
        "{} vs {expected}",
        alpha[4]
    );
}
