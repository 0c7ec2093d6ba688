//! The tracer's WGSL twins: the modules several twins share (`*.wgsl` here),
//! the scene data they read ([`buffers`]), and how a functor's template
//! (`functors/<name>/twin.wgsl`) becomes its twin (conventions in
//! [`dpp_runtime::wgsl`]).
//!
//! Templates are WGSL with `$NAME` placeholders: `$FUNCTION` is the requested
//! function name (helpers are `$FUNCTION_…`), the others constants that Rust
//! owns. Modules get such constants as `const` declarations in front. `f32`
//! constants are literals that parse to the same bits.
//! Twins follow their CPU functor's order of floating-point operations; see
//! `vector.wgsl` for glam's.

pub mod buffers;

use crate::bvh::Bvh;
use crate::functors::SURFACE_EPSILON;
use crate::marching_cubes_tables::MAX_CELL_TRIANGLES;
use buffers::{MarchingCubesGpuBuffers, SceneGpuBuffers, ShadingGpuBuffers, VolumeGpuBuffers};
use dpp_runtime::wgsl::{GpuBuffer, WgslModule, WgslRequest, WgslTwin};
use dpp_runtime::{FunctorError, Signature, TypePattern};
use std::any::Any;
use std::borrow::Cow;
use std::sync::OnceLock;

/// `x` as a WGSL literal of the same `f32` (the `f` suffix makes WGSL parse
/// the decimal straight to `f32`, as Rust does, with no rounding through f64).
pub(crate) fn f32_literal(x: f32) -> String {
    assert!(x.is_finite(), "WGSL has no literal for {x}");
    format!("{x:?}f")
}

/// `v` as a WGSL `vec3<f32>` of the same components.
pub(crate) fn vec3_literal(v: glam::Vec3) -> String {
    format!(
        "vec3<f32>({}, {}, {})",
        f32_literal(v.x),
        f32_literal(v.y),
        f32_literal(v.z)
    )
}

/// The failure of a twin that found no positive `scene.diagonal` uniform.
pub(crate) fn diagonal_failure(functor: &str) -> String {
    format!("{functor}: the scene.diagonal uniform is not a positive number (no scene loaded?)")
}

/// `template` with each `$NAME` of `values` replaced (longest names first, so
/// that one name may start another). Every `$` must be replaced.
pub(crate) fn instantiate(template: &str, values: &[(&str, String)]) -> String {
    let mut sorted: Vec<&(&str, String)> = values.iter().collect();
    sorted.sort_by_key(|(name, _)| std::cmp::Reverse(name.len()));
    let mut source = template.to_string();
    for (name, value) in sorted {
        source = source.replace(&format!("${name}"), value);
    }
    if let Some(at) = source.find('$') {
        let rest: String = source[at..].chars().take(40).collect();
        panic!("WGSL template placeholder without a value: {rest}");
    }
    source
}

/// A module's source behind the declarations of the constants Rust owns
/// (`(name, WGSL type, value)`), made once.
fn module_source(
    cell: &'static OnceLock<String>,
    source: &'static str,
    constants: impl FnOnce() -> Vec<(&'static str, &'static str, String)>,
) -> Cow<'static, str> {
    Cow::Borrowed(cell.get_or_init(|| {
        let mut text: String = constants()
            .into_iter()
            .map(|(name, ty, value)| format!("const {name}: {ty} = {value};\n"))
            .collect();
        text.push_str(&instantiate(source, &[]));
        text
    }))
}

/// `tracer_vector`: NaN and infinity tests on bits, glam's vector operations.
pub(crate) fn vector_module() -> WgslModule {
    WgslModule {
        name: "tracer_vector",
        source: Cow::Borrowed(include_str!("vector.wgsl")),
        buffers: Vec::new(),
    }
}

/// `tracer_random`: the PCG hash and `random_pair`.
pub(crate) fn random_module() -> WgslModule {
    WgslModule {
        name: "tracer_random",
        source: Cow::Borrowed(include_str!("random.wgsl")),
        buffers: Vec::new(),
    }
}

