//! The ray-tracing functors and their record types. One folder per functor, so
//! that each can grow a GPU twin beside its CPU implementation.
//!
//! Record layouts (field order is the column order of a record array):
//! - `Ray { origin: vec3, dir: vec3, tmax: f32, sample: u32, weight: vec3, depth: u32 }`:
//!   `sample` is `row-major pixel * spp + sample in pixel`; `weight` the colour
//!   throughput (1 for camera rays, scaled by reflectivity at each mirror
//!   bounce); `depth` the bounce number (0 for camera rays). A ray is *dead*
//!   when `tmax <= 0`: it hits nothing and its weight is 0;
//! - `Hit { t: f32, prim: u32, u: f32, v: f32 }`, a miss being
//!   `t = +inf, prim = 4294967295, u = v = 0`;
//! - `Surface { position: vec3, normal: vec3, view: vec3, scalar: f32, material: u32,
//!   hit: bool, sample: u32, weight: vec3, depth: u32, geometric: vec3 }`: what
//!   shading needs of a hit (see [`surface`]): `normal` is the (interpolated)
//!   shading normal, `geometric` the hit triangle's own normal, both on the side
//!   the ray comes from; a miss has `hit = false` and zeros except `sample`,
//!   `weight` and `depth`;
//! - `Material { diffuse: vec3, shininess: f32, specular: vec3, reflectivity: f32 }`
//!   and `Light { position: vec3, intensity: f32, color: vec3 }`: the scene's
//!   materials and lights as `material` and `light` give them to pipelines that
//!   write their shading themselves.

pub mod alive;
pub mod anti_alias;
pub mod camera_ray;
pub mod case_triangles;
pub mod cell_block;
pub mod cell_range;
pub mod clip_ray;
pub mod colormap;
pub mod cube_case;
pub mod cube_triangle;
pub mod global_id;
pub mod intersect;
#[cfg(feature = "embree")]
pub mod intersect_embree;
pub mod isosurface;
pub mod light;
pub mod march_block;
pub mod march_live;
pub mod material;
pub mod normal_color;
pub mod occ_ray_gen;
pub mod occluded;
pub mod over_background;
pub mod ray_order_key;
pub mod reflect_ray;
pub mod shader;
pub mod shadow_ray;
pub mod skip_empty;
pub mod surface;
pub mod transparent;
pub mod visible_lights;
pub mod volume_entry;
pub mod volume_march;
pub mod volume_render;
pub mod wgsl;
pub mod with_weight;

use crate::bvh::{HitPlaces, Ray};
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, ClosureFunctor, Column, ColumnView, ElemType, Functor, FunctorError, RecordId,
    RecordRegistry, RecordType, Signature,
};
use glam::Vec3;
use std::mem::MaybeUninit;
use std::ops::Range;
use std::sync::Arc;
use wgsl::TwinParts;

/// A tracer functor of what its folder holds: its signature, its CPU body, and
/// its twin, the folder's `twin.wgsl` template (`template`) instantiated with
/// the parts `twin_parts` gives for each request (see [`wgsl::twin`]).
pub(crate) fn tracer_functor(
    signature: Signature,
    cpu: impl Fn(&CallContext<'_>, &[ColumnView<'_>], &mut [Column]) -> Result<(), FunctorError>
        + Send
        + Sync
        + 'static,
    template: &'static str,
    twin_parts: impl Fn(&WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError>
        + Send
        + Sync
        + 'static,
) -> Arc<dyn Functor> {
    let functor = ClosureFunctor::new(signature, cpu).with_twin(move |signature, request| {
        wgsl::twin(signature, request, template, twin_parts(request)?)
    });
    Arc::new(functor)
}

/// `Hit.prim` of a miss.
pub use crate::bvh::MISS_PRIM;

/// Secondary rays start this fraction of the scene diagonal off the surface,
/// along the geometric normal on the side the ray came from (not along the
/// shading normal, which can lean down to the triangle's plane), so that they
/// neither hit their own triangle nor start behind it.
pub const SURFACE_EPSILON: f32 = 1e-4;

/// The ids of the tracer's record types in a library's registry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TracerRecords {
    pub ray: RecordId,
    pub hit: RecordId,
    pub surface: RecordId,
    pub material: RecordId,
    pub light: RecordId,
}

/// The places of the `Ray` fields that functors edit alone (`clipRay`,
/// `withWeight`) among its fields, in [`register_records`]' order.
pub(crate) const RAY_TMAX_FIELD: usize = 2;
pub(crate) const RAY_WEIGHT_FIELD: usize = 4;

