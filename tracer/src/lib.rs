//! The dpp functor library for ray tracing: meshes and scenes, the BVH, the camera,
//! and the ray-tracing functors the pipelines name.

pub mod builtin_scene;
pub mod bvh;
pub mod cache;
pub mod camera;
mod equal_keys;
pub mod functors;
mod huge_pages;
pub mod marching_cubes_tables;
pub mod mesh;
pub mod mesh_write;
pub mod obj;
pub mod partition;
pub mod ply;
mod ply_body;
mod prefetch;
pub mod scene;
pub mod shading;
#[cfg(test)]
mod test_meshes;
pub mod vector;
pub mod volume;
pub mod vtk;

pub use camera::{Camera, CameraSetup, StandardView};
pub use functors::{TracerRecords, MISS_PRIM};
pub use mesh::TriangleMesh;
pub use scene::{SceneError, TraceResources, TraceScene};
pub use shading::{PointLight, SceneFile, Shading, ShadingError, ShadingOverrides};

use dpp_runtime::{ElemType, FunctorLibrary, HostType, HostValue, RecordId, RecordType, Uniforms};

/// The uniform fields the tracer fills, by record: `(record, field, type)`.
pub const UNIFORM_FIELDS: [(&str, &str, HostType); 17] = [
    ("camera", "width", HostType::Int),
    ("camera", "height", HostType::Int),
    ("camera", "pixels", HostType::Int),
    ("camera", "tracedPixels", HostType::Int),
    ("camera", "fov", HostType::Float),
    ("camera", "eye", HostType::Vec3),
    ("camera", "lookAt", HostType::Vec3),
    ("camera", "up", HostType::Vec3),
    ("scene", "triangles", HostType::Int),
    ("scene", "boundsMin", HostType::Vec3),
    ("scene", "boundsMax", HostType::Vec3),
    ("scene", "center", HostType::Vec3),
    ("scene", "diagonal", HostType::Float),
    ("scene", "lights", HostType::Int),
    ("scene", "materials", HostType::Int),
    ("scene", "mirrors", HostType::Int),
    ("scene", "background", HostType::Vec3),
];

/// Registers the `Ray`, `Hit` and `Surface` records, declares the `camera.*` and
/// `scene.*` uniforms, and registers the ray-tracing functors.
pub fn register_tracer_functors(library: &mut FunctorLibrary) -> TracerRecords {
    use functors::*;
    let records = functors::register_records(&mut library.records);
    for (record, field, ty) in UNIFORM_FIELDS {
        library.uniforms.declare(record, field, ty);
    }
    let TracerRecords {
        ray,
        hit,
        surface,
        material,
        light,
    } = records;
    let functors = [
        camera_ray::functor(ray),
        intersect::functor(ray, hit),
        occluded::functor(ray),
        ray_order_key::functor(ray),
        normal_color::functor(ray, hit),
        surface::functor(ray, hit, surface),
        shadow_ray::functor(surface, ray),
        occ_ray_gen::functor(surface, ray),
        visible_lights::functor(),
        shader::functor(surface),
        reflect_ray::functor(surface, ray),
        alive::functor(ray),
        anti_alias::functor(),
        global_id::functor(),
        material::functor(material),
        light::functor(light),
        colormap::functor(),
        with_weight::functor(ray),
        clip_ray::functor(ray),
    ];
    for functor in functors {
        library.register(functor);
    }
    records
}

/// Registers the `Triangle` record, declares the `volume.*` uniforms and
/// registers `cubeCase`, `caseTriangles` and `cubeTriangle`. Returns the
/// `Triangle` record's id.
pub fn register_isosurface_functors(library: &mut FunctorLibrary) -> RecordId {
    let triangle = library.records.register(RecordType {
        name: "Triangle".into(),
        fields: ["a", "b", "c", "na", "nb", "nc"]
            .iter()
            .map(|name| (name.to_string(), ElemType::Vec3))
            .chain(["sa", "sb", "sc"].iter().map(|name| (name.to_string(), ElemType::F32)))
            .collect(),
        doc: "an isosurface triangle: corners a, b, c (counter-clockwise seen from higher values), unit vertex normals na, nb, nc (up the gradient), vertex scalars sa, sb, sc".into(),
    });
    for (record, field, ty) in functors::isosurface::VOLUME_UNIFORM_FIELDS {
        library.uniforms.declare(record, field, ty);
    }
    library.register(functors::cube_case::functor());
    library.register(functors::case_triangles::functor());
    library.register(functors::cube_triangle::functor(triangle));
    triangle
}

