//! The shading functors together in the project's WORKLOAD3 pipeline
//! (pipelines/workload3.dpp) on the CPU backend: the output does not depend on fusion,
//! chunking or the order rays are traced in, and each effect (reflection, ambient occlusion, shadows, samples
//! per pixel) changes the picture.

use dpp_runtime::compile::{compile_file, CompileOptions};
use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::exec::{run_plan, RunContext};
use dpp_runtime::interpret::OutputValue;
use dpp_tracer::shading::{Material, MeshMaterials};
use dpp_tracer::{Camera, CameraSetup, PointLight, TraceResources, TraceScene, TriangleMesh};
use glam::Vec3;
use std::path::Path;
use std::sync::Arc;

const WIDTH: u32 = 16;
const HEIGHT: u32 = 12;

/// A mirror floor (material 1) and a box standing on it (material 0).
fn scene() -> TraceScene {
    let mut positions = vec![
        Vec3::new(-2.0, 0.0, -2.0),
        Vec3::new(2.0, 0.0, -2.0),
        Vec3::new(2.0, 0.0, 2.0),
        Vec3::new(-2.0, 0.0, 2.0),
    ];
    let mut triangles = vec![[0, 3, 2], [0, 2, 1]];
    let corner = |i: u32| {
        Vec3::new(
            if i & 1 == 0 { -0.4 } else { 0.4 },
            if i & 2 == 0 { 0.0 } else { 0.8 },
            if i & 4 == 0 { -0.4 } else { 0.4 },
        )
    };
    positions.extend((0..8).map(corner));
    for [a, b, c, d] in [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
    ] {
        triangles.push([a + 4, b + 4, c + 4]);
        triangles.push([a + 4, c + 4, d + 4]);
    }
    let mesh = TriangleMesh {
        positions,
        triangles,
        normals: None,
        scalars: None,
    };
    let mut mirror = Material::named("mirror");
    mirror.reflectivity = 0.5;
    let mut triangle_materials = vec![1, 1];
    triangle_materials.extend([0; 12]);
    let materials = MeshMaterials {
        materials: vec![Material::named("default"), mirror],
        triangle_materials,
    };
    TraceScene::with_materials(mesh, materials).unwrap()
}

fn resources() -> TraceResources {
    let camera = Camera::new(
        Vec3::new(0.0, 1.5, 4.0),
        Vec3::new(0.0, 0.3, 0.0),
        Vec3::Y,
        45.0,
        WIDTH,
        HEIGHT,
    )
    .unwrap();
    TraceResources::new(Arc::new(scene()), Arc::new(CameraSetup::new(camera)))
}

fn render(
    resources: &TraceResources,
    overrides: &[(&str, &str)],
    fuse: bool,
    chunk: usize,
) -> Vec<Vec3> {
    let library = dpp_tracer::functor_library();
    let options = CompileOptions {
        fuse,
        overrides: overrides
            .iter()
            .map(|(name, value)| (name.to_string(), value.to_string()))
            .collect(),
    };
    let pipeline = Path::new(env!("CARGO_MANIFEST_DIR")).join("../pipelines/workload3.dpp");
    let plan = compile_file(&pipeline, &library, &options)
        .map_err(|failure| failure.render(false))
        .unwrap();
    let uniforms = resources.uniforms();
    let context = RunContext {
        library: &library,
        uniforms: &uniforms,
        resources,
        chunk,
        // Small arrays too, so that each bounce reuses the arrays of the one
        // before it, as a full-size frame's do.
        column_pool: &ColumnPool::keeping_every_size(),
        elementwise: dpp_runtime::cpu::compiled::Elementwise::default(),
    };
    let result = run_plan(&plan, &context).unwrap();
    let OutputValue::Array(image) = &result.outputs[0].1 else {
        panic!("the image is an array")
    };
    let pixels = image.view().as_vec3().to_vec();
    assert_eq!(pixels.len(), (WIDTH * HEIGHT) as usize);
    for pixel in &pixels {
        assert!(
            pixel.min_element() >= 0.0 && pixel.max_element() <= 1.0,
            "{pixel}"
        );
    }
    pixels
}

fn differing(a: &[Vec3], b: &[Vec3]) -> usize {
    a.iter().zip(b).filter(|(a, b)| a != b).count()
}

#[test]
fn fusion_chunking_and_ray_order_do_not_change_the_image() {
    let resources = resources();
    let reference = render(&resources, &[], true, 4096);
    assert_eq!(reference, render(&resources, &[], false, 7));
    assert_eq!(reference, render(&resources, &[], true, 5));
    // `occluded` answers each ray alone: tracing the occlusion and shadow
    // rays in their own order instead of `rayOrderKey`'s gives the same bits.
    let in_order = [("reorder", "false")];
    assert_eq!(reference, render(&resources, &in_order, true, 4096));
    assert_eq!(reference, render(&resources, &in_order, false, 7));
}

#[test]
fn every_effect_shows() {
    let mut resources = resources();
    let image = render(&resources, &[], true, 4096);
    let distinct: std::collections::HashSet<[u32; 3]> = image
        .iter()
        .map(|p| p.to_array().map(f32::to_bits))
        .collect();
    assert!(distinct.len() > 20, "{} distinct colours", distinct.len());
    for (overrides, what) in [
        (&[("maxDepth", "1")][..], "reflections"),
        (&[("aoRange", "0")][..], "ambient occlusion"),
        (&[("spp", "1")][..], "anti-aliasing"),
    ] {
        let changed = differing(&image, &render(&resources, overrides, true, 4096));
        assert!(changed > 0, "{what} change nothing");
    }
    // Moving the only light far below the floor leaves ambient light only.
    let shading = Arc::make_mut(&mut resources.shading);
    shading
        .set_lights(vec![PointLight::new(Vec3::new(0.0, -50.0, 0.0), 1.0)])
        .unwrap();
    let unlit = render(&resources, &[], true, 4096);
    let brightness = |image: &[Vec3]| image.iter().map(|p| p.element_sum()).sum::<f32>();
    assert!(brightness(&unlit) < 0.8 * brightness(&image));
}
