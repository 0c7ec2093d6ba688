//! Direct volume rendering (`pipelines/volume.dpp`): the `March` record and
//! the definitions the functors `volumeEntry`, `volumeMarch`, `marchLive` and
//! `overBackground` compute (their twins follow the same operations).
//!
//! # Definitions
//!
//! The volume is the run's ([`crate::TraceResources::volume`]); its samples
//! sit at `origin + spacing * (first + (i, j, k))` and the field between them
//! is **trilinear**. A march works in *sample coordinates* `g = (p - origin) /
//! spacing - first` (sample `(i, j, k)` at `g = (i, j, k)`), where the ray is
//! `g(t) = o + d t` with `o` the ray origin's coordinates and `d = dir /
//! spacing`; `t` stays the distance along the (unit) camera ray, so it compares
//! with a hit's `t`.
//!
//! - **Entry**: the ray is clipped to the box of the samples, `0 <= g <=
//!   dims - 1` on every axis (slabs), and to `0 <= t <= ray.tmax`. A ray that
//!   misses gets `t = +inf`, `tEnd = -inf`. With `jitter` the first sample is
//!   moved `u * step` further, `u` in [0, 1) the top 24 bits of the PCG hash of
//!   the ray's `sample` (deterministic).
//! - **Samples** at `t, t + step, …` while `t <= tEnd`. A sample's value `s` is
//!   the trilinear interpolation of the 8 samples around `g(t)` (clamped into
//!   the box), classified by the transfer function (the shading's colour map
//!   and its opacity table, [`crate::shading::ColorMap::rgba_at`]) at `(s - min)
//!   / (max - min)` of the scalar range: a linear colour `c` and an opacity `a`.
//! - **Opacity correction**: `a` is the opacity of a slab `unit` thick (the
//!   pipeline passes one cell, `volume.cellSize`: ANARI's `unitDistance`); a
//!   sample `step` apart stands for `alpha = 1 - (1 - a)^(step / unit)`.
//! - **Shading** (`shade`): `c` times `0.3 + 0.7 |n · l|`, `n` the normalised
//!   gradient of the trilinear field (central differences one sample apart on
//!   each axis, in world units) and `l` the ray's direction (a head light);
//!   unchanged where the gradient is 0.
//! - **Compositing**, front to back: `color += (1 - A) alpha c`, `A += (1 - A)
//!   alpha`; then `t += step`. **Early ray termination**: once `A >= cutoff`
//!   the march ends (`t = +inf`).
//! - A march is **live** while `t <= tEnd`.
//! - **Background**: a pixel's colour is `color + (1 - A) background`.
//!
//! # Empty-space skipping
//!
//! Blocks of `size`³ cells (the last ones along an axis may be smaller):
//! block `b` covers sample coordinates `b size ..= (b + 1) size` on each axis,
//! so every sample a trilinear value inside it reads is one of its own. A
//! block's value range is the reduction of its cells' ranges (`cellRange`
//! gives `(min, -max)` of a cell's 8 corners so that one `min` reduces both);
//! it is *transparent* when the transfer function's opacity is 0 over all of
//! it ([`ColorMap::transparent_between`]). A march in a transparent block
//! (`marchBlock` is the block of `g(t)`) jumps to the first `t + n step`
//! (`n >= 1`) past the block's far side: its samples there would have added
//! nothing, and the samples after it stay on the same lattice (up to the
//! rounding of `n step` against `n` additions of `step`).

use crate::functors::occ_ray_gen::pcg_hash;
use crate::functors::{named_f32, record_fields_mut};
use crate::shading::ColorMap;
use crate::volume::Volume;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, FunctorError, HostType, NamedParam, RecordId,
    RecordRegistry, RecordType,
};
use glam::{UVec3, Vec3};

/// The `step` argument of the functors that march (read by [`step`]).
pub(crate) const STEP: NamedParam = NamedParam {
    name: "step",
    ty: HostType::Float,
    default: None,
    doc: "the distance between samples (world units, > 0)",
};

/// The `size` argument of the empty-space skipping functors (read by [`block_size`]).
pub(crate) const BLOCK_SIZE: NamedParam = NamedParam {
    name: "size",
    ty: HostType::Int,
    default: None,
    doc: "cells per side of a block (>= 1)",
};

/// The [`STEP`] argument, named parameter `index`: finite and positive.
pub(crate) fn step(
    ctx: &CallContext<'_>,
    index: usize,
    functor: &str,
) -> Result<f32, FunctorError> {
    let step = named_f32(ctx, index, functor, "step")?;
    if step > 0.0 {
        Ok(step)
    } else {
        Err(FunctorError::bad_input(format!(
            "{functor}: step must be above 0, got {step}"
        )))
    }
}

/// The [`BLOCK_SIZE`] argument, named parameter `index`: at least 1.
pub(crate) fn block_size(
    ctx: &CallContext<'_>,
    index: usize,
    functor: &str,
) -> Result<u32, FunctorError> {
    ctx.named(index)
        .as_u32()
        .filter(|&size| size >= 1)
        .ok_or_else(|| {
            FunctorError::bad_input(format!(
                "{functor}: size must be at least 1, got {}",
                ctx.named(index)
            ))
        })
}

