//! Arrays as the CPU backend stores them: one typed column per element type,
//! records as one column per field (structure of arrays).

use crate::host::HostValue;
use crate::types::{ElemType, RecordId, RecordRegistry};
use glam::{Vec2, Vec3, Vec4};
use std::sync::Arc;

/// An owned array.
#[derive(Clone, Debug, PartialEq)]
pub enum Column {
    Bool(Vec<bool>),
    U32(Vec<u32>),
    I32(Vec<i32>),
    F32(Vec<f32>),
    Vec2(Vec<Vec2>),
    Vec3(Vec<Vec3>),
    Vec4(Vec<Vec4>),
    /// Fields are shared so that `a.field` is a zero-copy view of an array.
    Record {
        ty: RecordId,
        fields: Vec<Arc<Column>>,
    },
}

/// One scalar of an element, for comparing arrays element by element:
/// integers and bools by value, floats as they are (vectors by component).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scalar {
    Int(i64),
    Float(f32),
}

/// How many representable floats apart `a` and `b` are (`±0` are one value):
/// how the backends' agreement tests measure float differences.
pub fn ulp_distance(a: f32, b: f32) -> u64 {
    let ordered = |x: f32| {
        let bits = x.to_bits();
        let magnitude = i64::from(bits & 0x7fff_ffff);
        if bits >> 31 == 1 {
            -magnitude
        } else {
            magnitude
        }
    };
    ordered(a).abs_diff(ordered(b))
}

