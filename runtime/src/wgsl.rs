//! The contract between functors and the GPU backend: how a functor's WGSL
//! twin is asked for, what it must define, and what the backend provides
//! around it. One shader per stage is made by pasting the stage's twins (and
//! the modules they share) behind a prelude the backend generates.
//!
//! # Calling conventions
//!
//! A twin defines one function named [`WgslRequest::function`] (any helper it
//! needs is named `{function}_…` or lives in a shared [`WgslModule`]). Named
//! arguments always come last, in signature order, typed by [`host_type_wgsl`]
//! (`int` is `i32`, `float` is `f32`), named as in the signature or, where the
//! convention has taken the name, `arg_{name}` ([`named_parameter_wgsl`]).
//! Array values are typed by [`elem_type_wgsl`]: `bool`, `u32`, `i32`, `f32`, `vec2<f32>`, `vec3<f32>`,
//! `vec4<f32>`, and records as structs of the same name and fields (`Ray`).
//!
//! - `Map`: `fn F(index: u32, in0: T0, …, named…) -> Out` — `index` is the
//!   element's position in the stage's index space.
//! - `Group` (`gather<F>(src, group: k)`): `fn F(first: u32, k: u32, named…) -> Out`;
//!   element `first + j` of the source is read with `F_src(first + j)`, which the
//!   backend defines.
//! - `Expand` (`scatter<F>(src, fanout: k)`): `fn F(source_index: u32, src: T,
//!   lane: u32, k: u32, named…) -> Out` for output `source_index * k + lane`.
//! - `Monoid`: `fn F(a: T, b: T) -> T`. Reductions, scans and combining
//!   scatters use the backend's own kernels for the [`MonoidOp`](crate::MonoidOp).
//!
//! Only single-output functors have twins.
//!
//! # What the backend provides
//!
//! - a struct per record type of the library (fields in registry order);
//! - `fn uniform_{record}_{field}() -> T` for every uniform of the schema
//!   (`uniform_camera_width() -> i32`, `uniform_scene_diagonal() -> f32`);
//! - every [`GpuBuffer`] a twin lists, as `var<storage, read> {name}: {wgsl_type};`
//!   (shared by name across the twins of a shader, uploaded once per run);
//! - `fn {function}_fail(code: u32)`: records run-time failure `code` (an index
//!   into [`WgslTwin::failures`]); the run then fails with that message.
//!
//! The GPU crate's `check_twin` compiles a twin with such a prelude (naga), so
//! that a functor's tests can check its twin without a GPU.

use crate::elem::Element;
use crate::signature::{FunctorKind, Signature};
use crate::types::{ElemType, HostType, RecordRegistry};
use std::any::Any;
use std::borrow::Cow;
use std::fmt::Write;
use std::sync::Arc;

/// What the GPU backend asks of a functor: its twin for one instantiation.
pub struct WgslRequest<'a> {
    /// The name the twin's function must have (unique per instantiation).
    pub function: &'a str,
    /// The input element types, type variables bound.
    pub inputs: &'a [ElemType],
    pub outputs: &'a [ElemType],
    pub records: &'a RecordRegistry,
    /// The run's scene data, as [`CallContext::resources`](crate::CallContext).
    pub resources: &'a (dyn Any + Send + Sync),
}

/// WGSL source shared by several twins, included once per shader.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WgslModule {
    /// Unique across the library (`tracer_random`, `tracer_bvh`).
    pub name: &'static str,
    pub source: Cow<'static, str>,
    /// Buffers the module reads (declared once, like a twin's).
    pub buffers: Vec<GpuBuffer>,
}

/// A read-only storage buffer of scene data.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GpuBuffer {
    /// The WGSL variable name (`bvh_nodes`); the same name must mean the same data.
    pub name: &'static str,
    /// Its WGSL type, a runtime-sized array (`array<vec4<f32>>`, `array<u32>`).
    pub wgsl_type: &'static str,
    /// The contents as 32-bit words. Shared so that a backend uploads it once
    /// while the same `Arc` is handed back.
    pub data: Arc<[u32]>,
}

/// A functor's WGSL twin for one instantiation.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct WgslTwin {
    /// Defines `fn {function}` (see the module documentation).
    pub source: String,
    pub modules: Vec<WgslModule>,
    pub buffers: Vec<GpuBuffer>,
    /// Messages of the failures the twin may raise with `{function}_fail(code)`.
    pub failures: Vec<String>,
}

/// The WGSL type of a primitive element (`vec3<f32>`); `None` for a record.
pub fn primitive_type_wgsl(ty: ElemType) -> Option<&'static str> {
    Some(match ty {
        ElemType::Bool => "bool",
        ElemType::U32 => "u32",
        ElemType::I32 => "i32",
        ElemType::F32 => "f32",
        ElemType::Vec2 => "vec2<f32>",
        ElemType::Vec3 => "vec3<f32>",
        ElemType::Vec4 => "vec4<f32>",
        ElemType::Record(_) => return None,
    })
}

