//! The twins of every tracer functor compile (naga) against the real scene
//! resources of the test fixture, alone and all in one shader; the buffers
//! hold what the CPU reads, in the documented layouts, built once.

use super::buffers::{CameraFrame, MarchingCubesGpuBuffers, SceneGpuBuffers, ShadingGpuBuffers};
use super::{f32_literal, instantiate};
use crate::camera::{sample_offset, Camera};
use crate::functors::isosurface::VolumeResources;
use crate::functors::test_support::{checked_twin, Fixture};
use crate::marching_cubes_tables::tables;
use crate::register_isosurface_functors;
use crate::shading::PointLight;
use crate::volume::generate;
use dpp_gpu::validate_wgsl;
use dpp_runtime::wgsl::{
    collect_dependencies, elem_type_wgsl, host_type_wgsl, record_structs, twin_parameters,
    GpuBuffer, WgslTwin,
};
use dpp_runtime::FunctorKind;
use glam::{UVec3, Vec3};
use std::any::Any;
use std::fmt::Write;
use std::sync::Arc;

/// Which resources a functor's twin reads.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Reads {
    /// `TraceResources`: scene, camera or shading buffers.
    Scene,
    /// `VolumeResources`.
    Volume,
    /// Nothing of the run (like its CPU implementation).
    Nothing,
}

const TWINS: [(&str, Reads); 31] = [
    ("cameraRay", Reads::Scene),
    ("intersect", Reads::Scene),
    ("occluded", Reads::Scene),
    ("normalColor", Reads::Scene),
    ("surface", Reads::Scene),
    ("shader", Reads::Scene),
    ("shadowRay", Reads::Scene),
    ("occRayGen", Reads::Nothing),
    ("visibleLights", Reads::Nothing),
    ("reflectRay", Reads::Scene),
    ("alive", Reads::Nothing),
    ("rayOrderKey", Reads::Nothing),
    ("antiAlias", Reads::Nothing),
    ("globalId", Reads::Scene),
    ("material", Reads::Scene),
    ("light", Reads::Scene),
    ("colormap", Reads::Scene),
    ("withWeight", Reads::Nothing),
    ("clipRay", Reads::Nothing),
    ("cubeCase", Reads::Volume),
    ("caseTriangles", Reads::Nothing),
    ("cubeTriangle", Reads::Volume),
    ("volumeEntry", Reads::Scene),
    ("volumeMarch", Reads::Scene),
    ("marchLive", Reads::Nothing),
    ("overBackground", Reads::Scene),
    ("cellRange", Reads::Scene),
    ("cellBlock", Reads::Scene),
    ("transparent", Reads::Scene),
    ("marchBlock", Reads::Scene),
    ("skipEmpty", Reads::Scene),
];

/// The fixture's library with the isosurface functors too, and a small
/// volume, also in the fixture's resources for the volume renderer.
fn fixture() -> (Fixture, VolumeResources) {
    let mut fixture = Fixture::new();
    register_isosurface_functors(&mut fixture.library);
    let volume = VolumeResources {
        volume: Arc::new(generate::sphere(UVec3::new(5, 6, 7), 0.75)),
    };
    fixture.resources.volume = Some(volume.volume.clone());
    (fixture, volume)
}

fn resources_for<'a>(
    reads: Reads,
    fixture: &'a Fixture,
    volume: &'a VolumeResources,
) -> &'a (dyn Any + Send + Sync) {
    match reads {
        Reads::Scene | Reads::Nothing => &fixture.resources,
        Reads::Volume => volume,
    }
}

/// Every buffer a twin binds, its modules' included.
fn all_buffers(twin: &WgslTwin) -> Vec<GpuBuffer> {
    let (mut modules, mut buffers) = (Vec::new(), Vec::new());
    collect_dependencies(twin, &mut modules, &mut buffers);
    buffers
}

#[test]
fn every_tracer_functor_has_a_twin_that_validates() {
    let (fixture, volume) = fixture();
    let mut names: Vec<&str> = fixture.library.names().collect();
    names.sort_unstable();
    let mut listed: Vec<&str> = TWINS.iter().map(|(name, _)| *name).collect();
    listed.sort_unstable();
    assert_eq!(
        names, listed,
        "every functor of the library is in the table"
    );
    for (name, reads) in TWINS {
        let resources = resources_for(reads, &fixture, &volume);
        let twin = checked_twin(&fixture.library, name, resources)
            .unwrap_or_else(|error| panic!("{name}:\n{error}"));
        assert!(
            twin.source.contains(&format!("fn stage7_{name}(")),
            "{name}"
        );
        // Without the resources it reads, a twin is an error that says so.
        let without = checked_twin(&fixture.library, name, &());
        match reads {
            Reads::Nothing => assert!(without.is_ok(), "{name}: {without:?}"),
            _ => {
                let error = without.unwrap_err();
                assert!(error.contains("no scene loaded"), "{name}: {error}");
            }
        }
    }
}

