//! Every generic functor's WGSL twin compiles (naga parse and validation) for
//! every element type its signature admits. What the twins compute is compared
//! with the CPU by the GPU backend's tests, which need a GPU.

use dpp_gpu::check_twin;
use dpp_runtime::functor::no_twin;
use dpp_runtime::generic::register_generic_functors;
use dpp_runtime::wgsl::{WgslRequest, WgslTwin};
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, FunctorLibrary, RecordId,
    RecordType, Signature, TypeConstraint, TypePattern,
};

/// The generic functors and the record type `Pair { count: u32, position: vec3, hit: bool }`.
fn library() -> (FunctorLibrary, RecordId) {
    let mut library = FunctorLibrary::default();
    let pair = library.records.register(RecordType {
        name: "Pair".into(),
        fields: vec![
            ("count".into(), ElemType::U32),
            ("position".into(), ElemType::Vec3),
            ("hit".into(), ElemType::Bool),
        ],
        doc: "a test record".into(),
    });
    register_generic_functors(&mut library);
    (library, pair)
}

/// The input and output types of each instantiation of `signature`: its one
/// type variable bound to each of `candidates` that the constraint admits.
fn instantiations(
    signature: &Signature,
    candidates: &[ElemType],
) -> Vec<(Vec<ElemType>, ElemType)> {
    let patterns = signature.inputs.iter().chain(&signature.outputs);
    let constraint = patterns.clone().find_map(|p| match p.ty {
        TypePattern::Var(n, constraint) => {
            assert_eq!(n, 0, "`{}`: one type variable at most", signature.name);
            Some(constraint)
        }
        TypePattern::Exact(_) => None,
    });
    // Without a variable there is one instantiation; the binding is unused.
    let bindings: Vec<ElemType> = match constraint {
        Some(constraint) => candidates
            .iter()
            .copied()
            .filter(|&ty| constraint.admits(ty))
            .collect(),
        None => vec![ElemType::Bool],
    };
    let bind = |pattern: &TypePattern, variable: ElemType| match *pattern {
        TypePattern::Exact(ty) => ty,
        TypePattern::Var(..) => variable,
    };
    bindings
        .into_iter()
        .map(|variable| {
            let inputs = signature
                .inputs
                .iter()
                .map(|p| bind(&p.ty, variable))
                .collect();
            (inputs, bind(&signature.outputs[0].ty, variable))
        })
        .collect()
}

/// Builds `functor`'s twin for these types and compiles it as the backend would call it.
fn check(
    library: &FunctorLibrary,
    functor: &str,
    inputs: &[ElemType],
    output: ElemType,
) -> Result<WgslTwin, String> {
    let functor = library
        .get(functor)
        .unwrap_or_else(|| panic!("no functor `{functor}`"));
    let signature = functor.signature();
    let type_names: Vec<String> = inputs.iter().map(|ty| ty.name(&library.records)).collect();
    let function = format!("twin_{}_{}", signature.name, type_names.join("_"));
    let request = WgslRequest {
        function: &function,
        inputs,
        outputs: &[output],
        records: &library.records,
        resources: &(),
    };
    let twin = functor.wgsl(&request).map_err(|error| error.message)?;
    if !twin.source.contains(&format!("fn {function}(")) {
        return Err(format!("does not define `{function}`:\n{}", twin.source));
    }
    check_twin(signature, &request, &twin, &library.uniforms)
        .map_err(|error| format!("{error}\n{}", twin.source))?;
    Ok(twin)
}