/// Registers the `March` record and the volume-rendering functors
/// (`volumeEntry`, `volumeMarch`, `marchLive`, `overBackground`, and for
/// empty-space skipping `cellRange`, `cellBlock`, `transparent`,
/// `marchBlock`, `skipEmpty`); they read the `Ray` record of
/// [`register_tracer_functors`]. Returns the `March` id.
pub fn register_volume_render_functors(library: &mut FunctorLibrary, ray: RecordId) -> RecordId {
    use functors::*;
    let march = volume_render::register_march_record(&mut library.records);
    let functors = [
        volume_entry::functor(ray, march),
        volume_march::functor(march),
        march_live::functor(march),
        over_background::functor(),
        cell_range::functor(),
        cell_block::functor(),
        transparent::functor(),
        march_block::functor(march),
        skip_empty::functor(march),
    ];
    for functor in functors {
        library.register(functor);
    }
    march
}

/// Every functor a pipeline may name: the runtime's generic ones and the tracer's.
pub fn functor_library() -> FunctorLibrary {
    let mut library = FunctorLibrary::default();
    dpp_runtime::generic::register_generic_functors(&mut library);
    let records = register_tracer_functors(&mut library);
    register_isosurface_functors(&mut library);
    register_volume_render_functors(&mut library, records.ray);
    library
}