/// The WGSL type of an array element inside functions.
pub fn elem_type_wgsl(ty: ElemType, records: &RecordRegistry) -> String {
    match (ty, primitive_type_wgsl(ty)) {
        (_, Some(primitive)) => primitive.into(),
        (ElemType::Record(id), None) => records.get(id).name.clone(),
        (_, None) => unreachable!("every non-record type is primitive"),
    }
}

/// `element` as a WGSL expression of its type, exact to the bit (floats are
/// spelled by their bits, so infinities and `-0.0` survive).
pub fn element_wgsl(element: Element) -> String {
    let float = |x: f32| format!("bitcast<f32>({:#010x}u)", x.to_bits());
    let vector = |ty: ElemType, components: &[f32]| {
        let parts: Vec<String> = components.iter().map(|&x| float(x)).collect();
        format!(
            "{}({})",
            primitive_type_wgsl(ty).unwrap_or_default(),
            parts.join(", ")
        )
    };
    match element {
        Element::Bool(value) => value.to_string(),
        Element::U32(value) => format!("{value}u"),
        Element::I32(value) => format!("bitcast<i32>({:#010x}u)", value as u32),
        Element::F32(value) => float(value),
        Element::Vec2(value) => vector(ElemType::Vec2, &value.to_array()),
        Element::Vec3(value) => vector(ElemType::Vec3, &value.to_array()),
        Element::Vec4(value) => vector(ElemType::Vec4, &value.to_array()),
    }
}

/// The WGSL type of a named argument or uniform.
pub fn host_type_wgsl(ty: HostType) -> &'static str {
    match ty {
        HostType::Bool => "bool",
        HostType::Int => "i32",
        HostType::Float => "f32",
        HostType::Vec2 => "vec2<f32>",
        HostType::Vec3 => "vec3<f32>",
        HostType::Vec4 => "vec4<f32>",
    }
}

/// `struct Ray { origin: vec3<f32>, … }` for every record type.
pub fn record_structs(records: &RecordRegistry) -> String {
    let mut text = String::new();
    for (_, record) in records.iter() {
        let _ = writeln!(text, "struct {} {{", record.name);
        for (name, ty) in &record.fields {
            let _ = writeln!(text, "    {name}: {},", elem_type_wgsl(*ty, records));
        }
        text.push_str("}\n");
    }
    text
}

/// Adds `modules` and `buffers` to the lists a shader collects, skipping names
/// already there (the same name is the same module or data).
pub fn collect_dependencies(
    twin: &WgslTwin,
    modules: &mut Vec<WgslModule>,
    buffers: &mut Vec<GpuBuffer>,
) {
    for module in &twin.modules {
        for buffer in &module.buffers {
            if !buffers.iter().any(|b| b.name == buffer.name) {
                buffers.push(buffer.clone());
            }
        }
        if !modules.iter().any(|m| m.name == module.name) {
            modules.push(module.clone());
        }
    }
    for buffer in &twin.buffers {
        if !buffers.iter().any(|b| b.name == buffer.name) {
            buffers.push(buffer.clone());
        }
    }
}

/// The parameter list of a twin's function, for the backend and its twin checker:
/// `(name, wgsl type)` pairs in calling order.
pub fn twin_parameters(
    signature: &Signature,
    inputs: &[ElemType],
    records: &RecordRegistry,
) -> Vec<(String, String)> {
    let mut params: Vec<(String, String)> = Vec::new();
    let value = |i: usize| elem_type_wgsl(inputs[i], records);
    match signature.kind {
        FunctorKind::Map => {
            params.push(("index".into(), "u32".into()));
            for (i, p) in signature.inputs.iter().enumerate() {
                params.push((p.name.to_string(), value(i)));
            }
        }
        FunctorKind::Group => {
            params.push(("first".into(), "u32".into()));
            params.push(("k".into(), "u32".into()));
        }
        FunctorKind::Expand => {
            params.push(("source_index".into(), "u32".into()));
            params.push(("src".into(), value(0)));
            params.push(("lane".into(), "u32".into()));
            params.push(("k".into(), "u32".into()));
        }
        FunctorKind::Monoid(_) => {
            params.push(("a".into(), value(0)));
            params.push(("b".into(), value(0)));
        }
    }
    for named in &signature.named {
        let name = named_parameter_wgsl(signature, named.name);
        params.push((name, host_type_wgsl(named.ty).to_string()));
    }
    params
}

/// The WGSL name of the named argument `name` of `signature`: `name`, or
/// `arg_{name}` where the calling convention has a parameter of that name
/// already (`component(v, index: 1)` is a map, whose first parameter is
/// `index`).
pub fn named_parameter_wgsl(signature: &Signature, name: &str) -> String {
    let taken = match signature.kind {
        FunctorKind::Map => &["index"][..],
        FunctorKind::Group => &["first", "k"][..],
        FunctorKind::Expand => &["source_index", "src", "lane", "k"][..],
        FunctorKind::Monoid(_) => &["a", "b"][..],
    };
    let taken = taken.contains(&name) || signature.inputs.iter().any(|p| p.name == name);
    match taken {
        true => format!("arg_{name}"),
        false => name.to_string(),
    }
}