/// Registers the `March` record; returns its id.
pub fn register_march_record(records: &mut RecordRegistry) -> RecordId {
    records.register(RecordType {
        name: "March".into(),
        fields: vec![
            ("origin".into(), ElemType::Vec3),
            ("dir".into(), ElemType::Vec3),
            ("t".into(), ElemType::F32),
            ("tEnd".into(), ElemType::F32),
            ("color".into(), ElemType::Vec3),
            ("alpha".into(), ElemType::F32),
            ("sample".into(), ElemType::U32),
        ],
        doc: "a ray marching through the volume: origin and dir in sample coordinates (dir per unit of t), the next sample's t and the last t, the colour and opacity accumulated front to back, and the ray's sample (row-major pixel); live while t <= tEnd".into(),
    })
}

/// One `March` record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarchRecord {
    pub origin: Vec3,
    pub dir: Vec3,
    pub t: f32,
    pub t_end: f32,
    pub color: Vec3,
    pub alpha: f32,
    pub sample: u32,
}

impl MarchRecord {
    /// A march that samples nothing.
    pub fn missed(origin: Vec3, dir: Vec3, sample: u32) -> MarchRecord {
        MarchRecord {
            origin,
            dir,
            t: f32::INFINITY,
            t_end: f32::NEG_INFINITY,
            color: Vec3::ZERO,
            alpha: 0.0,
            sample,
        }
    }

    /// `t <= tEnd` (false for NaN).
    #[inline]
    pub fn live(&self) -> bool {
        self.t <= self.t_end
    }
}

/// The columns of a chunk of `March` records.
pub(crate) struct MarchColumns<'a> {
    origin: &'a [Vec3],
    dir: &'a [Vec3],
    t: &'a [f32],
    t_end: &'a [f32],
    color: &'a [Vec3],
    alpha: &'a [f32],
    sample: &'a [u32],
}

impl<'a> MarchColumns<'a> {
    pub fn new(view: &ColumnView<'a>) -> MarchColumns<'a> {
        MarchColumns {
            origin: view.field(0).as_vec3(),
            dir: view.field(1).as_vec3(),
            t: view.field(2).as_f32(),
            t_end: view.field(3).as_f32(),
            color: view.field(4).as_vec3(),
            alpha: view.field(5).as_f32(),
            sample: view.field(6).as_u32(),
        }
    }

    pub fn len(&self) -> usize {
        self.t.len()
    }

    #[inline]
    pub fn get(&self, i: usize) -> MarchRecord {
        MarchRecord {
            origin: self.origin[i],
            dir: self.dir[i],
            t: self.t[i],
            t_end: self.t_end[i],
            color: self.color[i],
            alpha: self.alpha[i],
            sample: self.sample[i],
        }
    }
}

/// Appends `March` records to an output column.
pub(crate) struct MarchWriter<'a> {
    fields: [&'a mut Column; 7],
}

impl<'a> MarchWriter<'a> {
    pub fn new(column: &'a mut Column) -> Result<MarchWriter<'a>, FunctorError> {
        Ok(MarchWriter {
            fields: record_fields_mut::<7>(column)?,
        })
    }

    #[inline]
    pub fn push(&mut self, m: MarchRecord) {
        let [origin, dir, t, t_end, color, alpha, sample] = &mut self.fields;
        origin.as_vec3_mut().push(m.origin);
        dir.as_vec3_mut().push(m.dir);
        t.as_f32_mut().push(m.t);
        t_end.as_f32_mut().push(m.t_end);
        color.as_vec3_mut().push(m.color);
        alpha.as_f32_mut().push(m.alpha);
        sample.as_u32_mut().push(m.sample);
    }
}

/// The start of the march of a ray from `origin` along unit `dir` up to
/// `tmax` (before any jitter): `(o, d, t, tEnd)` as [the module](self) defines them.
pub fn entry(volume: &Volume, origin: Vec3, dir: Vec3, tmax: f32) -> (Vec3, Vec3, f32, f32) {
    let o = (origin - volume.origin) / volume.spacing - volume.first.as_vec3();
    let d = dir / volume.spacing;
    let last = volume.dims.saturating_sub(UVec3::ONE).as_vec3();
    let (mut near, mut far) = (0.0f32, tmax);
    for axis in 0..3 {
        if d[axis] == 0.0 {
            if !(o[axis] >= 0.0 && o[axis] <= last[axis]) {
                return (o, d, f32::INFINITY, f32::NEG_INFINITY);
            }
            continue;
        }
        let t0 = (0.0 - o[axis]) / d[axis];
        let t1 = (last[axis] - o[axis]) / d[axis];
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1));
    }
    if near <= far {
        (o, d, near, far)
    } else {
        (o, d, f32::INFINITY, f32::NEG_INFINITY)
    }
}

