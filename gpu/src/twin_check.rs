//! Twins checked without a GPU: a twin compiled (naga) inside a placeholder
//! prelude and a kernel that calls it as the backend would, so that a
//! functor's own tests catch a broken twin on any machine.

use dpp_runtime::host::UniformSchema;
use dpp_runtime::signature::{FunctorKind, Signature};
use dpp_runtime::wgsl::{
    collect_dependencies, elem_type_wgsl, host_type_wgsl, record_structs, twin_parameters,
    WgslRequest, WgslTwin,
};
use std::fmt::Write;

/// Uniform accessors that return zero: enough to compile a twin in isolation.
fn placeholder_uniforms(schema: &UniformSchema) -> String {
    let mut text = String::new();
    for (record, fields) in &schema.records {
        for (field, ty) in fields {
            let wgsl = host_type_wgsl(*ty);
            let _ = writeln!(
                text,
                "fn uniform_{record}_{field}() -> {wgsl} {{ return {wgsl}(); }}"
            );
        }
    }
    text
}

/// Compiles and validates (naga) a twin for `request` inside a placeholder
/// prelude and a kernel that calls it the way the backend would; returns the
/// validation error as text. For functors' own tests.
pub fn check_twin(
    signature: &Signature,
    request: &WgslRequest<'_>,
    twin: &WgslTwin,
    uniforms: &UniformSchema,
) -> Result<(), String> {
    let records = request.records;
    let function = request.function;
    let mut source = record_structs(records);
    source.push_str(&placeholder_uniforms(uniforms));
    let mut modules = Vec::new();
    let mut buffers = Vec::new();
    collect_dependencies(twin, &mut modules, &mut buffers);
    for (binding, buffer) in buffers.iter().enumerate() {
        let _ = writeln!(
            source,
            "@group(1) @binding({binding}) var<storage, read> {}: {};",
            buffer.name, buffer.wgsl_type
        );
    }
    let _ = writeln!(source, "fn {function}_fail(code: u32) {{ }}");
    if signature.kind == FunctorKind::Group {
        let src = elem_type_wgsl(request.inputs[0], records);
        let _ = writeln!(
            source,
            "fn {function}_src(i: u32) -> {src} {{ return {src}(); }}"
        );
    }
    for module in &modules {
        source.push_str(&module.source);
        source.push('\n');
    }
    source.push_str(&twin.source);
    source.push('\n');
    let params = twin_parameters(signature, request.inputs, records);
    let output = elem_type_wgsl(request.outputs[0], records);
    let arguments: Vec<String> = params.iter().map(|(_, ty)| format!("{ty}()")).collect();
    let _ = writeln!(
        source,
        "@group(0) @binding(0) var<storage, read_write> check_sink: array<u32>;\n\
         @compute @workgroup_size(64)\n\
         fn main(@builtin(global_invocation_id) id: vec3<u32>) {{\n\
         \x20   let value: {output} = {function}({});\n\
         \x20   check_sink[id.x] = 0u;\n\
         }}",
        arguments.join(", ")
    );
    validate_wgsl(&source)
}

/// Parses and validates a whole WGSL module; the error carries the source location.
pub fn validate_wgsl(source: &str) -> Result<(), String> {
    let module = naga::front::wgsl::parse_str(source).map_err(|e| e.emit_to_string(source))?;
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .map_err(|e| e.emit_to_string(source))?;
    Ok(())
}