pub(crate) fn register_records(records: &mut RecordRegistry) -> TracerRecords {
    let ray = records.register(RecordType {
        name: "Ray".into(),
        fields: vec![
            ("origin".into(), ElemType::Vec3),
            ("dir".into(), ElemType::Vec3),
            ("tmax".into(), ElemType::F32),
            ("sample".into(), ElemType::U32),
            ("weight".into(), ElemType::Vec3),
            ("depth".into(), ElemType::U32),
        ],
        doc: "a ray segment (hits count for 0 < t < tmax; dead when tmax <= 0); sample = pixel * spp + sample in pixel, pixel row-major; weight = colour throughput; depth = bounce number".into(),
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
    let surface = records.register(RecordType {
        name: "Surface".into(),
        fields: vec![
            ("position".into(), ElemType::Vec3),
            ("normal".into(), ElemType::Vec3),
            ("view".into(), ElemType::Vec3),
            ("scalar".into(), ElemType::F32),
            ("material".into(), ElemType::U32),
            ("hit".into(), ElemType::Bool),
            ("sample".into(), ElemType::U32),
            ("weight".into(), ElemType::Vec3),
            ("depth".into(), ElemType::U32),
            ("geometric".into(), ElemType::Vec3),
        ],
        doc: "a shading point: position, unit shading normal facing the ray, unit vector towards the ray origin, interpolated scalar, material id; hit = false for a miss; sample, weight and depth of its ray; unit geometric (triangle) normal facing the ray, along which secondary rays leave".into(),
    });
    let material = records.register(RecordType {
        name: "Material".into(),
        fields: vec![
            ("diffuse".into(), ElemType::Vec3),
            ("shininess".into(), ElemType::F32),
            ("specular".into(), ElemType::Vec3),
            ("reflectivity".into(), ElemType::F32),
        ],
        doc: "a scene material: diffuse colour Kd (linear RGB), Phong exponent Ns, specular colour Ks, mirror reflectivity in [0, 1]".into(),
    });
    let light = records.register(RecordType {
        name: "Light".into(),
        fields: vec![
            ("position".into(), ElemType::Vec3),
            ("intensity".into(), ElemType::F32),
            ("color".into(), ElemType::Vec3),
        ],
        doc: "a point light: position, intensity, linear RGB colour".into(),
    });
    TracerRecords {
        ray,
        hit,
        surface,
        material,
        light,
    }
}

/// One `Ray` record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RayRecord {
    pub origin: Vec3,
    pub dir: Vec3,
    pub tmax: f32,
    pub sample: u32,
    pub weight: Vec3,
    pub depth: u32,
}

impl RayRecord {
    /// A dead ray: `tmax = 0`, zero weight, a harmless unit direction.
    pub fn dead(sample: u32, depth: u32) -> RayRecord {
        RayRecord {
            origin: Vec3::ZERO,
            dir: Vec3::Z,
            tmax: 0.0,
            sample,
            weight: Vec3::ZERO,
            depth,
        }
    }
}

/// The columns of a chunk of `Ray` records.
pub(crate) struct RayColumns<'a> {
    pub origin: &'a [Vec3],
    pub dir: &'a [Vec3],
    pub tmax: &'a [f32],
    pub sample: &'a [u32],
    pub weight: &'a [Vec3],
    pub depth: &'a [u32],
}

impl<'a> RayColumns<'a> {
    pub fn new(view: &ColumnView<'a>) -> RayColumns<'a> {
        RayColumns {
            origin: view.field(0).as_vec3(),
            dir: view.field(1).as_vec3(),
            tmax: view.field(RAY_TMAX_FIELD).as_f32(),
            sample: view.field(3).as_u32(),
            weight: view.field(RAY_WEIGHT_FIELD).as_vec3(),
            depth: view.field(5).as_u32(),
        }
    }

    pub fn len(&self) -> usize {
        self.origin.len()
    }

    /// The ray as the BVH traverses it.
    #[inline]
    pub fn get(&self, index: usize) -> Ray {
        Ray {
            origin: self.origin[index],
            direction: self.dir[index],
            tmax: self.tmax[index],
        }
    }
}

/// Appends `Ray` records to an output column.
pub(crate) struct RayWriter<'a> {
    origin: &'a mut Vec<Vec3>,
    dir: &'a mut Vec<Vec3>,
    tmax: &'a mut Vec<f32>,
    sample: &'a mut Vec<u32>,
    weight: &'a mut Vec<Vec3>,
    depth: &'a mut Vec<u32>,
}

