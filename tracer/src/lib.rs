//! The dpp functor library for ray tracing: meshes and scenes, the BVH, the camera,
//! and the ray-tracing functors the pipelines name.

pub mod builtin_scene;
pub mod bvh;
pub mod camera;
pub mod functors;
pub mod mesh;
pub mod obj;
mod random;
pub mod scene;

pub use camera::{Camera, CameraSetup, StandardView};
pub use functors::{TracerRecords, MISS_PRIM};
pub use mesh::TriangleMesh;
pub use scene::{SceneError, TraceResources, TraceScene};

use dpp_runtime::{FunctorLibrary, HostType, HostValue, Uniforms};
use std::sync::Arc;

/// The uniform fields the tracer fills, by record: `(record, field, type)`.
pub const UNIFORM_FIELDS: [(&str, &str, HostType); 12] = [
    ("camera", "width", HostType::Int),
    ("camera", "height", HostType::Int),
    ("camera", "pixels", HostType::Int),
    ("camera", "fov", HostType::Float),
    ("camera", "eye", HostType::Vec3),
    ("camera", "lookAt", HostType::Vec3),
    ("camera", "up", HostType::Vec3),
    ("scene", "triangles", HostType::Int),
    ("scene", "boundsMin", HostType::Vec3),
    ("scene", "boundsMax", HostType::Vec3),
    ("scene", "center", HostType::Vec3),
    ("scene", "diagonal", HostType::Float),
];

/// Registers the `Ray` and `Hit` records, declares the `camera.*` and `scene.*`
/// uniforms, and registers `cameraRay`, `intersect`, `occluded` and `normalColor`.
pub fn register_tracer_functors(library: &mut FunctorLibrary) -> TracerRecords {
    let records = functors::register_records(&mut library.records);
    for (record, field, ty) in UNIFORM_FIELDS {
        library.uniforms.declare(record, field, ty);
    }
    library.register(Arc::new(functors::camera_ray::CameraRay::new(records.ray)));
    library.register(Arc::new(functors::intersect::Intersect::new(
        records.ray,
        records.hit,
    )));
    library.register(Arc::new(functors::occluded::Occluded::new(records.ray)));
    library.register(Arc::new(functors::normal_color::NormalColor::new(
        records.ray,
        records.hit,
    )));
    records
}

/// Every functor a pipeline may name: the runtime's generic ones and the tracer's.
pub fn functor_library() -> FunctorLibrary {
    let mut library = FunctorLibrary::default();
    dpp_runtime::generic::register_generic_functors(&mut library);
    register_tracer_functors(&mut library);
    library
}

/// The uniform values of a scene seen through a camera (every field of [`UNIFORM_FIELDS`]).
pub fn uniforms(scene: &TraceScene, camera: &CameraSetup) -> Uniforms {
    let mut uniforms = Uniforms::default();
    let view = &camera.camera;
    let vec3 = |v: glam::Vec3| HostValue::Vec3(v.to_array());
    uniforms.set("camera", "width", HostValue::Int(view.width.into()));
    uniforms.set("camera", "height", HostValue::Int(view.height.into()));
    uniforms.set("camera", "pixels", HostValue::Int(view.pixels().into()));
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
        let values = uniforms(&scene, &CameraSetup::new(camera));
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
        for name in ["add", "cameraRay", "intersect", "occluded", "normalColor"] {
            assert!(library.get(name).is_some(), "{name}");
        }
    }

    #[test]
    fn functors_and_records_are_registered() {
        let mut library = FunctorLibrary::default();
        let records = register_tracer_functors(&mut library);
        let names: Vec<_> = library.names().collect();
        assert_eq!(names, ["cameraRay", "intersect", "normalColor", "occluded"]);
        let ray = library.records.get(records.ray);
        let fields: Vec<_> = ray.fields.iter().map(|(name, _)| name.as_str()).collect();
        assert_eq!(fields, ["origin", "dir", "tmax", "sample"]);
        let hit = library.records.get(records.hit);
        let fields: Vec<_> = hit.fields.iter().map(|(name, _)| name.as_str()).collect();
        assert_eq!(fields, ["t", "prim", "u", "v"]);
        let signature = library
            .get("cameraRay")
            .unwrap()
            .signature()
            .display(&library.records);
        assert!(
            signature.contains("cameraRay(index: u32) -> (ray: Ray) [spp: int = 1]"),
            "{signature}"
        );
    }
}