/// `tracer_sampling`: `cosine_hemisphere` (needs `tracer_vector`).
pub(crate) fn sampling_module() -> WgslModule {
    static SOURCE: OnceLock<String> = OnceLock::new();
    WgslModule {
        name: "tracer_sampling",
        source: module_source(&SOURCE, include_str!("sampling.wgsl"), || {
            vec![
                (
                    "TRACER_SAMPLING_TAU",
                    "f32",
                    f32_literal(std::f32::consts::TAU),
                ),
                (
                    "TRACER_SAMPLING_PI",
                    "f32",
                    f32_literal(std::f32::consts::PI),
                ),
            ]
        }),
        buffers: Vec::new(),
    }
}

/// `tracer_surface`: offsets, dead rays and the diagonal check of the twins
/// that start rays from a `Surface` (needs `tracer_vector`).
pub(crate) fn surface_module() -> WgslModule {
    static SOURCE: OnceLock<String> = OnceLock::new();
    WgslModule {
        name: "tracer_surface",
        source: module_source(&SOURCE, include_str!("surface.wgsl"), || {
            vec![(
                "TRACER_SURFACE_EPSILON",
                "f32",
                f32_literal(SURFACE_EPSILON),
            )]
        }),
        buffers: Vec::new(),
    }
}

/// `tracer_bvh`: the CPU's traversal and triangle test (needs `tracer_vector`).
pub(crate) fn bvh_module(scene: &SceneGpuBuffers) -> WgslModule {
    static SOURCE: OnceLock<String> = OnceLock::new();
    // The scene's own constants, then the cached rest.
    let scale = scene.bvh_scale;
    let scene_constants = format!(
        "const TRACER_BVH_SCALE: f32 = {};\nconst TRACER_BVH_INVERSE_SCALE: f32 = {};\n",
        f32_literal(scale),
        f32_literal(1.0 / scale)
    );
    WgslModule {
        name: "tracer_bvh",
        source: Cow::Owned(
            scene_constants
                + &module_source(&SOURCE, include_str!("bvh.wgsl"), || {
                    vec![
                        (
                            "TRACER_BVH_MAX_STACK_DEPTH",
                            "u32",
                            format!("{}u", Bvh::gpu_max_stack_depth()),
                        ),
                        (
                            "TRACER_BVH_ROBUST_FAR_SCALE",
                            "f32",
                            f32_literal(Bvh::gpu_robust_far_scale()),
                        ),
                    ]
                }),
        ),
        buffers: vec![
            scene.bvh_nodes.clone(),
            scene.bvh_triangles.clone(),
            scene.bvh_triangle_ids.clone(),
        ],
    }
}

/// `tracer_mesh`: file-order triangles, vertices, face normals (needs `tracer_vector`).
pub(crate) fn mesh_module(scene: &SceneGpuBuffers) -> WgslModule {
    WgslModule {
        name: "tracer_mesh",
        source: Cow::Borrowed(include_str!("mesh.wgsl")),
        buffers: vec![scene.mesh_triangles.clone(), scene.mesh_vertices.clone()],
    }
}

/// `tracer_colormap`: the colour map lookup (needs `tracer_vector`).
pub(crate) fn colormap_module(shading: &ShadingGpuBuffers) -> WgslModule {
    WgslModule {
        name: "tracer_colormap",
        source: Cow::Borrowed(include_str!("colormap.wgsl")),
        buffers: vec![shading.colormap.clone()],
    }
}

/// `tracer_volume`: samples, positions, gradients and cells of the volume.
pub(crate) fn volume_module(volume: &VolumeGpuBuffers) -> WgslModule {
    WgslModule {
        name: "tracer_volume",
        source: Cow::Borrowed(include_str!("volume.wgsl")),
        buffers: vec![volume.grid.clone(), volume.values.clone()],
    }
}