impl<'a> RayWriter<'a> {
    pub fn new(column: &'a mut Column, capacity: usize) -> Result<RayWriter<'a>, FunctorError> {
        let [origin, dir, tmax, sample, weight, depth] = record_fields_mut::<6>(column)?;
        let writer = RayWriter {
            origin: origin.as_vec3_mut(),
            dir: dir.as_vec3_mut(),
            tmax: tmax.as_f32_mut(),
            sample: sample.as_u32_mut(),
            weight: weight.as_vec3_mut(),
            depth: depth.as_u32_mut(),
        };
        writer.origin.reserve(capacity);
        writer.dir.reserve(capacity);
        writer.tmax.reserve(capacity);
        writer.sample.reserve(capacity);
        writer.weight.reserve(capacity);
        writer.depth.reserve(capacity);
        Ok(writer)
    }

    /// Appends `len` records, record `i` being `ray(i)`, in one pass that writes
    /// every column straight into its spare capacity (no per-element capacity
    /// checks).
    #[inline(always)]
    pub fn extend_with(&mut self, len: usize, mut ray: impl FnMut(usize) -> RayRecord) {
        let origin = spare(self.origin, len);
        let dir = spare(self.dir, len);
        let tmax = spare(self.tmax, len);
        let sample = spare(self.sample, len);
        let weight = spare(self.weight, len);
        let depth = spare(self.depth, len);
        for i in 0..len {
            let r = ray(i);
            origin[i].write(r.origin);
            dir[i].write(r.dir);
            tmax[i].write(r.tmax);
            sample[i].write(r.sample);
            weight[i].write(r.weight);
            depth[i].write(r.depth);
        }
        // SAFETY: the loop wrote the first `len` spare elements of every column.
        unsafe {
            commit(self.origin, len);
            commit(self.dir, len);
            commit(self.tmax, len);
            commit(self.sample, len);
            commit(self.weight, len);
            commit(self.depth, len);
        }
    }

    /// Appends `lanes` dead rays ([`RayRecord::dead`]) for each of a run of
    /// misses, whose samples and depths these are, a column at a time: fills
    /// and copies, not six interleaved streams of scalar stores. (Most
    /// surfaces of a view with much background are misses, and their
    /// occlusion rays were most of `occRayGen`'s time.)
    pub fn extend_dead(
        &mut self,
        samples: &[u32],
        depths: impl ExactSizeIterator<Item = u32>,
        lanes: usize,
    ) {
        let dead = RayRecord::dead(0, 0);
        let len = samples.len() * lanes;
        extend_with_copies_of_vec3(self.origin, len, dead.origin);
        extend_with_copies_of_vec3(self.dir, len, dead.dir);
        self.tmax.resize(self.tmax.len() + len, dead.tmax);
        extend_with_copies_of_vec3(self.weight, len, dead.weight);
        extend_with_each_repeated(self.sample, samples.iter().copied(), lanes);
        extend_with_each_repeated(self.depth, depths, lanes);
    }
}

/// `0..len` cut into maximal runs of consecutive indices with the same
/// `key`, in order, each with its key: a functor writes a run of misses at
/// once ([`RayWriter::extend_dead`], [`SurfaceWriter::extend_misses`]).
pub(crate) fn runs_of(
    len: usize,
    key: impl Fn(usize) -> bool,
) -> impl Iterator<Item = (bool, Range<usize>)> {
    let mut start = 0;
    std::iter::from_fn(move || {
        if start == len {
            return None;
        }
        let run_key = key(start);
        let end = (start + 1..len)
            .find(|&next| key(next) != run_key)
            .unwrap_or(len);
        let run = start..end;
        start = end;
        Some((run_key, run))
    })
}

/// Appends `len` copies of `value` to `column`: zeros by `memset`, then eight
/// copies at a time as one 96-byte copy (a loop of 12-byte stores does not
/// vectorise).
fn extend_with_copies_of_vec3(column: &mut Vec<Vec3>, len: usize, value: Vec3) {
    let start = column.len();
    let written = spare(column, len);
    // SAFETY: all-zero bytes are a valid `Vec3` (three 0.0 floats), so the
    // `len` spare elements are initialised and may be appended.
    unsafe {
        std::ptr::write_bytes(written.as_mut_ptr(), 0, len);
        commit(column, len);
    }
    if value != Vec3::ZERO {
        let eight = [value; 8];
        let eight: &[f32] = bytemuck::cast_slice(&eight);
        let floats: &mut [f32] = bytemuck::cast_slice_mut(&mut column[start..]);
        let mut copies = floats.chunks_exact_mut(eight.len());
        for copy in &mut copies {
            copy.copy_from_slice(eight);
        }
        let rest = copies.into_remainder();
        rest.copy_from_slice(&eight[..rest.len()]);
    }
}

/// Appends each of `values` `lanes` times over.
fn extend_with_each_repeated(
    column: &mut Vec<u32>,
    values: impl ExactSizeIterator<Item = u32>,
    lanes: usize,
) {
    let len = values.len() * lanes;
    let written = spare(column, len);
    // A count of copies known to the compiler makes each value one store.
    match lanes {
        1 => write_each_repeated::<1>(written, values),
        2 => write_each_repeated::<2>(written, values),
        4 => write_each_repeated::<4>(written, values),
        8 => write_each_repeated::<8>(written, values),
        _ => {
            for (copies, value) in written.chunks_exact_mut(lanes.max(1)).zip(values) {
                copies.fill(MaybeUninit::new(value));
            }
        }
    }
    // SAFETY: every arm wrote all `len` spare elements.
    unsafe { commit(column, len) }
}

fn write_each_repeated<const LANES: usize>(
    written: &mut [MaybeUninit<u32>],
    values: impl Iterator<Item = u32>,
) {
    for (copies, value) in written.chunks_exact_mut(LANES).zip(values) {
        copies.copy_from_slice(&[MaybeUninit::new(value); LANES]);
    }
}

/// The first `len` elements of `column`'s spare capacity (reserved here), to be
/// written and then appended with [`commit`].
#[inline(always)]
fn spare<T>(column: &mut Vec<T>, len: usize) -> &mut [MaybeUninit<T>] {
    column.reserve(len);
    &mut column.spare_capacity_mut()[..len]
}

/// Appends the first `len` elements of `column`'s spare capacity.
///
/// # Safety
/// They must have been written (as through [`spare`]).
#[inline(always)]
unsafe fn commit<T>(column: &mut Vec<T>, len: usize) {
    // SAFETY: `spare` reserved them and the caller wrote them.
    unsafe { column.set_len(column.len() + len) }
}

/// The columns of a chunk of `Hit` records.
pub(crate) struct HitColumns<'a> {
    pub prim: &'a [u32],
    pub u: &'a [f32],
    pub v: &'a [f32],
}