#[test]
fn all_twins_compile_together_in_one_shader() {
    // Twins share modules and buffers by name; their own helpers are prefixed
    // by their function names, so any set of them fits in one shader.
    let (fixture, volume) = fixture();
    let library = &fixture.library;
    let mut source = record_structs(&library.records);
    for (record, fields) in &library.uniforms.records {
        for (field, ty) in fields {
            let wgsl = host_type_wgsl(*ty);
            let _ = writeln!(
                source,
                "fn uniform_{record}_{field}() -> {wgsl} {{ return {wgsl}(); }}"
            );
        }
    }
    let (mut modules, mut buffers) = (Vec::new(), Vec::new());
    let mut twins = String::new();
    let mut calls = String::new();
    for (name, reads) in TWINS {
        let twin = checked_twin(library, name, resources_for(reads, &fixture, &volume)).unwrap();
        collect_dependencies(&twin, &mut modules, &mut buffers);
        let function = format!("stage7_{name}");
        let signature = library.get(name).unwrap().signature();
        let _ = writeln!(twins, "fn {function}_fail(code: u32) {{ }}");
        let inputs: Vec<_> = signature
            .inputs
            .iter()
            .map(|p| match p.ty {
                dpp_runtime::TypePattern::Exact(ty) => ty,
                dpp_runtime::TypePattern::Var(..) => unreachable!(),
            })
            .collect();
        if signature.kind == FunctorKind::Group {
            let ty = elem_type_wgsl(inputs[0], &library.records);
            let _ = writeln!(
                twins,
                "fn {function}_src(i: u32) -> {ty} {{ return {ty}(); }}"
            );
        }
        twins.push_str(&twin.source);
        let arguments: Vec<String> = twin_parameters(signature, &inputs, &library.records)
            .iter()
            .map(|(_, ty)| format!("{ty}()"))
            .collect();
        let _ = writeln!(calls, "    _ = {function}({});", arguments.join(", "));
    }
    for (binding, buffer) in buffers.iter().enumerate() {
        let _ = writeln!(
            source,
            "@group(1) @binding({binding}) var<storage, read> {}: {};",
            buffer.name, buffer.wgsl_type
        );
    }
    for module in &modules {
        source.push_str(&module.source);
    }
    source.push_str(&twins);
    let _ = writeln!(
        source,
        "@compute @workgroup_size(64)\nfn main() {{\n{calls}}}"
    );
    validate_wgsl(&source).unwrap_or_else(|error| panic!("{error}"));
    let mut names: Vec<&str> = buffers.iter().map(|b| b.name).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), buffers.len(), "one buffer per name");
    assert_eq!(buffers.len(), 17, "{names:?}");
}

#[test]
fn twins_hand_out_the_buffers_built_once_until_the_shading_changes() {
    let (mut fixture, volume) = fixture();
    let buffers_of = |fixture: &Fixture, name: &str| {
        let (_, reads) = TWINS.iter().find(|(n, _)| *n == name).unwrap();
        all_buffers(
            &checked_twin(
                &fixture.library,
                name,
                resources_for(*reads, fixture, &volume),
            )
            .unwrap(),
        )
    };
    let same = |a: &[GpuBuffer], b: &[GpuBuffer]| {
        a.len() == b.len() && a.iter().zip(b).all(|(a, b)| Arc::ptr_eq(&a.data, &b.data))
    };
    for name in [
        "intersect",
        "surface",
        "cameraRay",
        "shader",
        "cubeTriangle",
        "caseTriangles",
    ] {
        let first = buffers_of(&fixture, name);
        assert!(!first.is_empty(), "{name}");
        assert!(same(&first, &buffers_of(&fixture, name)), "{name}");
    }
    // `occluded` shares the BVH of `intersect`.
    let intersect = buffers_of(&fixture, "intersect");
    assert!(same(&intersect, &buffers_of(&fixture, "occluded")));

    let lights_before = buffers_of(&fixture, "shadowRay");
    let scene_before = buffers_of(&fixture, "surface");
    let light = PointLight::new(Vec3::new(1.0, 2.0, 3.0), 0.5);
    fixture.set_shading(|shading| shading.set_lights(vec![light]).unwrap());
    let lights_after = buffers_of(&fixture, "shadowRay");
    assert!(!same(&lights_before, &lights_after));
    let words: Vec<f32> = lights_after[0]
        .data
        .iter()
        .map(|w| f32::from_bits(*w))
        .collect();
    assert_eq!(words, [1.0, 2.0, 3.0, 0.5, 1.0, 1.0, 1.0, 0.0]);
    assert!(same(&lights_after, &buffers_of(&fixture, "shadowRay")));
    assert!(same(&scene_before, &buffers_of(&fixture, "surface")));
}

