//! Arrays on the device: one buffer set per field (structure of arrays, as
//! on the CPU), each field split into segments no longer than the adapter's
//! largest storage binding. Every element of a field is `words` 32-bit words.

use crate::caches::BufferPool;
use crate::device::{GpuContext, GpuError};
use dpp_runtime::column::Column;
use dpp_runtime::types::{ElemType, RecordRegistry};
use glam::{Vec2, Vec3, Vec4};
use std::sync::{Arc, Mutex};

/// One primitive-typed column on the device.
#[derive(Debug)]
pub struct Field {
    pub ty: ElemType,
    pub len: usize,
    /// Elements per segment: every segment but the last holds exactly this many.
    pub segment: usize,
    pub buffers: Vec<wgpu::Buffer>,
    /// Where the buffers go when the field is dropped (`None`: not ours).
    pub(crate) pool: Option<Arc<RunBuffers>>,
}

impl Drop for Field {
    fn drop(&mut self) {
        if let Some(run) = &self.pool {
            let mut released = run.released.lock().unwrap_or_else(|e| e.into_inner());
            released.append(&mut self.buffers);
        }
    }
}

/// The buffers a run's dropped arrays leave. They go to the context's pool
/// when the run's last array is gone: by then every command that used them
/// has been submitted (each stage submits its work before it returns), so
/// the clear of a reused buffer, submitted later, runs after them. Within the
/// run they are not reused: a dropped temporary may be in a command that is
/// still being recorded.
#[derive(Debug)]
pub struct RunBuffers {
    released: Mutex<Vec<wgpu::Buffer>>,
    pool: Arc<BufferPool>,
}

impl RunBuffers {
    pub fn new(gpu: &GpuContext) -> Arc<RunBuffers> {
        Arc::new(RunBuffers {
            released: Mutex::new(Vec::new()),
            pool: gpu.buffer_pool.clone(),
        })
    }
}

impl Drop for RunBuffers {
    fn drop(&mut self) {
        let released = std::mem::take(self.released.get_mut().unwrap_or_else(|e| e.into_inner()));
        self.pool.give(released);
    }
}

impl Field {
    pub fn words(&self) -> usize {
        words_of(self.ty)
    }
}

/// An array on the device. Records are one [`Field`] per record field, shared
/// so that `a.field` is a view, as on the CPU.
#[derive(Clone, Debug)]
pub struct GpuArray {
    pub ty: ElemType,
    pub len: usize,
    pub fields: Vec<Arc<Field>>,
}

/// 32-bit words per element of a primitive type (`bool` is one word, 0 or 1).
pub fn words_of(ty: ElemType) -> usize {
    match ty {
        ElemType::Bool | ElemType::U32 | ElemType::I32 | ElemType::F32 => 1,
        ElemType::Vec2 => 2,
        ElemType::Vec3 => 3,
        ElemType::Vec4 => 4,
        ElemType::Record(_) => unreachable!("record fields are primitive"),
    }
}

/// The primitive types of an element type's fields, in order.
pub fn field_types(ty: ElemType, records: &RecordRegistry) -> Vec<ElemType> {
    match ty {
        ElemType::Record(id) => records.get(id).fields.iter().map(|(_, t)| *t).collect(),
        primitive => vec![primitive],
    }
}

const USAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_SRC)
    .union(wgpu::BufferUsages::COPY_DST);

/// A zeroed field of `len` elements (wgpu zero-initialises new buffers; a
/// buffer from the pool is cleared before anything submitted later runs),
/// whose buffers return to the pool through `run`.
pub fn allocate_field(
    gpu: &GpuContext,
    ty: ElemType,
    len: usize,
    run: Option<&Arc<RunBuffers>>,
) -> Result<Field, GpuError> {
    let words = words_of(ty);
    let element_bytes = 4 * words as u64;
    let segment = (gpu.limits.max_binding_bytes / element_bytes).max(1) as usize;
    let segments = len.div_ceil(segment).max(1);
    let mut buffers = Vec::with_capacity(segments);
    for s in 0..segments {
        let elements = (len - (s * segment).min(len)).min(segment);
        // A binding may not be empty: an empty array still has one word.
        let bytes = (elements as u64 * element_bytes).max(4);
        if bytes > gpu.limits.max_buffer_bytes {
            return Err(GpuError::resource_limit(format!(
                "an array segment of {bytes} bytes is above the adapter `{}`'s max_buffer_size of {} bytes",
                gpu.adapter_name(),
                gpu.limits.max_buffer_bytes
            )));
        }
        buffers.push(match gpu.buffer_pool.take(bytes) {
            Some(buffer) => {
                let mut encoder = gpu.device.create_command_encoder(&Default::default());
                encoder.clear_buffer(&buffer, 0, None);
                gpu.queue.submit([encoder.finish()]);
                buffer
            }
            None => gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size: bytes,
                usage: USAGE,
                mapped_at_creation: false,
            }),
        });
    }
    Ok(Field {
        ty,
        len,
        segment,
        buffers,
        pool: run.cloned(),
    })
}

