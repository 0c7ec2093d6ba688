//! Building one compute shader: its bindings (array fields, scene buffers,
//! parameters, status), the typed accessors generated for them, and the
//! parameter words it reads. Stage kernels and the sink kernels both use it.

use crate::array::{Field, GpuArray};
use dpp_runtime::host::HostValue;
use dpp_runtime::types::{ElemType, RecordRegistry};
use dpp_runtime::wgsl::elem_type_wgsl;
use std::fmt::Write;
use std::sync::Arc;

/// Invocations per workgroup of every kernel.
pub const WORKGROUP: u32 = 64;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    Read,
    ReadWrite,
    /// Read-write through atomics (combining scatters).
    Atomic,
}

#[derive(Clone, Debug)]
pub struct Binding {
    /// `None` for binding 0, the kernel's parameter words, which exist only
    /// once the kernel is dispatched.
    pub buffer: Option<wgpu::Buffer>,
    pub read_only: bool,
}

/// A shader under construction.
pub struct ShaderBuilder<'r> {
    pub records: &'r RecordRegistry,
    pub bindings: Vec<Binding>,
    /// Binding declarations and generated accessors.
    pub declarations: String,
    /// Everything else before `main` (twins, modules).
    pub functions: String,
    /// The body of `main` after `i` is known to be in range.
    pub body: String,
    pub params: Vec<u32>,
    fields: Vec<(Arc<Field>, Access, String)>,
    next_local: usize,
}