impl<'a> HitColumns<'a> {
    pub fn new(view: &ColumnView<'a>) -> HitColumns<'a> {
        HitColumns {
            prim: view.field(1).as_u32(),
            u: view.field(2).as_f32(),
            v: view.field(3).as_f32(),
        }
    }
}

/// One `Surface` record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SurfaceRecord {
    pub position: Vec3,
    pub normal: Vec3,
    pub view: Vec3,
    pub scalar: f32,
    pub material: u32,
    pub hit: bool,
    pub sample: u32,
    pub weight: Vec3,
    pub depth: u32,
    /// The hit triangle's unit normal on the side the ray comes from.
    pub geometric: Vec3,
}

impl SurfaceRecord {
    /// What a ray that hits nothing sees.
    pub fn miss(sample: u32, weight: Vec3, depth: u32) -> SurfaceRecord {
        SurfaceRecord {
            position: Vec3::ZERO,
            normal: Vec3::ZERO,
            view: Vec3::ZERO,
            scalar: 0.0,
            material: 0,
            hit: false,
            sample,
            weight,
            depth,
            geometric: Vec3::ZERO,
        }
    }

    /// The start of a secondary ray: off the surface along the geometric normal,
    /// on the side the ray came from. (The shading normal only approximates the
    /// surface: it can lean so far from the triangle's normal that an offset
    /// along it leaves the origin on, or behind, the triangle's plane, and the
    /// ray passes through its own triangle.)
    #[inline]
    pub fn offset_origin(&self, epsilon: f32) -> Vec3 {
        offset_origin(self.position, self.geometric, epsilon)
    }
}

/// [`SurfaceRecord::offset_origin`] of a surface's position and geometric
/// normal (for code that holds them apart, in batches).
#[inline]
pub(crate) fn offset_origin(position: Vec3, geometric: Vec3, epsilon: f32) -> Vec3 {
    position + geometric * epsilon
}

/// `dir` turned onto the side of the plane of unit normal `geometric` (a
/// surface's geometric normal): mirrored in the plane when it points into (or
/// along) it, unchanged otherwise. Directions about a shading normal can
/// point into the surface where it leans away from the geometric one.
#[inline]
pub(crate) fn above_plane(dir: Vec3, geometric: Vec3) -> Vec3 {
    let below = dir.dot(geometric);
    // Both sides computed and one chosen, which batches of rays vectorise.
    let mirrored = dir - 2.0 * below * geometric;
    if below > 0.0 {
        dir
    } else {
        mirrored
    }
}

/// The columns of a chunk of `Surface` records.
pub(crate) struct SurfaceColumns<'a> {
    pub position: &'a [Vec3],
    pub normal: &'a [Vec3],
    pub view: &'a [Vec3],
    pub scalar: &'a [f32],
    pub material: &'a [u32],
    pub hit: &'a [bool],
    pub sample: &'a [u32],
    pub weight: &'a [Vec3],
    pub depth: &'a [u32],
    pub geometric: &'a [Vec3],
}