fn floats(words: &[u32]) -> Vec<f32> {
    words.iter().map(|w| f32::from_bits(*w)).collect()
}

#[test]
fn scene_buffers_hold_the_cpu_layouts() {
    let fixture = Fixture::new();
    let scene = &fixture.resources.scene;
    let buffers: &SceneGpuBuffers = scene.gpu_buffers();
    let bvh = &scene.bvh;
    // Node n: per child (min, index bits), (max, count bits).
    let nodes = &buffers.bvh_nodes.data;
    assert_eq!(nodes.len(), 16 * bvh.nodes().len());
    for (n, node) in bvh.nodes().iter().enumerate() {
        for (side, child) in node.children.iter().enumerate() {
            let at = 16 * n + 8 * side;
            assert_eq!(floats(&nodes[at..at + 3]), child.min);
            assert_eq!(nodes[at + 3], child.index);
            assert_eq!(floats(&nodes[at + 4..at + 7]), child.max);
            assert_eq!(nodes[at + 7], child.count);
        }
    }
    let triangles = floats(&buffers.bvh_triangles.data);
    for (i, triangle) in bvh.triangles().iter().enumerate() {
        let expected: Vec<f32> = [triangle.v0, triangle.v1, triangle.v2].concat();
        assert_eq!(triangles[9 * i..9 * i + 9], expected);
    }
    assert_eq!(&*buffers.bvh_triangle_ids.data, bvh.triangle_ids());
    // Triangles in file order with their material; vertices with scalar and normal.
    let mesh = &scene.mesh;
    let corners = &buffers.mesh_triangles.data;
    for (t, &[a, b, c]) in mesh.triangles.iter().enumerate() {
        assert_eq!(
            corners[4 * t..4 * t + 4],
            [a, b, c, scene.triangle_material(t as u32)]
        );
    }
    let vertices = floats(&buffers.mesh_vertices.data);
    for (v, position) in mesh.positions.iter().enumerate() {
        let normal = mesh.normals.as_ref().unwrap()[v];
        let scalar = mesh.scalars.as_ref().unwrap()[v];
        let expected = [
            &position.to_array()[..],
            &[scalar],
            &normal.to_array(),
            &[0.0],
        ]
        .concat();
        assert_eq!(vertices[8 * v..8 * v + 8], expected);
    }
}

#[test]
fn shading_buffers_hold_what_the_shader_reads() {
    let mut fixture = Fixture::new();
    fixture.set_shading(|shading| shading.set_scalar_range(-1.0, 3.0).unwrap());
    let shading = &fixture.resources.shading;
    let buffers = ShadingGpuBuffers::new(shading);
    let constants = floats(&buffers.constants.data);
    let background = shading.background();
    assert_eq!(
        constants,
        [
            -1.0,
            3.0,
            0.25,
            0.0,
            background.x,
            background.y,
            background.z,
            0.0
        ]
    );
    let colormap = floats(&buffers.colormap.data);
    assert_eq!(colormap.len(), 4 * 256);
    let map = shading.colormap();
    for (i, (color, opacity)) in map.linear().iter().zip(map.opacity()).enumerate() {
        assert_eq!(colormap[4 * i..4 * i + 3], color.to_array());
        assert_eq!(colormap[4 * i + 3], *opacity);
    }
    let materials = floats(&buffers.materials.data);
    for (m, material) in shading.materials().iter().enumerate() {
        let expected = [
            &material.kd.to_array()[..],
            &[material.ns],
            &material.ks.to_array(),
            &[material.reflectivity],
        ]
        .concat();
        assert_eq!(materials[8 * m..8 * m + 8], expected);
    }
    assert_eq!(buffers.lights.data.len(), 8 * shading.lights().len());
}