/// `tracer_marching_cubes`: the marching-cubes tables.
pub(crate) fn marching_cubes_module() -> WgslModule {
    static SOURCE: OnceLock<String> = OnceLock::new();
    let tables = MarchingCubesGpuBuffers::get();
    WgslModule {
        name: "tracer_marching_cubes",
        source: module_source(&SOURCE, include_str!("marching_cubes.wgsl"), || {
            vec![(
                "TRACER_MC_MAX_CELL_TRIANGLES",
                "u32",
                format!("{MAX_CELL_TRIANGLES}u"),
            )]
        }),
        buffers: vec![
            tables.case_triangle_counts.clone(),
            tables.case_triangles.clone(),
            tables.edge_corners.clone(),
        ],
    }
}

/// The run's resources of type `T`, as [`dpp_runtime::CallContext::resources`] gives them.
pub(crate) fn request_resources<'a, T: Any>(
    request: &'a WgslRequest<'_>,
    functor: &str,
) -> Result<&'a T, FunctorError> {
    request.resources.downcast_ref::<T>().ok_or_else(|| {
        FunctorError::bad_input(format!(
            "{functor}: the WGSL twin needs {} but the run has none (no scene loaded?)",
            std::any::type_name::<T>()
        ))
    })
}

/// What a functor's twin is made of besides its template (the parts a twin
/// does not need left at their empty defaults).
#[derive(Default)]
pub(crate) struct TwinParts<'a> {
    /// `$NAME` values besides `$FUNCTION`.
    pub constants: Vec<(&'a str, String)>,
    /// Every module the template and its modules call (duplicates are dropped).
    pub modules: Vec<WgslModule>,
    /// Buffers the template reads itself.
    pub buffers: Vec<GpuBuffer>,
    /// The messages of `$FUNCTION_fail(code)`, by code.
    pub failures: Vec<String>,
}

/// The parts of the twin of `functor`, a traversal of the scene's BVH: the
/// BVH module, and failure 0 for a traversal whose stack overflowed (the
/// CPU's build keeps trees within it, so this marks a BVH the GPU does not
/// read as the CPU does).
pub(crate) fn bvh_traversal_parts(scene: &SceneGpuBuffers, functor: &str) -> TwinParts<'static> {
    TwinParts {
        modules: vec![vector_module(), bvh_module(scene)],
        failures: vec![format!(
            "{functor}: the BVH traversal needed more than {} stack entries",
            Bvh::gpu_max_stack_depth()
        )],
        ..TwinParts::default()
    }
}

/// The parts of a twin whose template needs nothing besides itself: none.
pub(crate) fn no_parts(_: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    Ok(TwinParts::default())
}

/// A functor's twin: its template instantiated for `request`, which must ask
/// for the signature's (monomorphic) element types.
pub(crate) fn twin(
    signature: &Signature,
    request: &WgslRequest<'_>,
    template: &str,
    parts: TwinParts<'_>,
) -> Result<WgslTwin, FunctorError> {
    let exact = |patterns: &[dpp_runtime::ArrayParam]| -> Vec<Option<dpp_runtime::ElemType>> {
        patterns
            .iter()
            .map(|p| match p.ty {
                TypePattern::Exact(ty) => Some(ty),
                TypePattern::Var(..) => None,
            })
            .collect()
    };
    let asked = |types: &[dpp_runtime::ElemType]| -> Vec<Option<dpp_runtime::ElemType>> {
        types.iter().copied().map(Some).collect()
    };
    if exact(&signature.inputs) != asked(request.inputs)
        || exact(&signature.outputs) != asked(request.outputs)
    {
        return Err(FunctorError::bad_input(format!(
            "internal error: the WGSL twin of `{}` was asked for inputs {:?} and outputs {:?}",
            signature.name, request.inputs, request.outputs
        )));
    }
    // Memory of a volume no run holds any more goes at the next twin built.
    buffers::release_gpu_buffers_of_dropped_volumes();
    let mut values = parts.constants;
    values.push(("FUNCTION", request.function.to_string()));
    let mut modules: Vec<WgslModule> = Vec::new();
    for module in parts.modules {
        if !modules.iter().any(|m| m.name == module.name) {
            modules.push(module);
        }
    }
    Ok(WgslTwin {
        source: instantiate(template, &values),
        modules,
        buffers: parts.buffers,
        failures: parts.failures,
    })
}

#[cfg(test)]
mod agreement;
#[cfg(test)]
mod tests;