#[test]
fn every_twin_compiles_for_every_admitted_type() {
    let (library, pair) = library();
    let mut candidates = ElemType::PRIMITIVES.to_vec();
    candidates.push(ElemType::Record(pair));
    let mut failures = Vec::new();
    // Which functors the library holds is pinned by the runtime's own test
    // (runtime/tests/runtime/generic_functors.rs); here every one compiles.
    let mut checked = 0;
    for name in library.names() {
        checked += 1;
        let signature = library.get(name).expect("a generic functor").signature();
        let cases = instantiations(signature, &candidates);
        assert!(!cases.is_empty(), "`{name}` admits no type");
        for (inputs, output) in cases {
            if let Err(error) = check(&library, name, &inputs, output) {
                failures.push(format!("{name}{inputs:?} -> {output:?}: {error}"));
            }
        }
    }
    assert!(checked > 50, "only {checked} generic functors were checked");
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// The run-time failures a twin declares, with the CPU's messages (less the
/// element position, which a failure code cannot carry).
#[test]
fn twins_declare_the_cpus_failures() {
    let (library, _) = library();
    let empty_group = "a group needs at least one element";
    let cases: &[(&str, &[ElemType], ElemType, &[&str])] = &[
        (
            "div",
            &[ElemType::U32; 2],
            ElemType::U32,
            &["integer division by zero"],
        ),
        (
            "div",
            &[ElemType::I32; 2],
            ElemType::I32,
            &["integer division by zero"],
        ),
        ("div", &[ElemType::F32; 2], ElemType::F32, &[]),
        ("div", &[ElemType::Vec3; 2], ElemType::Vec3, &[]),
        ("sum", &[ElemType::F32], ElemType::F32, &[empty_group]),
        ("average", &[ElemType::Bool], ElemType::F32, &[empty_group]),
        ("add", &[ElemType::U32; 2], ElemType::U32, &[]),
        ("toU32", &[ElemType::F32], ElemType::U32, &[]),
        (
            "rem",
            &[ElemType::I32; 2],
            ElemType::I32,
            &["integer division by zero"],
        ),
        ("rem", &[ElemType::F32; 2], ElemType::F32, &[]),
        (
            "component",
            &[ElemType::Vec3],
            ElemType::F32,
            &["component index is out of range for vec3, whose components are 0 to 2"],
        ),
        ("normalize", &[ElemType::Vec2], ElemType::Vec2, &[]),
    ];
    for &(name, inputs, output, expected) in cases {
        let twin = check(&library, name, inputs, output).unwrap_or_else(|error| panic!("{error}"));
        assert_eq!(twin.failures, expected, "{name}{inputs:?}");
        assert_eq!(
            twin.source.contains("_fail("),
            !expected.is_empty(),
            "{name}{inputs:?}: {}",
            twin.source
        );
    }
}

/// Types a signature excludes get an error, not a twin that does something else.
#[test]
fn types_outside_the_signature_get_no_twin() {
    let (library, pair) = library();
    let record = ElemType::Record(pair);
    let cases: &[(&str, &[ElemType], ElemType)] = &[
        ("add", &[ElemType::Bool; 2], ElemType::Bool),
        ("min", &[record, record], record),
        ("or", &[ElemType::U32; 2], ElemType::U32),
        ("lt", &[ElemType::Bool; 2], ElemType::Bool),
        ("eq", &[ElemType::Vec3; 2], ElemType::Bool),
        ("isZero", &[ElemType::Bool], ElemType::Bool),
        ("toF32", &[ElemType::Vec2], ElemType::F32),
        (
            "select",
            &[ElemType::Bool, ElemType::U32, ElemType::I32],
            ElemType::U32,
        ),
        ("sum", &[record], record),
        ("average", &[ElemType::Vec4], ElemType::F32),
        ("neg", &[ElemType::U32], ElemType::U32),
        ("sqrt", &[ElemType::I32], ElemType::I32),
        ("clamp", &[ElemType::U32; 3], ElemType::U32),
        ("dot", &[ElemType::F32; 2], ElemType::F32),
        ("cross", &[ElemType::Vec2; 2], ElemType::Vec2),
        ("component", &[ElemType::F32], ElemType::F32),
        ("rem", &[ElemType::Vec2; 2], ElemType::Vec2),
    ];
    for &(name, inputs, output) in cases {
        let result = check(&library, name, inputs, output);
        assert!(result.is_err(), "{name}{inputs:?} gave a twin");
    }
    // The request's arity must be the signature's.
    let result = check(&library, "add", &[ElemType::U32], ElemType::U32);
    assert!(result.is_err_and(|error| error.contains("asked for 1 inputs")));
}

/// A functor that keeps the trait's default `wgsl`.
struct CpuOnly(Signature);

impl Functor for CpuOnly {
    fn signature(&self) -> &Signature {
        &self.0
    }

    fn run_cpu(
        &self,
        _: &CallContext<'_>,
        _: &[ColumnView<'_>],
        _: &mut [Column],
    ) -> Result<(), FunctorError> {
        Ok(())
    }
}

#[test]
fn a_functor_without_a_twin_says_so() {
    let (library, _) = library();
    let functor =
        CpuOnly(Signature::map("cpuOnly").output("out", TypePattern::Var(0, TypeConstraint::Any)));
    let request = WgslRequest {
        function: "twin_cpuOnly",
        inputs: &[],
        outputs: &[ElemType::U32],
        records: &library.records,
        resources: &(),
    };
    assert_eq!(functor.wgsl(&request), Err(no_twin("cpuOnly")));
}