#[test]
fn the_camera_frame_gives_the_cpu_directions_bit_for_bit() {
    let cameras = [
        Fixture::new().resources.camera.camera.clone(),
        Camera::new(
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(-1.0, 0.5, -2.0),
            Vec3::new(0.1, 1.0, 0.2),
            37.0,
            33,
            17,
        )
        .unwrap(),
    ];
    for camera in &cameras {
        let frame = CameraFrame::new(camera);
        for spp in [1, 4] {
            for y in 0..camera.height {
                for x in 0..camera.width {
                    for sample in 0..spp {
                        let (sx, sy) = sample_offset(spp, sample);
                        let expected = camera.direction(x, y, sx, sy);
                        let got = frame.direction(camera, x, y, sx, sy);
                        assert_eq!(
                            got.to_array().map(f32::to_bits),
                            expected.to_array().map(f32::to_bits)
                        );
                    }
                }
            }
        }
    }
    let setup = Fixture::new().resources.camera;
    let buffers = super::buffers::CameraGpuBuffers::new(&setup);
    assert_eq!(&*buffers.morton_pixels.data, setup.morton_pixels.as_slice());
    let words = floats(&buffers.camera.data);
    assert_eq!(words[0..3], setup.camera.eye.to_array());
    assert_eq!((words[11], words[15]), (4.0, 3.0));
}

#[test]
fn volume_and_table_buffers_hold_the_cpu_data() {
    let (_, resources) = fixture();
    let volume = &resources.volume;
    let buffers = resources.gpu_buffers().unwrap();
    let grid = &buffers.grid.data;
    assert_eq!(grid[0..4], [5, 6, 7, 4 * 5 * 6]);
    assert_eq!(floats(&grid[4..7]), volume.origin.to_array());
    assert_eq!(floats(&grid[8..11]), volume.spacing.to_array());
    assert_eq!(grid[12..16], [0, 0, 0, 0], "first");
    let brick = crate::volume::generate::Dataset::Sphere
        .generate_box(
            UVec3::new(9, 9, 9),
            [UVec3::new(2, 3, 4), UVec3::new(6, 9, 8)],
        )
        .unwrap();
    let brick_grid = super::buffers::VolumeGpuBuffers::new(&brick)
        .unwrap()
        .grid
        .data;
    assert_eq!(brick_grid[12..16], [2, 3, 4, 0], "first");
    assert_eq!(floats(&buffers.values.data), volume.values);
    let mut bad = (**volume).clone();
    bad.values.pop();
    let bad = VolumeResources {
        volume: Arc::new(bad),
    };
    assert!(bad
        .gpu_buffers()
        .unwrap_err()
        .message
        .contains("values for"));

    let tables_buffers = MarchingCubesGpuBuffers::get();
    let tables = tables();
    for case in 0..256u32 {
        let count = tables_buffers.case_triangle_counts.data[case as usize];
        let triangles = tables.case_triangles(case);
        assert_eq!(count as usize, triangles.len());
        for (t, edges) in triangles.iter().enumerate() {
            let word = tables_buffers.case_triangles.data[case as usize * 5 + t];
            assert_eq!(
                [word & 0xff, word >> 8 & 0xff, word >> 16],
                edges.map(u32::from)
            );
        }
    }
    assert_eq!(tables_buffers.edge_corners.data[5], 1 | 3 << 8);
}

#[test]
fn literals_and_templates() {
    // The literal parses back to the same bits (as naga parses an `f` literal).
    for x in [
        0.1f32,
        0.12,
        1e-4,
        1.0 / 2.4,
        (1.0f32 - 0.0001).sqrt(),
        1e-40,
        -0.5,
    ] {
        let text = f32_literal(x);
        let parsed: f32 = text.trim_end_matches('f').parse().unwrap();
        assert_eq!(parsed.to_bits(), x.to_bits(), "{text}");
    }
    let scale = crate::bvh::Bvh::gpu_robust_far_scale();
    assert!(scale > 1.0 && scale < 1.000_001);
    assert_eq!(
        instantiate(
            "fn $FUNCTION() -> u32 { $FUNCTION_fail(0u); return $MISS_PRIM + $MISS; }",
            &[
                ("FUNCTION", "f".into()),
                ("MISS", "1u".into()),
                ("MISS_PRIM", "2u".into())
            ]
        ),
        "fn f() -> u32 { f_fail(0u); return 2u + 1u; }"
    );
    let missing = std::panic::catch_unwind(|| instantiate("$NOPE", &[]));
    assert!(missing.is_err());
}
