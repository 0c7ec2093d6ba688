//! Columns as bytes for MPI messages. The format carries no header: sender
//! and receiver both know the element types (checked equal on every rank
//! before a schedule starts) and the pixel count (from the plan), so a
//! receiver can allocate the exact buffer before the message arrives and a
//! message is nothing but the pixels. Values are in the machine's byte order
//! (every rank of one run is the same kind of machine); records travel as
//! one column per field, in field order, as the runtime stores them.

use dpp_runtime::interpret::RunError;
use dpp_runtime::{Column, ColumnView, ElemType, RecordRegistry};
use std::ops::Range;
use std::sync::Arc;

/// Bytes one pixel of all `columns` takes on the wire.
pub fn pixel_bytes(types: &[ElemType], records: &RecordRegistry) -> usize {
    types.iter().map(|ty| ty.bytes(records)).sum()
}

/// Appends `view`'s elements to `out`.
pub fn encode_view(view: &ColumnView<'_>, out: &mut Vec<u8>) {
    match view {
        ColumnView::Bool(v) => out.extend(v.iter().map(|b| u8::from(*b))),
        ColumnView::U32(v) => out.extend_from_slice(bytemuck::cast_slice(v)),
        ColumnView::I32(v) => out.extend_from_slice(bytemuck::cast_slice(v)),
        ColumnView::F32(v) => out.extend_from_slice(bytemuck::cast_slice(v)),
        ColumnView::Vec2(v) => out.extend_from_slice(bytemuck::cast_slice(v)),
        ColumnView::Vec3(v) => out.extend_from_slice(bytemuck::cast_slice(v)),
        ColumnView::Vec4(v) => out.extend_from_slice(bytemuck::cast_slice(v)),
        ColumnView::Record { fields, .. } => fields.iter().for_each(|f| encode_view(f, out)),
    }
}

/// Pixels `range` of every column, one column after the other.
pub fn encode_range(columns: &[Arc<Column>], range: Range<usize>) -> Vec<u8> {
    let mut out = Vec::new();
    for column in columns {
        encode_view(&column.slice(range.clone()), &mut out);
    }
    out
}

/// Decodes `len` elements of `ty` from the front of `bytes`, returning the
/// column and the bytes left.
pub fn decode_column<'b>(
    ty: ElemType,
    len: usize,
    bytes: &'b [u8],
    records: &RecordRegistry,
) -> Result<(Column, &'b [u8]), RunError> {
    let size = ty.bytes(records) * len;
    if bytes.len() < size {
        return Err(RunError::internal(format!(
            "a message holds {} bytes, {len} {} elements need {size}",
            bytes.len(),
            ty.name(records)
        )));
    }
    if let ElemType::Record(id) = ty {
        let mut rest = bytes;
        let mut fields = Vec::new();
        for (_, field) in &records.get(id).fields {
            let (column, left) = decode_column(*field, len, rest, records)?;
            fields.push(Arc::new(column));
            rest = left;
        }
        return Ok((Column::Record { ty: id, fields }, rest));
    }
    let (mine, rest) = bytes.split_at(size);
    // `pod_collect_to_vec` copies, so a message buffer need not be aligned.
    let column = match ty {
        ElemType::Bool => Column::Bool(
            mine.iter()
                .map(|b| match b {
                    0 => Ok(false),
                    1 => Ok(true),
                    other => Err(RunError::internal(format!("a bool on the wire is {other}"))),
                })
                .collect::<Result<_, _>>()?,
        ),
        ElemType::U32 => Column::U32(bytemuck::pod_collect_to_vec(mine)),
        ElemType::I32 => Column::I32(bytemuck::pod_collect_to_vec(mine)),
        ElemType::F32 => Column::F32(bytemuck::pod_collect_to_vec(mine)),
        ElemType::Vec2 => Column::Vec2(bytemuck::pod_collect_to_vec(mine)),
        ElemType::Vec3 => Column::Vec3(bytemuck::pod_collect_to_vec(mine)),
        ElemType::Vec4 => Column::Vec4(bytemuck::pod_collect_to_vec(mine)),
        ElemType::Record(_) => unreachable!("records are handled above"),
    };
    Ok((column, rest))
}

/// Decodes `len` pixels of columns of `types` (what [`encode_range`] made);
/// the bytes must be exactly that many.
pub fn decode(
    types: &[ElemType],
    len: usize,
    bytes: &[u8],
    records: &RecordRegistry,
) -> Result<Vec<Arc<Column>>, RunError> {
    let mut rest = bytes;
    let mut columns = Vec::with_capacity(types.len());
    for ty in types {
        let (column, left) = decode_column(*ty, len, rest, records)?;
        columns.push(Arc::new(column));
        rest = left;
    }
    if !rest.is_empty() {
        return Err(RunError::internal(format!(
            "a message has {} bytes more than its {len} pixels",
            rest.len()
        )));
    }
    Ok(columns)
}