impl<'a> SurfaceColumns<'a> {
    pub fn new(view: &ColumnView<'a>) -> SurfaceColumns<'a> {
        SurfaceColumns {
            position: view.field(0).as_vec3(),
            normal: view.field(1).as_vec3(),
            view: view.field(2).as_vec3(),
            scalar: view.field(3).as_f32(),
            material: view.field(4).as_u32(),
            hit: view.field(5).as_bool(),
            sample: view.field(6).as_u32(),
            weight: view.field(7).as_vec3(),
            depth: view.field(8).as_u32(),
            geometric: view.field(9).as_vec3(),
        }
    }

    pub fn len(&self) -> usize {
        self.position.len()
    }

    #[inline]
    pub fn get(&self, index: usize) -> SurfaceRecord {
        SurfaceRecord {
            position: self.position[index],
            normal: self.normal[index],
            view: self.view[index],
            scalar: self.scalar[index],
            material: self.material[index],
            hit: self.hit[index],
            sample: self.sample[index],
            weight: self.weight[index],
            depth: self.depth[index],
            geometric: self.geometric[index],
        }
    }
}

/// Appends `Surface` records to an output column.
pub(crate) struct SurfaceWriter<'a> {
    position: &'a mut Vec<Vec3>,
    normal: &'a mut Vec<Vec3>,
    view: &'a mut Vec<Vec3>,
    scalar: &'a mut Vec<f32>,
    material: &'a mut Vec<u32>,
    hit: &'a mut Vec<bool>,
    sample: &'a mut Vec<u32>,
    weight: &'a mut Vec<Vec3>,
    depth: &'a mut Vec<u32>,
    geometric: &'a mut Vec<Vec3>,
}