impl<'r> ShaderBuilder<'r> {
    /// A shader whose first three bindings are the parameter words (bound at
    /// dispatch), the run's status and uniforms.
    pub fn new(
        records: &'r RecordRegistry,
        status: &wgpu::Buffer,
        uniforms: &wgpu::Buffer,
    ) -> ShaderBuilder<'r> {
        let mut declarations = String::new();
        declarations.push_str(
            "@group(0) @binding(0) var<storage, read> params: array<u32>;\n\
             @group(0) @binding(1) var<storage, read_write> status: array<atomic<u32>>;\n\
             @group(0) @binding(2) var<storage, read> uniforms: array<u32>;\n\
             fn dpp_fail(code: u32, a: u32, b: u32) {\n\
             \x20   if (atomicCompareExchangeWeak(&status[0], 0u, code).exchanged) {\n\
             \x20       atomicStore(&status[1], a);\n\
             \x20       atomicStore(&status[2], b);\n\
             \x20   }\n\
             }\n",
        );
        ShaderBuilder {
            records,
            bindings: vec![
                Binding {
                    buffer: None,
                    read_only: true,
                },
                Binding {
                    buffer: Some(status.clone()),
                    read_only: false,
                },
                Binding {
                    buffer: Some(uniforms.clone()),
                    read_only: true,
                },
            ],
            declarations,
            functions: String::new(),
            body: String::new(),
            params: vec![0, 0],
            fields: Vec::new(),
            next_local: 0,
        }
    }

    /// A fresh local name.
    pub fn local(&mut self) -> String {
        self.next_local += 1;
        format!("v{}", self.next_local)
    }

    /// Binds a raw buffer (scene data) under `name` with WGSL type `wgsl_type`.
    pub fn bind_named(&mut self, name: &str, wgsl_type: &str, buffer: wgpu::Buffer) {
        let binding = self.bindings.len();
        let _ = writeln!(
            self.declarations,
            "@group(0) @binding({binding}) var<storage, read> {name}: {wgsl_type};"
        );
        self.bindings.push(Binding {
            buffer: Some(buffer),
            read_only: true,
        });
    }

    /// A parameter word the kernel reads (`params[k]`), set now.
    pub fn param_u32(&mut self, value: u32) -> String {
        self.params.push(value);
        format!("params[{}]", self.params.len() - 1)
    }

    /// A host value as a WGSL expression of its WGSL type. Integers travel as
    /// 32 bits (`i32`; values up to 2^32 - 1 keep their bits, so a `u32`
    /// reading of them is exact); a wider one is an error, not a wrapped value.
    pub fn param_host(&mut self, value: HostValue) -> Result<String, String> {
        Ok(match value {
            HostValue::Bool(b) => format!("({} != 0u)", self.param_u32(u32::from(b))),
            HostValue::Int(n) => {
                if !(i64::from(i32::MIN)..=i64::from(u32::MAX)).contains(&n) {
                    return Err(format!(
                        "{n} does not fit in the 32 bits the GPU backend passes integers in"
                    ));
                }
                format!("bitcast<i32>({})", self.param_u32(n as u32))
            }
            HostValue::Float(x) => {
                format!("bitcast<f32>({})", self.param_u32((x as f32).to_bits()))
            }
            HostValue::Vec2(v) => self.param_floats("vec2<f32>", &v),
            HostValue::Vec3(v) => self.param_floats("vec3<f32>", &v),
            HostValue::Vec4(v) => self.param_floats("vec4<f32>", &v),
        })
    }

    /// A `fill`'s value as its array element, converted as the CPU converts it.
    pub fn param_element(&mut self, value: HostValue) -> Result<String, String> {
        let column = dpp_runtime::column::Column::filled(value, 1)?;
        let words: Vec<String> = crate::array::column_words(&column)
            .into_iter()
            .map(|w| self.param_u32(w))
            .collect();
        Ok(words_to_value(column.elem_type(), &|j| words[j].clone()))
    }

    fn param_floats(&mut self, ty: &str, values: &[f32]) -> String {
        let parts: Vec<String> = values
            .iter()
            .map(|x| format!("bitcast<f32>({})", self.param_u32(x.to_bits())))
            .collect();
        format!("{ty}({})", parts.join(", "))
    }

    /// Binds `field` (once per access) and returns its accessor prefix `fN`:
    /// `fN_load(i) -> T`, and `fN_store(i, v)` for read-write fields.
    pub fn field(&mut self, field: &Arc<Field>, access: Access) -> String {
        if let Some((_, _, name)) = self
            .fields
            .iter()
            .find(|(f, a, _)| Arc::ptr_eq(f, field) && *a == access)
        {
            return name.clone();
        }
        let name = format!("f{}", self.fields.len());
        self.fields.push((field.clone(), access, name.clone()));
        let words = field.words();
        let (storage, element) = match access {
            Access::Read => ("read", "u32"),
            Access::ReadWrite => ("read_write", "u32"),
            Access::Atomic => ("read_write", "atomic<u32>"),
        };
        for (s, buffer) in field.buffers.iter().enumerate() {
            let binding = self.bindings.len();
            let _ = writeln!(
                self.declarations,
                "@group(0) @binding({binding}) var<storage, {storage}> {name}_{s}: array<{element}>;"
            );
            self.bindings.push(Binding {
                buffer: Some(buffer.clone()),
                read_only: access == Access::Read,
            });
        }
        let segments = field.buffers.len();
        let segment = field.segment;
        // Word `j` of element `i`: segment `i / segment`, then its own offset.
        let dispatch = |body: &dyn Fn(usize) -> String| -> String {
            if segments == 1 {
                return body(0);
            }
            let mut text = format!(
                "let s = i / {segment}u;\n    let l = i - s * {segment}u;\n    switch s {{\n"
            );
            for s in 0..segments {
                let label = if s + 1 == segments {
                    "default".to_string()
                } else {
                    format!("case {s}u")
                };
                let _ = writeln!(text, "        {label}: {{ {} }}", body(s));
            }
            text.push_str("    }");
            text
        };
        let index = if segments == 1 { "i" } else { "l" };
        let ty = elem_type_wgsl(field.ty, self.records);
        match access {
            Access::Read | Access::ReadWrite => {
                let load_word =
                    dispatch(&|s| format!("return {name}_{s}[{index} * {words}u + j];"));
                let _ = writeln!(
                    self.declarations,
                    "fn {name}_word(i: u32, j: u32) -> u32 {{\n    {load_word}\n}}"
                );
                let _ = writeln!(
                    self.declarations,
                    "fn {name}_load(i: u32) -> {ty} {{ return {}; }}",
                    words_to_value(field.ty, &|j| format!("{name}_word(i, {j}u)"))
                );
                if access == Access::ReadWrite {
                    let store_word =
                        dispatch(&|s| format!("{name}_{s}[{index} * {words}u + j] = w; return;"));
                    let _ = writeln!(
                        self.declarations,
                        "fn {name}_word_store(i: u32, j: u32, w: u32) {{\n    {store_word}\n}}"
                    );
                    let mut store = format!("fn {name}_store(i: u32, v: {ty}) {{\n");
                    for (j, word) in value_to_words(field.ty, "v").iter().enumerate() {
                        let _ = writeln!(store, "    {name}_word_store(i, {j}u, {word});");
                    }
                    store.push_str("}\n");
                    self.declarations.push_str(&store);
                }
            }
            Access::Atomic => {
                // `fN_update(i, j, value, op)` is generated by the caller per
                // monoid; here only the pointer dispatch, as a CAS helper.
                let cas = dispatch(&|s| {
                    format!("let r = atomicCompareExchangeWeak(&{name}_{s}[{index} * {words}u + j], old, replacement); return vec2<u32>(r.old_value, select(0u, 1u, r.exchanged));")
                });
                let _ = writeln!(
                    self.declarations,
                    "fn {name}_cas(i: u32, j: u32, old: u32, replacement: u32) -> vec2<u32> {{\n    {cas}\n}}"
                );
                let load = dispatch(&|s| {
                    format!("return atomicLoad(&{name}_{s}[{index} * {words}u + j]);")
                });
                let _ = writeln!(
                    self.declarations,
                    "fn {name}_atomic_load(i: u32, j: u32) -> u32 {{\n    {load}\n}}"
                );
            }
        }
        name
    }

    /// Binds every field of `array` for reading and returns a function name
    /// `aN_load(i) -> T` that loads whole elements (records as structs).
    pub fn array_loader(&mut self, array: &GpuArray) -> String {
        let names: Vec<String> = array
            .fields
            .iter()
            .map(|f| self.field(f, Access::Read))
            .collect();
        if let [single] = names.as_slice() {
            if !matches!(array.ty, ElemType::Record(_)) {
                return format!("{single}_load");
            }
        }
        let function = format!("{}_record_load", names.join("_"));
        if !self.declarations.contains(&format!("fn {function}(")) {
            let ty = elem_type_wgsl(array.ty, self.records);
            let parts: Vec<String> = names.iter().map(|n| format!("{n}_load(i)")).collect();
            let _ = writeln!(
                self.declarations,
                "fn {function}(i: u32) -> {ty} {{ return {ty}({}); }}",
                parts.join(", ")
            );
        }
        function
    }

    /// Binds every field of a freshly allocated `array` for writing and returns
    /// the WGSL statements that store value `value` at index `index`.
    pub fn array_store(&mut self, array: &GpuArray, index: &str, value: &str) -> String {
        let names: Vec<String> = array
            .fields
            .iter()
            .map(|f| self.field(f, Access::ReadWrite))
            .collect();
        match array.ty {
            ElemType::Record(id) => {
                let record = self.records.get(id);
                names
                    .iter()
                    .zip(&record.fields)
                    .map(|(n, (field, _))| format!("{n}_store({index}, {value}.{field});\n"))
                    .collect()
            }
            _ => format!("{}_store({index}, {value});\n", names[0]),
        }
    }

    /// The whole shader: declarations, functions and `main` over `i < params[1]`
    /// (params[0] is the number of workgroups along x of a 2-D dispatch).
    pub fn finish(&self) -> String {
        format!(
            "{}\n{}\n@compute @workgroup_size({WORKGROUP})\n\
             fn main(@builtin(workgroup_id) workgroup: vec3<u32>, @builtin(local_invocation_index) lane_in_group: u32) {{\n\
             \x20   let i = (workgroup.y * params[0] + workgroup.x) * {WORKGROUP}u + lane_in_group;\n\
             \x20   if (i >= params[1]) {{ return; }}\n{}}}\n",
            self.declarations, self.functions, self.body
        )
    }
}