/// The jitter fraction of ray `sample`: in [0, 1), from 24 bits of its hash.
#[inline]
pub fn jitter(sample: u32) -> f32 {
    (pcg_hash(sample) >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// The trilinear value at sample coordinates `g` (clamped into the box).
#[inline]
pub fn trilinear(volume: &Volume, g: Vec3) -> f32 {
    let last = volume.dims.saturating_sub(UVec3::ONE);
    let g = g.clamp(Vec3::ZERO, last.as_vec3());
    let cell = g
        .as_uvec3()
        .min(volume.dims.saturating_sub(UVec3::splat(2)));
    let f = g - cell.as_vec3();
    let v = |dx: u32, dy: u32, dz: u32| volume.value(cell.x + dx, cell.y + dy, cell.z + dz);
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let x00 = lerp(v(0, 0, 0), v(1, 0, 0), f.x);
    let x10 = lerp(v(0, 1, 0), v(1, 1, 0), f.x);
    let x01 = lerp(v(0, 0, 1), v(1, 0, 1), f.x);
    let x11 = lerp(v(0, 1, 1), v(1, 1, 1), f.x);
    lerp(lerp(x00, x10, f.y), lerp(x01, x11, f.y), f.z)
}

/// The gradient of the trilinear field at `g` in world units: central
/// differences one sample apart.
#[inline]
pub fn gradient(volume: &Volume, g: Vec3) -> Vec3 {
    let axis = |a: Vec3| trilinear(volume, g + a) - trilinear(volume, g - a);
    Vec3::new(axis(Vec3::X), axis(Vec3::Y), axis(Vec3::Z)) / (2.0 * volume.spacing)
}

/// What `volumeMarch` is asked to do.
#[derive(Clone, Copy, Debug)]
pub struct MarchParams {
    pub step: f32,
    pub unit: f32,
    pub samples: u32,
    pub cutoff: f32,
    pub shade: bool,
    /// The scalar range's low end and `1 / (max - min)`.
    pub low: f32,
    pub inverse_range: f32,
}

/// Up to `params.samples` samples of a live march.
#[inline]
pub fn march(volume: &Volume, map: &ColorMap, params: &MarchParams, m: MarchRecord) -> MarchRecord {
    let mut m = m;
    let ratio = params.step / params.unit;
    let light = (m.dir * volume.spacing).normalize_or_zero();
    for _ in 0..params.samples {
        if !m.live() {
            break;
        }
        let g = m.origin + m.dir * m.t;
        let s = trilinear(volume, g);
        let (mut c, a) = map.rgba_at((s - params.low) * params.inverse_range);
        let alpha = corrected_opacity(a, ratio);
        if params.shade && alpha > 0.0 {
            let n = gradient(volume, g).normalize_or_zero();
            if n != Vec3::ZERO {
                c *= 0.3 + 0.7 * n.dot(light).abs();
            }
        }
        let weight = (1.0 - m.alpha) * alpha;
        m.color += c * weight;
        m.alpha += weight;
        m.t += params.step;
        if m.alpha >= params.cutoff {
            m.t = f32::INFINITY;
        }
    }
    m
}

/// Skipping blocks per axis: the cells divided into blocks of `size`, rounded up.
pub fn block_dims(volume: &Volume, size: u32) -> UVec3 {
    let cells = volume.cell_dims().max(UVec3::ONE);
    (cells + UVec3::splat(size - 1)) / size
}

/// The skipping block of sample coordinates `g` (clamped into the grid of blocks).
#[inline]
pub fn point_block(volume: &Volume, g: Vec3, size: u32) -> UVec3 {
    let last = block_dims(volume, size) - UVec3::ONE;
    (g / size as f32).max(Vec3::ZERO).as_uvec3().min(last)
}

/// The index of block `b` (x fastest).
#[inline]
pub fn block_index(volume: &Volume, b: UVec3, size: u32) -> u32 {
    let dims = block_dims(volume, size);
    b.x + dims.x * (b.y + dims.y * b.z)
}

/// The march moved past the far side of the block it is in, on its lattice
/// of samples `step` apart.
#[inline]
pub fn skip_block(volume: &Volume, m: MarchRecord, size: u32, step: f32) -> MarchRecord {
    let g = m.origin + m.dir * m.t;
    let b = point_block(volume, g, size);
    let last = volume.dims.saturating_sub(UVec3::ONE).as_vec3();
    let low = (b * size).as_vec3();
    let high = ((b + UVec3::ONE) * size).as_vec3().min(last);
    let mut exit = f32::INFINITY;
    for axis in 0..3 {
        if m.dir[axis] != 0.0 {
            let t0 = (low[axis] - m.origin[axis]) / m.dir[axis];
            let t1 = (high[axis] - m.origin[axis]) / m.dir[axis];
            exit = exit.min(t0.max(t1));
        }
    }
    let steps = ((exit - m.t) / step).ceil().max(1.0);
    MarchRecord {
        t: m.t + steps * step,
        ..m
    }
}

/// `1 - (1 - a)^ratio`, exact at `a = 0` and `a = 1`.
#[inline]
pub fn corrected_opacity(a: f32, ratio: f32) -> f32 {
    if a <= 0.0 {
        0.0
    } else if a >= 1.0 {
        1.0
    } else {
        1.0 - (1.0 - a).powf(ratio)
    }
}