pub fn allocate_array(
    gpu: &GpuContext,
    ty: ElemType,
    len: usize,
    records: &RecordRegistry,
    run: &Arc<RunBuffers>,
) -> Result<GpuArray, GpuError> {
    let fields = field_types(ty, records)
        .into_iter()
        .map(|t| allocate_field(gpu, t, len, Some(run)).map(Arc::new))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(GpuArray { ty, len, fields })
}

/// Copies of every buffer of `array`, for `scatter(…, into: dst)`.
pub fn copy_array(
    gpu: &GpuContext,
    encoder: &mut wgpu::CommandEncoder,
    array: &GpuArray,
    run: &Arc<RunBuffers>,
) -> Result<GpuArray, GpuError> {
    let mut fields = Vec::new();
    for field in &array.fields {
        let copy = allocate_field(gpu, field.ty, field.len, Some(run))?;
        for (from, to) in field.buffers.iter().zip(&copy.buffers) {
            encoder.copy_buffer_to_buffer(from, 0, to, 0, from.size());
        }
        fields.push(Arc::new(copy));
    }
    Ok(GpuArray {
        ty: array.ty,
        len: array.len,
        fields,
    })
}

/// Reads every word of `field` back (waits for the device).
pub fn download_words(gpu: &GpuContext, field: &Field) -> Result<Vec<u32>, GpuError> {
    let ElemType::U32 = field.ty else {
        return Err(GpuError::internal("read back as words: not a u32 field"));
    };
    match download_field(gpu, field)? {
        Column::U32(words) => Ok(words),
        _ => unreachable!("a u32 field reads back as u32s"),
    }
}

/// Bytes per read-back buffer. A driver may place a large read-back buffer
/// in slower host memory: on an H100 a 24 MB one read back at 1.4 GB/s,
/// 8 MB ones at 7 GB/s.
const READ_BACK_PIECE_BYTES: u64 = 4 << 20;