/// A WGSL expression of type `ty` from its words, `word(j)` giving word `j`
/// as a `u32` expression.
pub fn words_to_value(ty: ElemType, word: &dyn Fn(usize) -> String) -> String {
    let float = |j: usize| format!("bitcast<f32>({})", word(j));
    match ty {
        ElemType::Bool => format!("({} != 0u)", word(0)),
        ElemType::U32 => word(0),
        ElemType::I32 => format!("bitcast<i32>({})", word(0)),
        ElemType::F32 => float(0),
        ElemType::Vec2 => format!("vec2<f32>({}, {})", float(0), float(1)),
        ElemType::Vec3 => format!("vec3<f32>({}, {}, {})", float(0), float(1), float(2)),
        ElemType::Vec4 => format!(
            "vec4<f32>({}, {}, {}, {})",
            float(0),
            float(1),
            float(2),
            float(3)
        ),
        ElemType::Record(_) => unreachable!("record fields are primitive"),
    }
}

/// The words of a value `value` of primitive type `ty`, as WGSL `u32` expressions.
pub fn value_to_words(ty: ElemType, value: &str) -> Vec<String> {
    const COMPONENTS: [&str; 4] = ["x", "y", "z", "w"];
    match ty {
        ElemType::Bool => vec![format!("select(0u, 1u, {value})")],
        ElemType::U32 => vec![value.to_string()],
        ElemType::I32 | ElemType::F32 => vec![format!("bitcast<u32>({value})")],
        ElemType::Vec2 | ElemType::Vec3 | ElemType::Vec4 => COMPONENTS
            [..crate::array::words_of(ty)]
            .iter()
            .map(|c| format!("bitcast<u32>({value}.{c})"))
            .collect(),
        ElemType::Record(_) => unreachable!("record fields are primitive"),
    }
}
