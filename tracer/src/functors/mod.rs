//! The ray-tracing functors and their record types. One folder per functor, so
//! that each can grow a GPU twin beside its CPU implementation.
//!
//! Record layouts (field order is the column order of a record array):
//! - `Ray { origin: vec3, dir: vec3, tmax: f32, sample: u32 }`, `sample` being
//!   `row-major pixel * spp + sample in pixel`;
//! - `Hit { t: f32, prim: u32, u: f32, v: f32 }`, a miss being
//!   `t = +inf, prim = 4294967295, u = v = 0`.

pub mod camera_ray;
pub mod intersect;
pub mod normal_color;
pub mod occluded;

use crate::bvh::{HitRecord, Ray};
use dpp_runtime::{
    Column, ColumnView, ElemType, FunctorError, RecordId, RecordRegistry, RecordType,
};
use glam::Vec3;
use std::sync::Arc;

/// `Hit.prim` of a miss.
pub const MISS_PRIM: u32 = u32::MAX;

/// The ids of the tracer's record types in a library's registry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TracerRecords {
    pub ray: RecordId,
    pub hit: RecordId,
}

pub(crate) fn register_records(records: &mut RecordRegistry) -> TracerRecords {
    let ray = records.register(RecordType {
        name: "Ray".into(),
        fields: vec![
            ("origin".into(), ElemType::Vec3),
            ("dir".into(), ElemType::Vec3),
            ("tmax".into(), ElemType::F32),
            ("sample".into(), ElemType::U32),
        ],
        doc: "a ray segment (hits count for 0 < t < tmax); sample = pixel * spp + sample in pixel, pixel row-major".into(),
    });
    let hit = records.register(RecordType {
        name: "Hit".into(),
        fields: vec![
            ("t".into(), ElemType::F32),
            ("prim".into(), ElemType::U32),
            ("u".into(), ElemType::F32),
            ("v".into(), ElemType::F32),
        ],
        doc: "closest hit: distance, triangle in input file order, barycentrics of v1 and v2; a miss has t = inf, prim = 4294967295".into(),
    });
    TracerRecords { ray, hit }
}

/// The columns of a chunk of `Ray` records.
pub(crate) struct RayColumns<'a> {
    pub origin: &'a [Vec3],
    pub dir: &'a [Vec3],
    pub tmax: &'a [f32],
}

impl<'a> RayColumns<'a> {
    pub fn new(view: &ColumnView<'a>) -> RayColumns<'a> {
        RayColumns {
            origin: view.field(0).as_vec3(),
            dir: view.field(1).as_vec3(),
            tmax: view.field(2).as_f32(),
        }
    }

    pub fn len(&self) -> usize {
        self.origin.len()
    }

    #[inline]
    pub fn get(&self, index: usize) -> Ray {
        Ray {
            origin: self.origin[index],
            direction: self.dir[index],
            tmax: self.tmax[index],
        }
    }
}

/// The columns of a chunk of `Hit` records.
pub(crate) struct HitColumns<'a> {
    pub prim: &'a [u32],
}

impl<'a> HitColumns<'a> {
    pub fn new(view: &ColumnView<'a>) -> HitColumns<'a> {
        HitColumns {
            prim: view.field(1).as_u32(),
        }
    }
}

/// The `Hit` fields of a hit record, or of a miss.
#[inline]
pub(crate) fn hit_fields(hit: Option<HitRecord>) -> (f32, u32, f32, f32) {
    match hit {
        Some(hit) => (hit.t, hit.prim, hit.u, hit.v),
        None => (f32::INFINITY, MISS_PRIM, 0.0, 0.0),
    }
}

/// Mutable access to all `N` field columns of a record output at once (the
/// runtime's `field_mut` borrows one at a time).
pub(crate) fn record_fields_mut<const N: usize>(
    column: &mut Column,
) -> Result<[&mut Column; N], FunctorError> {
    let type_error = |found: ElemType| {
        FunctorError(format!(
            "internal error: expected a record output with {N} fields, got {found:?}"
        ))
    };
    let found = column.elem_type();
    match column {
        Column::Record { fields, .. } => {
            let fields: &mut [Arc<Column>; N] = fields
                .as_mut_slice()
                .try_into()
                .map_err(|_| type_error(found))?;
            Ok(fields.each_mut().map(Arc::make_mut))
        }
        _ => Err(type_error(found)),
    }
}

#[cfg(test)]
pub(crate) mod test_support {
    use crate::camera::{Camera, CameraSetup};
    use crate::scene::{TraceResources, TraceScene};
    use crate::{register_tracer_functors, uniforms};
    use dpp_runtime::{
        CallContext, Column, ColumnView, ElemType, FunctorLibrary, HostValue, Uniforms,
    };
    use glam::Vec3;
    use std::sync::Arc;