/// The field as a host column (waits for the device): copied in pieces of
/// whole elements to read-back buffers, and converted piece by piece.
fn download_field(gpu: &GpuContext, field: &Field) -> Result<Column, GpuError> {
    let element_bytes = 4 * field.words() as u64;
    let piece_bytes = (READ_BACK_PIECE_BYTES / element_bytes).max(1) * element_bytes;
    let segment_bytes = field.segment as u64 * element_bytes;
    let mut left = field.len as u64 * element_bytes;
    let mut encoder = gpu.device.create_command_encoder(&Default::default());
    let mut staging = Vec::new();
    for buffer in &field.buffers {
        let mut offset = 0;
        while offset < segment_bytes.min(buffer.size()) && left > 0 {
            let size = piece_bytes.min(left).min(buffer.size() - offset);
            let piece = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("dpp read-back"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            encoder.copy_buffer_to_buffer(buffer, offset, &piece, 0, size);
            staging.push(piece);
            offset += size;
            left -= size;
        }
    }
    gpu.queue.submit([encoder.finish()]);
    for buffer in &staging {
        buffer.slice(..).map_async(wgpu::MapMode::Read, |_| {});
    }
    wait(gpu)?;
    let mut column = Column::with_capacity(field.ty, field.len, &RecordRegistry::default());
    for buffer in &staging {
        let view = buffer
            .slice(..)
            .get_mapped_range()
            .map_err(|e| GpuError::device(format!("reading a GPU buffer back failed: {e}")))?;
        extend_from_words(&mut column, bytemuck::cast_slice(&view));
        drop(view);
        buffer.unmap();
    }
    Ok(column)
}

/// Blocks until the device has finished everything submitted.
pub fn wait(gpu: &GpuContext) -> Result<(), GpuError> {
    gpu.device
        .poll(wgpu::PollType::Wait {
            submission_index: None,
            timeout: None,
        })
        .map(|_| ())
        .map_err(|e| GpuError::device(format!("waiting for the GPU failed: {e}")))
}

/// The array as a host column.
pub fn download(
    gpu: &GpuContext,
    array: &GpuArray,
    records: &RecordRegistry,
) -> Result<Column, GpuError> {
    let columns = array
        .fields
        .iter()
        .map(|field| download_field(gpu, field))
        .collect::<Result<Vec<Column>, GpuError>>()?;
    Ok(match array.ty {
        ElemType::Record(ty) => {
            let _ = records;
            Column::Record {
                ty,
                fields: columns.into_iter().map(Arc::new).collect(),
            }
        }
        _ => columns
            .into_iter()
            .next()
            .expect("a primitive array has one field"),
    })
}

/// Appends the elements stored in `words` (whole elements) to `column`.
fn extend_from_words(column: &mut Column, words: &[u32]) {
    let float = |w: &u32| f32::from_bits(*w);
    match column {
        Column::Bool(v) => v.extend(words.iter().map(|w| *w != 0)),
        Column::U32(v) => v.extend_from_slice(words),
        Column::I32(v) => v.extend(words.iter().map(|w| *w as i32)),
        Column::F32(v) => v.extend(words.iter().map(float)),
        Column::Vec2(v) => v.extend(
            words
                .chunks_exact(2)
                .map(|c| Vec2::new(float(&c[0]), float(&c[1]))),
        ),
        Column::Vec3(v) => v.extend(
            words
                .chunks_exact(3)
                .map(|c| Vec3::new(float(&c[0]), float(&c[1]), float(&c[2]))),
        ),
        Column::Vec4(v) => v.extend(
            words
                .chunks_exact(4)
                .map(|c| Vec4::new(float(&c[0]), float(&c[1]), float(&c[2]), float(&c[3]))),
        ),
        Column::Record { .. } => unreachable!("record fields are primitive"),
    }
}

/// The column's words, as a field of its type stores them.
pub(crate) fn column_words(column: &Column) -> Vec<u32> {
    match column {
        Column::Bool(v) => v.iter().map(|b| u32::from(*b)).collect(),
        Column::U32(v) => v.clone(),
        Column::I32(v) => v.iter().map(|x| *x as u32).collect(),
        Column::F32(v) => v.iter().map(|x| x.to_bits()).collect(),
        Column::Vec2(v) => v
            .iter()
            .flat_map(|x| x.to_array())
            .map(f32::to_bits)
            .collect(),
        Column::Vec3(v) => v
            .iter()
            .flat_map(|x| x.to_array())
            .map(f32::to_bits)
            .collect(),
        Column::Vec4(v) => v
            .iter()
            .flat_map(|x| x.to_array())
            .map(f32::to_bits)
            .collect(),
        Column::Record { .. } => unreachable!("record fields are primitive"),
    }
}

/// A host column on the device (tests and `dpp` hand the GPU arrays this way).
pub fn upload(gpu: &GpuContext, column: &Column) -> Result<GpuArray, GpuError> {
    let ty = column.elem_type();
    let len = column.len();
    let parts: Vec<&Column> = match column {
        Column::Record { fields, .. } => fields.iter().map(|f| f.as_ref()).collect(),
        primitive => vec![primitive],
    };
    let mut fields = Vec::new();
    for part in parts {
        let field = allocate_field(gpu, part.elem_type(), len, None)?;
        let words = column_words(part);
        let per_segment = field.segment * field.words();
        for (s, buffer) in field.buffers.iter().enumerate() {
            let start = (s * per_segment).min(words.len());
            let end = (start + per_segment).min(words.len());
            if end > start {
                gpu.queue
                    .write_buffer(buffer, 0, bytemuck::cast_slice(&words[start..end]));
            }
        }
        fields.push(Arc::new(field));
    }
    Ok(GpuArray { ty, len, fields })
}