/// A borrowed slice of an array: what a functor's CPU implementation receives.
#[derive(Clone, Debug)]
pub enum ColumnView<'a> {
    Bool(&'a [bool]),
    U32(&'a [u32]),
    I32(&'a [i32]),
    F32(&'a [f32]),
    Vec2(&'a [Vec2]),
    Vec3(&'a [Vec3]),
    Vec4(&'a [Vec4]),
    Record {
        ty: RecordId,
        fields: Vec<ColumnView<'a>>,
    },
}

/// Calls `$body` with `$v` bound to the inner `Vec` (or slice) of every primitive
/// variant; `$record` handles records. Keeps per-type code in one place.
#[macro_export]
macro_rules! for_each_primitive {
    ($enum:ident, $value:expr, $v:ident => $body:expr, $record:pat => $rbody:expr) => {
        match $value {
            $enum::Bool($v) => $body,
            $enum::U32($v) => $body,
            $enum::I32($v) => $body,
            $enum::F32($v) => $body,
            $enum::Vec2($v) => $body,
            $enum::Vec3($v) => $body,
            $enum::Vec4($v) => $body,
            $record => $rbody,
        }
    };
}

/// Like [`for_each_primitive`], but rebuilds the same variant from `$body`.
#[macro_export]
macro_rules! map_primitive {
    ($in:ident => $out:ident, $value:expr, $v:ident => $body:expr, $record:pat => $rbody:expr) => {
        match $value {
            $in::Bool($v) => $out::Bool($body),
            $in::U32($v) => $out::U32($body),
            $in::I32($v) => $out::I32($body),
            $in::F32($v) => $out::F32($body),
            $in::Vec2($v) => $out::Vec2($body),
            $in::Vec3($v) => $out::Vec3($body),
            $in::Vec4($v) => $out::Vec4($body),
            $record => $rbody,
        }
    };
}

impl Column {
    /// A record of type `id` whose fields `make` builds from their types.
    pub fn record_with(
        id: RecordId,
        records: &RecordRegistry,
        mut make: impl FnMut(ElemType) -> Column,
    ) -> Column {
        Column::Record {
            ty: id,
            fields: records
                .get(id)
                .fields
                .iter()
                .map(|(_, field)| Arc::new(make(*field)))
                .collect(),
        }
    }

    /// An empty column of type `ty` with room for `capacity` elements.
    pub fn with_capacity(ty: ElemType, capacity: usize, records: &RecordRegistry) -> Column {
        match ty {
            ElemType::Bool => Column::Bool(Vec::with_capacity(capacity)),
            ElemType::U32 => Column::U32(Vec::with_capacity(capacity)),
            ElemType::I32 => Column::I32(Vec::with_capacity(capacity)),
            ElemType::F32 => Column::F32(Vec::with_capacity(capacity)),
            ElemType::Vec2 => Column::Vec2(Vec::with_capacity(capacity)),
            ElemType::Vec3 => Column::Vec3(Vec::with_capacity(capacity)),
            ElemType::Vec4 => Column::Vec4(Vec::with_capacity(capacity)),
            ElemType::Record(id) => Column::record_with(id, records, |field| {
                Column::with_capacity(field, capacity, records)
            }),
        }
    }

    /// `len` zeroed elements (all-zero bits for every field).
    pub fn zeroed(ty: ElemType, len: usize, records: &RecordRegistry) -> Column {
        match ty {
            ElemType::Bool => Column::Bool(vec![false; len]),
            ElemType::U32 => Column::U32(vec![0; len]),
            ElemType::I32 => Column::I32(vec![0; len]),
            ElemType::F32 => Column::F32(vec![0.0; len]),
            // Zeroed allocations, as `vec![0; len]` makes for scalars: a large
            // one comes as fresh zero pages, so a frame's image is not
            // cleared on one thread before the stage that fills it.
            ElemType::Vec2 => Column::Vec2(bytemuck::zeroed_vec(len)),
            ElemType::Vec3 => Column::Vec3(bytemuck::zeroed_vec(len)),
            ElemType::Vec4 => Column::Vec4(bytemuck::zeroed_vec(len)),
            ElemType::Record(id) => {
                Column::record_with(id, records, |field| Column::zeroed(field, len, records))
            }
        }
    }

    /// `len` copies of a host scalar, as `fill(n, value)` makes them.
    /// Integers become `u32` (an error if negative or too large).
    pub fn filled(value: HostValue, len: usize) -> Result<Column, String> {
        Ok(match value {
            HostValue::Bool(b) => Column::Bool(vec![b; len]),
            HostValue::Int(i) => Column::U32(vec![
                u32::try_from(i).map_err(|_| format!(
                    "fill value {i} does not fit in u32"
                ))?;
                len
            ]),
            HostValue::Float(f) => Column::F32(vec![f as f32; len]),
            HostValue::Vec2(v) => Column::Vec2(vec![Vec2::from(v); len]),
            HostValue::Vec3(v) => Column::Vec3(vec![Vec3::from(v); len]),
            HostValue::Vec4(v) => Column::Vec4(vec![Vec4::from(v); len]),
        })
    }

    pub fn elem_type(&self) -> ElemType {
        match self {
            Column::Bool(_) => ElemType::Bool,
            Column::U32(_) => ElemType::U32,
            Column::I32(_) => ElemType::I32,
            Column::F32(_) => ElemType::F32,
            Column::Vec2(_) => ElemType::Vec2,
            Column::Vec3(_) => ElemType::Vec3,
            Column::Vec4(_) => ElemType::Vec4,
            Column::Record { ty, .. } => ElemType::Record(*ty),
        }
    }

    pub fn len(&self) -> usize {
        for_each_primitive!(Column, self, v => v.len(), Column::Record { fields, .. } => fields[0].len())
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn view(&self) -> ColumnView<'_> {
        map_primitive!(Column => ColumnView, self, v => v.as_slice(),
        Column::Record { ty, fields } => ColumnView::Record {
            ty: *ty,
            fields: fields.iter().map(|f| f.view()).collect(),
        })
    }

    /// Elements `range` as a view.
    pub fn slice(&self, range: std::ops::Range<usize>) -> ColumnView<'_> {
        self.view().slice(range)
    }

    /// Appends all elements of `other`, which must have the same type.
    pub fn extend_from_view(&mut self, other: &ColumnView<'_>) {
        match (self, other) {
            (Column::Bool(a), ColumnView::Bool(b)) => a.extend_from_slice(b),
            (Column::U32(a), ColumnView::U32(b)) => a.extend_from_slice(b),
            (Column::I32(a), ColumnView::I32(b)) => a.extend_from_slice(b),
            (Column::F32(a), ColumnView::F32(b)) => a.extend_from_slice(b),
            (Column::Vec2(a), ColumnView::Vec2(b)) => a.extend_from_slice(b),
            (Column::Vec3(a), ColumnView::Vec3(b)) => a.extend_from_slice(b),
            (Column::Vec4(a), ColumnView::Vec4(b)) => a.extend_from_slice(b),
            (Column::Record { fields: a, .. }, ColumnView::Record { fields: b, .. }) => {
                for (fa, fb) in a.iter_mut().zip(b) {
                    Arc::make_mut(fa).extend_from_view(fb);
                }
            }
            (a, b) => panic!(
                "extend_from_view: type mismatch {:?} vs {:?}",
                a.elem_type(),
                b.elem_type()
            ),
        }
    }

    /// Appends element `i`'s scalars to `out`, record fields in order.
    pub fn scalars_of(&self, i: usize, out: &mut Vec<Scalar>) {
        let floats =
            |xs: &[f32], out: &mut Vec<Scalar>| out.extend(xs.iter().map(|x| Scalar::Float(*x)));
        match self {
            Column::Bool(v) => out.push(Scalar::Int(v[i].into())),
            Column::U32(v) => out.push(Scalar::Int(v[i].into())),
            Column::I32(v) => out.push(Scalar::Int(v[i].into())),
            Column::F32(v) => out.push(Scalar::Float(v[i])),
            Column::Vec2(v) => floats(&v[i].to_array(), out),
            Column::Vec3(v) => floats(&v[i].to_array(), out),
            Column::Vec4(v) => floats(&v[i].to_array(), out),
            Column::Record { fields, .. } => fields.iter().for_each(|f| f.scalars_of(i, out)),
        }
    }

    /// Concatenates same-typed columns in order (the CPU backend's way of joining chunks).
    pub fn concat(ty: ElemType, parts: &[Column], records: &RecordRegistry) -> Column {
        let views: Vec<ColumnView<'_>> = parts.iter().map(Column::view).collect();
        Column::concat_views(ty, &views, records)
    }

    /// [`Column::concat`] of borrowed parts; a record's fields are joined in
    /// parallel (joining is a plain copy, bound by memory bandwidth).
    pub fn concat_views(
        ty: ElemType,
        parts: &[ColumnView<'_>],
        records: &RecordRegistry,
    ) -> Column {
        use rayon::prelude::*;
        if let ElemType::Record(id) = ty {
            let fields = records
                .get(id)
                .fields
                .par_iter()
                .enumerate()
                .map(|(index, (_, field_ty))| {
                    let field_parts: Vec<ColumnView<'_>> =
                        parts.iter().map(|part| part.field(index).clone()).collect();
                    Arc::new(Column::concat_views(*field_ty, &field_parts, records))
                })
                .collect();
            return Column::Record { ty: id, fields };
        }
        let total = parts.iter().map(ColumnView::len).sum();
        let mut out = Column::with_capacity(ty, total, records);
        for part in parts {
            out.extend_from_view(part);
        }
        out
    }

    /// The shared column of field `index` of a record array (`a.field`).
    pub fn field(&self, index: usize) -> Option<Arc<Column>> {
        match self {
            Column::Record { fields, .. } => fields.get(index).cloned(),
            _ => None,
        }
    }

    /// Mutable access to field `index` of a record column being built.
    pub fn field_mut(&mut self, index: usize) -> &mut Column {
        match self {
            Column::Record { fields, .. } => Arc::make_mut(&mut fields[index]),
            other => panic!("field_mut on a {:?} column", other.elem_type()),
        }
    }
}

impl<'a> ColumnView<'a> {
    pub fn elem_type(&self) -> ElemType {
        match self {
            ColumnView::Bool(_) => ElemType::Bool,
            ColumnView::U32(_) => ElemType::U32,
            ColumnView::I32(_) => ElemType::I32,
            ColumnView::F32(_) => ElemType::F32,
            ColumnView::Vec2(_) => ElemType::Vec2,
            ColumnView::Vec3(_) => ElemType::Vec3,
            ColumnView::Vec4(_) => ElemType::Vec4,
            ColumnView::Record { ty, .. } => ElemType::Record(*ty),
        }
    }

    pub fn len(&self) -> usize {
        for_each_primitive!(ColumnView, self, v => v.len(), ColumnView::Record { fields, .. } => fields[0].len())
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn slice(&self, range: std::ops::Range<usize>) -> ColumnView<'a> {
        map_primitive!(ColumnView => ColumnView, self, v => &v[range.clone()],
        ColumnView::Record { ty, fields } => ColumnView::Record {
            ty: *ty,
            fields: fields.iter().map(|f| f.slice(range.clone())).collect(),
        })
    }

    pub fn to_column(&self) -> Column {
        map_primitive!(ColumnView => Column, self, v => v.to_vec(),
        ColumnView::Record { ty, fields } => Column::Record {
            ty: *ty,
            fields: fields.iter().map(|f| Arc::new(f.to_column())).collect(),
        })
    }

    pub fn field(&self, index: usize) -> &ColumnView<'a> {
        match self {
            ColumnView::Record { fields, .. } => &fields[index],
            other => panic!("field on a {:?} view", other.elem_type()),
        }
    }
}

/// Typed access to views and columns, for functor implementations.
/// A mismatch is a bug in the plan compiler's type checking, so these panic.
macro_rules! typed_accessors {
    ($($variant:ident, $t:ty, $as_ref:ident, $as_mut:ident;)*) => {
        impl<'a> ColumnView<'a> {
            $(pub fn $as_ref(&self) -> &'a [$t] {
                match self {
                    ColumnView::$variant(v) => v,
                    other => panic!(concat!("expected ", stringify!($variant), ", got {:?}"), other.elem_type()),
                }
            })*
        }
        impl Column {
            $(pub fn $as_mut(&mut self) -> &mut Vec<$t> {
                match self {
                    Column::$variant(v) => v,
                    other => panic!(concat!("expected ", stringify!($variant), ", got {:?}"), other.elem_type()),
                }
            })*
        }
    };
}

typed_accessors! {
    Bool, bool, as_bool, as_bool_mut;
    U32, u32, as_u32, as_u32_mut;
    I32, i32, as_i32, as_i32_mut;
    F32, f32, as_f32, as_f32_mut;
    Vec2, Vec2, as_vec2, as_vec2_mut;
    Vec3, Vec3, as_vec3, as_vec3_mut;
    Vec4, Vec4, as_vec4, as_vec4_mut;
}

/// `out[i] = src[source_of(i)]` for `i < len`. The runtime's own index maps
/// (a fan-out's `i / k`) use it directly; `source_of` must stay below
/// `src.len()`, so user-supplied indices go through [`gather`].
pub(crate) fn gather_by_position(
    src: &ColumnView<'_>,
    len: usize,
    source_of: &impl Fn(usize) -> usize,
) -> Column {
    map_primitive!(ColumnView => Column, src,
    values => (0..len).map(|position| values[source_of(position)]).collect(),
    ColumnView::Record { ty, fields } => Column::Record {
        ty: *ty,
        fields: fields
            .iter()
            .map(|field| Arc::new(gather_by_position(field, len, source_of)))
            .collect(),
    })
}