    /// Rays: down onto the small square, down beside it onto the big one, up into
    /// nothing, and down with tmax short of the big square.
    pub fn probe_rays(fixture: &Fixture) -> Column {
        let ElemType::Record(ty) = fixture.record("Ray") else {
            unreachable!("Ray is a record")
        };
        Column::Record {
            ty,
            fields: vec![
                Arc::new(Column::Vec3(vec![
                    Vec3::new(0.25, 0.5, 2.0),
                    Vec3::new(3.0, 0.0, 2.0),
                    Vec3::new(0.0, 0.0, 2.0),
                    Vec3::new(3.0, 0.0, 2.0),
                ])),
                Arc::new(Column::Vec3(vec![
                    Vec3::NEG_Z,
                    Vec3::NEG_Z,
                    Vec3::Z,
                    Vec3::NEG_Z,
                ])),
                Arc::new(Column::F32(vec![
                    f32::INFINITY,
                    f32::INFINITY,
                    f32::INFINITY,
                    2.5,
                ])),
                Arc::new(Column::U32(vec![0, 1, 2, 3])),
            ],
        }
    }

    /// A library, a small scene (two unit squares facing +z at z = 0 and z = -1) and
    /// a 4×3 camera looking down -z at them.
    pub struct Fixture {
        pub library: FunctorLibrary,
        pub resources: TraceResources,
        pub uniforms: Uniforms,
    }

    impl Fixture {
        pub fn new() -> Fixture {
            let mut library = FunctorLibrary::default();
            register_tracer_functors(&mut library);
            let mesh = crate::mesh::TriangleMesh {
                positions: vec![
                    Vec3::new(-1.0, -1.0, 0.0),
                    Vec3::new(1.0, -1.0, 0.0),
                    Vec3::new(1.0, 1.0, 0.0),
                    Vec3::new(-1.0, 1.0, 0.0),
                    Vec3::new(-5.0, -5.0, -1.0),
                    Vec3::new(5.0, -5.0, -1.0),
                    Vec3::new(5.0, 5.0, -1.0),
                    Vec3::new(-5.0, 5.0, -1.0),
                ],
                triangles: vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]],
                normals: None,
                scalars: None,
            };
            let scene = Arc::new(TraceScene::new(mesh).unwrap());
            let camera =
                Camera::new(Vec3::new(0.0, 0.0, 2.0), Vec3::ZERO, Vec3::Y, 90.0, 4, 3).unwrap();
            let camera = Arc::new(CameraSetup::new(camera));
            let uniforms = uniforms(&scene, &camera);
            Fixture {
                library,
                resources: TraceResources { scene, camera },
                uniforms,
            }
        }

        pub fn record(&self, name: &str) -> ElemType {
            ElemType::Record(self.library.records.find(name).unwrap())
        }

        /// Runs functor `name` on one chunk starting at `first_index`.
        pub fn run(
            &self,
            name: &str,
            named: &[HostValue],
            first_index: usize,
            inputs: &[ColumnView<'_>],
        ) -> Result<Vec<Column>, dpp_runtime::FunctorError> {
            let functor = self.library.get(name).unwrap();
            let ctx = CallContext {
                named,
                uniforms: &self.uniforms,
                resources: &self.resources,
                first_index,
                group: 1,
                records: &self.library.records,
            };
            let mut outputs: Vec<Column> = functor
                .signature()
                .outputs
                .iter()
                .map(|output| match output.ty {
                    dpp_runtime::TypePattern::Exact(ty) => {
                        Column::with_capacity(ty, 0, &self.library.records)
                    }
                    dpp_runtime::TypePattern::Var(..) => {
                        unreachable!("tracer functors are monomorphic")
                    }
                })
                .collect();
            functor.run_cpu(&ctx, inputs, &mut outputs)?;
            Ok(outputs)
        }
    }
}