impl<'a> SurfaceWriter<'a> {
    /// A writer of records appended by [`SurfaceWriter::extend_with`], which
    /// reserves what it writes.
    pub fn new(column: &'a mut Column) -> Result<SurfaceWriter<'a>, FunctorError> {
        let [position, normal, view, scalar, material, hit, sample, weight, depth, geometric] =
            record_fields_mut::<10>(column)?;
        Ok(SurfaceWriter {
            position: position.as_vec3_mut(),
            normal: normal.as_vec3_mut(),
            view: view.as_vec3_mut(),
            scalar: scalar.as_f32_mut(),
            material: material.as_u32_mut(),
            hit: hit.as_bool_mut(),
            sample: sample.as_u32_mut(),
            weight: weight.as_vec3_mut(),
            depth: depth.as_u32_mut(),
            geometric: geometric.as_vec3_mut(),
        })
    }

    /// Appends one record (the tests build inputs with it).
    #[cfg(test)]
    pub fn push(&mut self, surface: SurfaceRecord) {
        self.extend_with(1, |_| surface);
    }

    /// Appends the records of a run of misses ([`SurfaceRecord::miss`]) of
    /// these samples, weights and depths, a column at a time: fills and
    /// copies, not ten interleaved streams of scalar stores (most rays of a
    /// view with much background miss).
    pub fn extend_misses(
        &mut self,
        samples: &[u32],
        weights: impl ExactSizeIterator<Item = Vec3>,
        depths: &[u32],
    ) {
        let miss = SurfaceRecord::miss(0, Vec3::ZERO, 0);
        let len = samples.len();
        for (column, value) in [
            (&mut *self.position, miss.position),
            (&mut *self.normal, miss.normal),
            (&mut *self.view, miss.view),
            (&mut *self.geometric, miss.geometric),
        ] {
            extend_with_copies_of_vec3(column, len, value);
        }
        self.scalar.resize(self.scalar.len() + len, miss.scalar);
        self.material
            .resize(self.material.len() + len, miss.material);
        self.hit.resize(self.hit.len() + len, miss.hit);
        self.sample.extend_from_slice(samples);
        self.weight.extend(weights);
        self.depth.extend_from_slice(depths);
    }

    /// Appends `len` records, record `i` being `surface(i)`, in one pass that
    /// writes every column straight into its spare capacity (no per-element
    /// capacity checks).
    #[inline(always)]
    pub fn extend_with(&mut self, len: usize, mut surface: impl FnMut(usize) -> SurfaceRecord) {
        let position = spare(self.position, len);
        let normal = spare(self.normal, len);
        let view = spare(self.view, len);
        let scalar = spare(self.scalar, len);
        let material = spare(self.material, len);
        let hit = spare(self.hit, len);
        let sample = spare(self.sample, len);
        let weight = spare(self.weight, len);
        let depth = spare(self.depth, len);
        let geometric = spare(self.geometric, len);
        for i in 0..len {
            let s = surface(i);
            position[i].write(s.position);
            normal[i].write(s.normal);
            view[i].write(s.view);
            scalar[i].write(s.scalar);
            material[i].write(s.material);
            hit[i].write(s.hit);
            sample[i].write(s.sample);
            weight[i].write(s.weight);
            depth[i].write(s.depth);
            geometric[i].write(s.geometric);
        }
        // SAFETY: the loop wrote the first `len` spare elements of every column.
        unsafe {
            commit(self.position, len);
            commit(self.normal, len);
            commit(self.view, len);
            commit(self.scalar, len);
            commit(self.material, len);
            commit(self.hit, len);
            commit(self.sample, len);
            commit(self.weight, len);
            commit(self.depth, len);
            commit(self.geometric, len);
        }
    }
}

/// Appends `len` hits to a `Hit` output column, written by `produce` straight
/// into reserved space, field by field ([`HitPlaces`]). Both `intersect`
/// engines write through it, so that they pay the same for the writes.
///
/// # Safety
/// `produce` must write every one of the `len` places of every column (as
/// [`crate::bvh::Bvh::intersect_closest_into`] and [`HitPlaces::write`] of
/// each index do).
pub(crate) unsafe fn write_hits(
    column: &mut Column,
    len: usize,
    produce: impl FnOnce(HitPlaces<'_>),
) -> Result<(), FunctorError> {
    let [t, prim, u, v] = record_fields_mut::<4>(column)?;
    let (t, prim, u, v) = (
        t.as_f32_mut(),
        prim.as_u32_mut(),
        u.as_f32_mut(),
        v.as_f32_mut(),
    );
    produce(HitPlaces {
        t: spare(t, len),
        prim: spare(prim, len),
        u: spare(u, len),
        v: spare(v, len),
    });
    // SAFETY: `produce` wrote the first `len` spare elements of every column.
    unsafe {
        commit(t, len);
        commit(prim, len);
        commit(u, len);
        commit(v, len);
    }
    Ok(())
}

/// The `scene.diagonal` uniform (positive and finite).
pub(crate) fn scene_diagonal(ctx: &CallContext<'_>, functor: &str) -> Result<f32, FunctorError> {
    ctx.uniforms
        .get("scene", "diagonal")
        .and_then(|value| value.as_f32())
        .filter(|diagonal| diagonal.is_finite() && *diagonal > 0.0)
        .ok_or_else(|| {
            FunctorError::bad_input(format!(
                "{functor}: the scene.diagonal uniform is missing or not a positive number (no scene loaded?)"
            ))
        })
}

/// A named parameter read as a finite `f32`.
pub(crate) fn named_f32(
    ctx: &CallContext<'_>,
    index: usize,
    functor: &str,
    name: &str,
) -> Result<f32, FunctorError> {
    let value = ctx.named(index);
    value.as_f32().filter(|v| v.is_finite()).ok_or_else(|| {
        FunctorError::bad_input(format!(
            "{functor}: {name} must be a finite number, got {value}"
        ))
    })
}

/// A copy of a chunk of records with field `field` made by `replace` from the
/// old one, every other field kept.
pub(crate) fn with_field_replaced(
    records: &ColumnView<'_>,
    field: usize,
    replace: impl FnOnce(&ColumnView<'_>) -> Column,
) -> Column {
    let mut copy = records.to_column();
    *copy.field_mut(field) = replace(records.field(field));
    copy
}

/// Mutable access to all `N` field columns of a record output at once (the
/// runtime's `field_mut` borrows one at a time).
pub(crate) fn record_fields_mut<const N: usize>(
    column: &mut Column,
) -> Result<[&mut Column; N], FunctorError> {
    let type_error = |found: ElemType| {
        FunctorError::bad_input(format!(
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
    use super::{RayRecord, RayWriter, SurfaceRecord, SurfaceWriter};
    use crate::camera::{Camera, CameraSetup};
    use crate::register_tracer_functors;
    use crate::scene::{TraceResources, TraceScene};
    use crate::shading::Shading;
    use dpp_runtime::{
        CallContext, Column, ColumnView, ElemType, FunctorLibrary, HostValue, RecordRegistry,
        Uniforms,
    };
    use glam::Vec3;
    use std::sync::Arc;

    /// A live camera-like ray (weight 1, depth 0).
    pub fn ray(origin: Vec3, dir: Vec3, tmax: f32, sample: u32) -> RayRecord {
        RayRecord {
            origin,
            dir,
            tmax,
            sample,
            weight: Vec3::ONE,
            depth: 0,
        }
    }

    /// A hit at `position` whose shading normal, geometric normal and view
    /// vector are all `normal`: material 0, scalar 0, weight 1, depth 0.
    pub fn surface_hit(position: Vec3, normal: Vec3, sample: u32) -> SurfaceRecord {
        SurfaceRecord {
            position,
            normal,
            view: normal,
            scalar: 0.0,
            material: 0,
            hit: true,
            sample,
            weight: Vec3::ONE,
            depth: 0,
            geometric: normal,
        }
    }

    /// Rays: down onto the small square, down beside it onto the big one, up into
    /// nothing, and down with tmax short of the big square.
    pub fn probe_rays(fixture: &Fixture) -> Column {
        fixture.rays(&[
            ray(Vec3::new(0.25, 0.5, 2.0), Vec3::NEG_Z, f32::INFINITY, 0),
            ray(Vec3::new(3.0, 0.0, 2.0), Vec3::NEG_Z, f32::INFINITY, 1),
            ray(Vec3::new(0.0, 0.0, 2.0), Vec3::Z, f32::INFINITY, 2),
            ray(Vec3::new(3.0, 0.0, 2.0), Vec3::NEG_Z, 2.5, 3),
        ])
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
            Fixture::with_scene(TraceScene::new(mesh).unwrap())
        }

        pub fn with_scene(scene: TraceScene) -> Fixture {
            let mut library = FunctorLibrary::default();
            let records = register_tracer_functors(&mut library);
            crate::register_volume_render_functors(&mut library, records.ray);
            let scene = Arc::new(scene);
            let camera =
                Camera::new(Vec3::new(0.0, 0.0, 2.0), Vec3::ZERO, Vec3::Y, 90.0, 4, 3).unwrap();
            let resources = TraceResources::new(scene, Arc::new(CameraSetup::new(camera)));
            let uniforms = resources.uniforms();
            Fixture {
                library,
                resources,
                uniforms,
            }
        }

        /// Changes the shading (and the uniforms that follow from it).
        pub fn set_shading(&mut self, change: impl FnOnce(&mut Shading)) {
            change(Arc::make_mut(&mut self.resources.shading));
            self.uniforms = self.resources.uniforms();
        }

        pub fn record(&self, name: &str) -> ElemType {
            ElemType::Record(self.library.records.find(name).unwrap())
        }

        pub fn rays(&self, rays: &[RayRecord]) -> Column {
            ray_column(&self.library.records, rays)
        }

        pub fn surfaces(&self, surfaces: &[SurfaceRecord]) -> Column {
            surface_column(&self.library.records, surfaces)
        }

        pub fn hits(&self, hits: &[(f32, u32, f32, f32)]) -> Column {
            hit_column(&self.library.records, hits)
        }

        /// Runs functor `name` on one chunk starting at `first_index`.
        pub fn run(
            &self,
            name: &str,
            named: &[HostValue],
            first_index: usize,
            inputs: &[ColumnView<'_>],
        ) -> Result<Vec<Column>, dpp_runtime::FunctorError> {
            self.run_grouped(name, named, 1, first_index, inputs)
        }

        /// Runs a functor with `k = group` (a `Group` or `Expand` functor).
        pub fn run_grouped(
            &self,
            name: &str,
            named: &[HostValue],
            group: usize,
            first_index: usize,
            inputs: &[ColumnView<'_>],
        ) -> Result<Vec<Column>, dpp_runtime::FunctorError> {
            let functor = self.library.get(name).unwrap();
            // Named parameters left out take their defaults, as the runtime does.
            let mut values: Vec<HostValue> = named.to_vec();
            for param in
                &functor.signature().named[named.len().min(functor.signature().named.len())..]
            {
                values.push(param.default.expect("test passes required parameters"));
            }
            let ctx = CallContext {
                named: &values,
                uniforms: &self.uniforms,
                resources: &self.resources,
                first_index,
                group,
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

    /// The rays of a `Ray` column.
    /// A `Ray` column of `rays`.
    pub fn ray_column(records: &RecordRegistry, rays: &[RayRecord]) -> Column {
        let ty = ElemType::Record(records.find("Ray").unwrap());
        let mut column = Column::with_capacity(ty, 0, records);
        let mut writer = RayWriter::new(&mut column, rays.len()).unwrap();
        writer.extend_with(rays.len(), |i| rays[i]);
        column
    }

    /// A `Surface` column of `surfaces`.
    pub fn surface_column(records: &RecordRegistry, surfaces: &[SurfaceRecord]) -> Column {
        let ty = ElemType::Record(records.find("Surface").unwrap());
        let mut column = Column::with_capacity(ty, 0, records);
        let mut writer = SurfaceWriter::new(&mut column).unwrap();
        surfaces.iter().for_each(|&surface| writer.push(surface));
        column
    }

    /// A `Hit` column of `(t, prim, u, v)`s.
    pub fn hit_column(records: &RecordRegistry, hits: &[(f32, u32, f32, f32)]) -> Column {
        Column::Record {
            ty: records.find("Hit").unwrap(),
            fields: vec![
                Arc::new(Column::F32(hits.iter().map(|h| h.0).collect())),
                Arc::new(Column::U32(hits.iter().map(|h| h.1).collect())),
                Arc::new(Column::F32(hits.iter().map(|h| h.2).collect())),
                Arc::new(Column::F32(hits.iter().map(|h| h.3).collect())),
            ],
        }
    }

    pub fn read_rays(column: &Column) -> Vec<RayRecord> {
        let view = column.view();
        let rays = super::RayColumns::new(&view);
        (0..rays.len())
            .map(|i| RayRecord {
                origin: rays.origin[i],
                dir: rays.dir[i],
                tmax: rays.tmax[i],
                sample: rays.sample[i],
                weight: rays.weight[i],
                depth: rays.depth[i],
            })
            .collect()
    }

    /// The surfaces of a `Surface` column.
    pub fn read_surfaces(column: &Column) -> Vec<SurfaceRecord> {
        let view = column.view();
        let surfaces = super::SurfaceColumns::new(&view);
        (0..surfaces.len()).map(|i| surfaces.get(i)).collect()
    }

    /// The element types a monomorphic signature's parameters have.
    fn exact_types(params: &[dpp_runtime::ArrayParam]) -> Vec<ElemType> {
        params
            .iter()
            .map(|p| match p.ty {
                dpp_runtime::TypePattern::Exact(ty) => ty,
                dpp_runtime::TypePattern::Var(..) => {
                    unreachable!("tracer functors are monomorphic")
                }
            })
            .collect()
    }

    /// Functor `name`'s WGSL twin for `resources`, as the GPU backend asks for
    /// it (function `stage7_{name}`), validated by `check_twin` with the
    /// library's uniforms; also checks that every `_fail(code)` the source
    /// raises has a message and every message is raised.
    pub fn checked_twin(
        library: &FunctorLibrary,
        name: &str,
        resources: &(dyn std::any::Any + Send + Sync),
    ) -> Result<dpp_runtime::wgsl::WgslTwin, String> {
        let functor = library.get(name).ok_or(format!("no functor `{name}`"))?;
        let signature = functor.signature();
        let (inputs, outputs) = (
            exact_types(&signature.inputs),
            exact_types(&signature.outputs),
        );
        let function = format!("stage7_{name}");
        let request = dpp_runtime::wgsl::WgslRequest {
            function: &function,
            inputs: &inputs,
            outputs: &outputs,
            records: &library.records,
            resources,
        };
        let twin = functor.wgsl(&request).map_err(|e| e.message)?;
        dpp_gpu::check_twin(signature, &request, &twin, &library.uniforms)?;
        let fail = format!("{function}_fail(");
        let mut raised: Vec<usize> = twin
            .source
            .match_indices(&fail)
            .map(|(at, _)| {
                let code = &twin.source[at + fail.len()..];
                let digits: String = code.chars().take_while(char::is_ascii_digit).collect();
                digits.parse().expect("failure codes are literals")
            })
            .collect();
        raised.sort_unstable();
        raised.dedup();
        let expected: Vec<usize> = (0..twin.failures.len()).collect();
        if raised != expected {
            return Err(format!(
                "{name}: the source raises failures {raised:?} but has messages for {expected:?}"
            ));
        }
        Ok(twin)
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::{ray, read_rays, Fixture};
    use super::{runs_of, RayRecord, RayWriter};
    use glam::Vec3;

    #[test]
    fn runs_of_equal_keys_cover_every_index_in_order() {
        let keys = [true, true, false, true, false, false, false];
        let runs: Vec<_> = runs_of(keys.len(), |index| keys[index]).collect();
        assert_eq!(
            runs,
            [(true, 0..2), (false, 2..3), (true, 3..4), (false, 4..7)]
        );
        assert_eq!(runs_of(0, |_| unreachable!("no index")).count(), 0);
        assert_eq!(runs_of(3, |_| false).collect::<Vec<_>>(), [(false, 0..3)]);
    }

    /// Records come out in the order written, a few at a time.
    #[test]
    fn rays_are_appended_in_order() {
        let fixture = Fixture::new();
        let mut column = fixture.rays(&[]);
        let mut writer = RayWriter::new(&mut column, 0).unwrap();
        for group in 0..3 {
            writer.extend_with(2, |lane| {
                ray(Vec3::ZERO, Vec3::Z, 1.0, (10 * group + lane) as u32)
            });
        }
        writer.extend_with(0, |_| unreachable!("no records"));
        writer.extend_with(1, |_| ray(Vec3::ONE, Vec3::X, 2.0, 99));
        let rays = read_rays(&column);
        let samples: Vec<u32> = rays.iter().map(|r| r.sample).collect();
        assert_eq!(samples, [0, 1, 10, 11, 20, 21, 99]);
        assert_eq!(rays[6], ray(Vec3::ONE, Vec3::X, 2.0, 99));
    }

    /// Runs of misses' dead rays, written a column at a time, are the
    /// records written one by one, after and before other rays, for every
    /// fanout the copies are specialised for and others, and run lengths
    /// around the eight-ray copies.
    #[test]
    fn dead_rays_of_a_run_of_misses_are_written_column_by_column() {
        let fixture = Fixture::new();
        for lanes in [0, 1, 2, 3, 4, 5, 8] {
            for misses in [0, 1, 2, 7, 8, 9, 17] {
                let samples: Vec<u32> = (0..misses).map(|miss| 3 * miss + 1).collect();
                let depths: Vec<u32> = (0..misses).map(|miss| miss % 3).collect();
                let live = ray(Vec3::ONE, Vec3::X, 2.0, 99);
                let mut column = fixture.rays(&[]);
                let mut writer = RayWriter::new(&mut column, 0).unwrap();
                writer.extend_with(1, |_| live);
                writer.extend_dead(&samples, depths.iter().copied(), lanes);
                writer.extend_with(1, |_| live);
                let mut expected = vec![live];
                for (&sample, &depth) in samples.iter().zip(&depths) {
                    expected.extend(std::iter::repeat_n(RayRecord::dead(sample, depth), lanes));
                }
                expected.push(live);
                assert_eq!(
                    read_rays(&column),
                    expected,
                    "{lanes} lanes, {misses} misses"
                );
            }
        }
    }
}