/// The uniform values of a scene seen through a camera and lit by `shading`
/// (every field of [`UNIFORM_FIELDS`]; `scene.lights` and `scene.materials`
/// are the numbers of lights and materials).
pub fn uniforms(scene: &TraceScene, camera: &CameraSetup, shading: &Shading) -> Uniforms {
    let mut uniforms = Uniforms::default();
    let view = &camera.camera;
    let vec3 = |v: glam::Vec3| HostValue::Vec3(v.to_array());
    uniforms.set("camera", "width", HostValue::Int(view.width.into()));
    uniforms.set("camera", "height", HostValue::Int(view.height.into()));
    uniforms.set("camera", "pixels", HostValue::Int(view.pixels().into()));
    let traced = camera.morton_pixels.len() as i64;
    uniforms.set("camera", "tracedPixels", HostValue::Int(traced));
    uniforms.set("camera", "fov", HostValue::Float(view.fov_degrees.into()));
    uniforms.set("camera", "eye", vec3(view.eye));
    uniforms.set("camera", "lookAt", vec3(view.look_at));
    uniforms.set("camera", "up", vec3(view.up));
    let triangles = scene.mesh.triangles.len() as i64;
    uniforms.set("scene", "triangles", HostValue::Int(triangles));
    uniforms.set("scene", "boundsMin", vec3(scene.bounds.min));
    uniforms.set("scene", "boundsMax", vec3(scene.bounds.max));
    uniforms.set("scene", "center", vec3(scene.bounds.center()));
    uniforms.set(
        "scene",
        "diagonal",
        HostValue::Float(scene.bounds.diagonal().into()),
    );
    let lights = shading.lights().len() as i64;
    uniforms.set("scene", "lights", HostValue::Int(lights));
    let materials = shading.materials().len() as i64;
    uniforms.set("scene", "materials", HostValue::Int(materials));
    // A pipeline stops its bounces where nothing can reflect.
    let mirrors = shading
        .materials()
        .iter()
        .filter(|m| m.reflectivity > 0.0)
        .count() as i64;
    uniforms.set("scene", "mirrors", HostValue::Int(mirrors));
    uniforms.set("scene", "background", vec3(shading.background()));
    uniforms
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn uniforms_match_their_declared_types() {
        let mut library = FunctorLibrary::default();
        register_tracer_functors(&mut library);
        let scene = TraceScene::builtin(builtin_scene::MIN_RESOLUTION).unwrap();
        let camera = Camera::standard(StandardView::Front, &scene.bounds, 32, 16).unwrap();
        let shading = Shading::for_scene(&scene);
        let values = uniforms(&scene, &CameraSetup::new(camera.clone()), &shading);
        let mut filled = 0;
        for (record, fields) in &library.uniforms.records {
            for (field, ty) in fields {
                let value = values.get(record, field).unwrap();
                assert_eq!(value.host_type(), *ty, "{record}.{field}");
                filled += 1;
            }
        }
        assert_eq!(filled, UNIFORM_FIELDS.len());
        assert_eq!(
            values.records.values().map(|r| r.len()).sum::<usize>(),
            filled
        );
        assert_eq!(values.get("camera", "pixels"), Some(HostValue::Int(512)));
        assert_eq!(
            values.get("scene", "triangles"),
            Some(HostValue::Int(scene.mesh.triangles.len() as i64))
        );
        assert_eq!(values.get("scene", "lights"), Some(HostValue::Int(2)));
        let mirrors = |shading: &Shading| {
            let values = uniforms(&scene, &CameraSetup::new(camera.clone()), shading);
            values.get("scene", "mirrors")
        };
        assert_eq!(mirrors(&shading), Some(HostValue::Int(0)));
        let mut mirrored = shading.clone();
        let first = mirrored.materials()[0].name.clone();
        let spec = shading::MaterialSpec {
            reflectivity: Some(0.5),
            ..Default::default()
        };
        mirrored.set_material(&first, &spec).unwrap();
        assert_eq!(mirrors(&mirrored), Some(HostValue::Int(1)));
        let center = values.get("scene", "center").unwrap().as_vec3().unwrap();
        assert_eq!(center, scene.bounds.center());
        assert_eq!(
            values.get("camera", "eye").unwrap().as_vec3().unwrap(),
            center + Vec3::new(0.0, 0.0, scene.bounds.diagonal())
        );
    }

    #[test]
    fn the_full_library_has_generic_and_tracer_functors() {
        let library = functor_library();
        for name in [
            "add",
            "cameraRay",
            "intersect",
            "occluded",
            "normalColor",
            "surface",
            "shadowRay",
            "occRayGen",
            "visibleLights",
            "shader",
            "reflectRay",
            "alive",
            "antiAlias",
            "globalId",
        ] {
            assert!(library.get(name).is_some(), "{name}");
        }
    }

    #[test]
    fn functors_and_records_are_registered() {
        let mut library = FunctorLibrary::default();
        let records = register_tracer_functors(&mut library);
        let names: Vec<_> = library.names().collect();
        assert_eq!(
            names,
            [
                "alive",
                "antiAlias",
                "cameraRay",
                "clipRay",
                "colormap",
                "globalId",
                "intersect",
                "light",
                "material",
                "normalColor",
                "occRayGen",
                "occluded",
                "rayOrderKey",
                "reflectRay",
                "shader",
                "shadowRay",
                "surface",
                "visibleLights",
                "withWeight"
            ]
        );
        let fields = |id| -> Vec<String> {
            let record = library.records.get(id);
            record
                .fields
                .iter()
                .map(|(name, ty)| format!("{name}: {}", ty.name(&library.records)))
                .collect()
        };
        assert_eq!(
            fields(records.ray),
            [
                "origin: vec3",
                "dir: vec3",
                "tmax: f32",
                "sample: u32",
                "weight: vec3",
                "depth: u32"
            ]
        );
        assert_eq!(
            fields(records.hit),
            ["t: f32", "prim: u32", "u: f32", "v: f32"]
        );
        assert_eq!(
            fields(records.surface),
            [
                "position: vec3",
                "normal: vec3",
                "view: vec3",
                "scalar: f32",
                "material: u32",
                "hit: bool",
                "sample: u32",
                "weight: vec3",
                "depth: u32",
                "geometric: vec3"
            ]
        );
        let signature = |name| {
            library
                .get(name)
                .unwrap()
                .signature()
                .display(&library.records)
        };
        let expected = [
            "map          cameraRay(index: u32) -> (ray: Ray) [spp: int = 1]",
            "map          surface(ray: Ray, hit: Hit) -> (surf: Surface)",
            "expand       shadowRay(surf: Surface) -> (ray: Ray)",
            "expand       occRayGen(surf: Surface) -> (ray: Ray) [range: float = 0.05]",
            "group        visibleLights(blocked: bool) -> (mask: u32)",
            "map          shader(surf: Surface, occlusion: f32, visible: u32) -> (rgb: vec3) [ambient: float = 0.15] [falloff: float = 1.0]",
            "map          reflectRay(surf: Surface) -> (ray: Ray) [maxDepth: int = 3]",
            "map          alive(ray: Ray) -> (alive: bool)",
            "map          rayOrderKey(ray: Ray) -> (key: u32)",
            "group        antiAlias(color: vec3) -> (pixel: vec3)",
            "map          normalColor(ray: Ray, hit: Hit) -> (color: vec3)",
            "map          globalId(prim: u32) -> (id: u32)",
            "map          material(id: u32) -> (m: Material)",
            "map          light(index: u32) -> (l: Light)",
            "map          colormap(scalar: f32) -> (rgb: vec3)",
            "map          withWeight(ray: Ray, weight: vec3) -> (ray: Ray)",
            "map          clipRay(ray: Ray, t: f32) -> (ray: Ray)",
        ];
        for line in expected {
            let name = line.split_whitespace().nth(1).unwrap();
            let name = &name[..name.find('(').unwrap()];
            assert_eq!(signature(name), line);
        }
    }
}