/// Pixels `range` of every column, as new columns.
pub fn slice_columns(columns: &[Arc<Column>], range: Range<usize>) -> Vec<Arc<Column>> {
    if columns.first().is_some_and(|c| range == (0..c.len())) {
        return columns.to_vec();
    }
    columns
        .iter()
        .map(|c| Arc::new(c.slice(range.clone()).to_column()))
        .collect()
}

/// `out[j] = column[indices[j]]`.
pub fn take(view: &ColumnView<'_>, indices: &[usize]) -> Column {
    fn pick<T: Copy>(values: &[T], indices: &[usize]) -> Vec<T> {
        indices.iter().map(|&i| values[i]).collect()
    }
    match view {
        ColumnView::Bool(v) => Column::Bool(pick(v, indices)),
        ColumnView::U32(v) => Column::U32(pick(v, indices)),
        ColumnView::I32(v) => Column::I32(pick(v, indices)),
        ColumnView::F32(v) => Column::F32(pick(v, indices)),
        ColumnView::Vec2(v) => Column::Vec2(pick(v, indices)),
        ColumnView::Vec3(v) => Column::Vec3(pick(v, indices)),
        ColumnView::Vec4(v) => Column::Vec4(pick(v, indices)),
        ColumnView::Record { ty, fields } => Column::Record {
            ty: *ty,
            fields: fields.iter().map(|f| Arc::new(take(f, indices))).collect(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dpp_runtime::RecordType;
    use glam::{Vec2, Vec3, Vec4};

    fn sample() -> (Vec<Arc<Column>>, RecordRegistry) {
        let mut records = RecordRegistry::default();
        let hit = records.register(RecordType {
            name: "Hit".into(),
            fields: vec![("t".into(), ElemType::F32), ("id".into(), ElemType::U32)],
            doc: String::new(),
        });
        let n = 7;
        let f = |i: usize| i as f32 * 1.5 - 2.0;
        let columns = vec![
            Column::Bool((0..n).map(|i| i % 3 == 0).collect()),
            Column::U32((0..n as u32).map(|i| i * 1_000_003).collect()),
            Column::I32((0..n as i32).map(|i| -i * 77).collect()),
            Column::F32((0..n).map(f).collect()),
            Column::Vec2((0..n).map(|i| Vec2::new(f(i), -f(i))).collect()),
            Column::Vec3((0..n).map(|i| Vec3::new(f(i), 2.0, f(i) * f(i))).collect()),
            Column::Vec4((0..n).map(|i| Vec4::splat(f(i))).collect()),
            Column::Record {
                ty: hit,
                fields: vec![
                    Arc::new(Column::F32((0..n).map(f).collect())),
                    Arc::new(Column::U32((0..n as u32).collect())),
                ],
            },
        ];
        (columns.into_iter().map(Arc::new).collect(), records)
    }

    #[test]
    fn every_element_type_round_trips() {
        let (columns, records) = sample();
        let types: Vec<ElemType> = columns.iter().map(|c| c.elem_type()).collect();
        assert_eq!(
            pixel_bytes(&types, &records),
            1 + 4 + 4 + 4 + 8 + 12 + 16 + 8
        );
        for range in [0..7, 2..5, 3..3, 6..7] {
            let bytes = encode_range(&columns, range.clone());
            assert_eq!(bytes.len(), range.len() * pixel_bytes(&types, &records));
            let back = decode(&types, range.len(), &bytes, &records).unwrap();
            assert_eq!(back, slice_columns(&columns, range));
        }
    }

    #[test]
    fn a_message_of_the_wrong_size_is_an_error() {
        let (columns, records) = sample();
        let types: Vec<ElemType> = columns.iter().map(|c| c.elem_type()).collect();
        let mut bytes = encode_range(&columns, 0..4);
        assert!(decode(&types, 5, &bytes, &records).is_err());
        bytes.push(0);
        assert!(decode(&types, 4, &bytes, &records).is_err());
        let mut bools = Vec::new();
        encode_view(&Column::Bool(vec![true]).view(), &mut bools);
        bools[0] = 2;
        assert!(decode(&[ElemType::Bool], 1, &bools, &records).is_err());
    }

    #[test]
    fn take_picks_by_index_through_records() {
        let (columns, _) = sample();
        let picked = take(&columns[7].view(), &[6, 0, 3]);
        assert_eq!(
            picked.field(1).unwrap().as_ref(),
            &Column::U32(vec![6, 0, 3])
        );
    }
}
