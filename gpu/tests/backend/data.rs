//! Test input for both backends: columns handed to `…Data` functors, which
//! read them on the CPU from the run's resources and on the GPU from scene
//! buffers, so a pipeline's inputs need no upload path of their own.

use dpp_runtime::wgsl::{GpuBuffer, WgslRequest, WgslTwin};
use dpp_runtime::*;
use std::sync::Arc;

/// The test's input columns, handed to the `…Data` functors (see
/// [`register_data_functor`]) as run resources, and as words for their GPU
/// twin: one `array<u32>` buffer per primitive column, per field of a record
/// column (vectors take one word per component).
pub struct Data {
    pub columns: Vec<Column>,
    buffers: Vec<GpuBuffer>,
    /// Index in `buffers` of each column's first buffer.
    first_buffer: Vec<usize>,
}

const DATA_NAMES: [&str; 16] = [
    "data0", "data1", "data2", "data3", "data4", "data5", "data6", "data7", "data8", "data9",
    "data10", "data11", "data12", "data13", "data14", "data15",
];

impl Data {
    pub fn new(columns: Vec<Column>) -> Data {
        fn words(column: &Column, out: &mut Vec<Vec<u32>>) {
            let floats = |v: &mut dyn Iterator<Item = f32>| v.map(f32::to_bits).collect();
            out.push(match column {
                Column::Bool(v) => v.iter().map(|b| u32::from(*b)).collect(),
                Column::U32(v) => v.clone(),
                Column::I32(v) => v.iter().map(|x| *x as u32).collect(),
                Column::F32(v) => floats(&mut v.iter().copied()),
                Column::Vec2(v) => floats(&mut v.iter().flat_map(|x| x.to_array())),
                Column::Vec3(v) => floats(&mut v.iter().flat_map(|x| x.to_array())),
                Column::Vec4(v) => floats(&mut v.iter().flat_map(|x| x.to_array())),
                Column::Record { fields, .. } => {
                    fields.iter().for_each(|field| words(field, out));
                    return;
                }
            });
        }
        let mut all_words = Vec::new();
        let mut first_buffer = Vec::new();
        for column in &columns {
            first_buffer.push(all_words.len());
            words(column, &mut all_words);
        }
        assert!(all_words.len() <= DATA_NAMES.len(), "too many test buffers");
        let buffers = all_words
            .into_iter()
            .zip(DATA_NAMES)
            .map(|(words, name)| GpuBuffer {
                name,
                wgsl_type: "array<u32>",
                data: words.into(),
            })
            .collect();
        Data {
            columns,
            buffers,
            first_buffer,
        }
    }
}

/// `{name}(index, column: c)`: element `index` of input column `c` of the
/// run's [`Data`], whose type must be `ty`.
struct DataFunctor {
    signature: Signature,
}

/// A WGSL expression for element `index` of a column of type `ty` stored in
/// `buffers` (consumed in order, a record's fields one after another).
fn read_data_wgsl<'a>(
    ty: ElemType,
    records: &RecordRegistry,
    buffers: &mut impl Iterator<Item = &'a GpuBuffer>,
) -> String {
    let components = |n: usize, buffer: &str| -> String {
        let words: Vec<String> = (0..n)
            .map(|j| format!("bitcast<f32>({buffer}[{n}u * index + {j}u])"))
            .collect();
        format!("vec{n}<f32>({})", words.join(", "))
    };
    if let ElemType::Record(id) = ty {
        let record = records.get(id);
        let fields: Vec<String> = record
            .fields
            .iter()
            .map(|(_, field)| read_data_wgsl(*field, records, buffers))
            .collect();
        return format!("{}({})", record.name, fields.join(", "));
    }
    let buffer = buffers.next().expect("a buffer per field").name;
    match ty {
        ElemType::Bool => format!("{buffer}[index] != 0u"),
        ElemType::U32 => format!("{buffer}[index]"),
        ElemType::I32 => format!("bitcast<i32>({buffer}[index])"),
        ElemType::F32 => format!("bitcast<f32>({buffer}[index])"),
        ElemType::Vec2 => components(2, buffer),
        ElemType::Vec3 => components(3, buffer),
        ElemType::Vec4 => components(4, buffer),
        ElemType::Record(_) => unreachable!(),
    }
}

impl Functor for DataFunctor {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    fn run_cpu(
        &self,
        ctx: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError> {
        let data = ctx.resources::<Data>()?;
        let column = &data.columns[ctx.named(0).as_int().unwrap() as usize];
        let indices = inputs[0].as_u32();
        outputs[0] = dpp_runtime::cpu::kernels::gather(indices, &column.view())
            .map_err(|e| FunctorError::bad_input(e.to_string()))?;
        Ok(())
    }

    /// The columns of the output's type are scene buffers; `column` picks one.
    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        let data = request
            .resources
            .downcast_ref::<Data>()
            .ok_or_else(|| FunctorError::bad_input("no test data"))?;
        let function = request.function;
        let ty = request.outputs[0];
        let wgsl = dpp_runtime::wgsl::elem_type_wgsl(ty, request.records);
        let mut source =
            format!("fn {function}(element: u32, index: u32, column: i32) -> {wgsl} {{\n    switch column {{\n");
        let mut buffers = Vec::new();
        for (c, column) in data.columns.iter().enumerate() {
            if column.elem_type() != ty {
                continue;
            }
            let mut leaves = data.buffers[data.first_buffer[c]..].iter();
            let value = read_data_wgsl(ty, request.records, &mut leaves);
            let used = data.buffers.len() - data.first_buffer[c] - leaves.len();
            buffers.extend_from_slice(&data.buffers[data.first_buffer[c]..][..used]);
            source.push_str(&format!("        case {c}: {{ return {value}; }}\n"));
        }
        source.push_str(&format!(
            "        default: {{}}\n    }}\n    return {wgsl}();\n}}\n"
        ));
        Ok(WgslTwin {
            source,
            buffers,
            ..Default::default()
        })
    }
}

/// Registers `{name}(index: u32, column: int) -> ty`, which reads the run's [`Data`].
pub fn register_data_functor(library: &mut FunctorLibrary, name: &'static str, ty: ElemType) {
    library.register(Arc::new(DataFunctor {
        signature: Signature::map(name)
            .input("index", ElemType::U32)
            .output("value", ty)
            .named("column", HostType::Int, None, "input column")
            .doc("test input"),
    }));
}
