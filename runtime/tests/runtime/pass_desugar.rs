//! Pass 5, `desugar`: element-wise expressions over arrays (operators,
//! functors called by name, vector swizzles) become maps of the generic
//! functors, host scalars broadcast by `fill`, `f32` arrays by `splatN`.
//!
//! `check!(source, @"…")` shows the fused plan's stages and ops, then the
//! outputs of running it (fused and unfused must agree); or every
//! diagnostic, one per line.

use crate::common::{check, compile, diagnostics_text, ops_text, run_text, trim_indent};
use std::path::Path;

fn report(source: &str) -> String {
    let source = trim_indent(source);
    let library = crate::common::library();
    let path = Path::new("desugar.dpp");
    let plan = |fuse| compile(path, &source, &library, fuse);
    let (fused, unfused) = match (plan(true), plan(false)) {
        (Ok(fused), Ok(unfused)) => (fused, unfused),
        (Err(failure), _) | (_, Err(failure)) => return diagnostics_text(&failure),
    };
    let outputs = run_text(&fused, &library);
    assert_eq!(
        outputs,
        run_text(&unfused, &library),
        "fused and unfused disagree"
    );
    format!("{}---\n{outputs}", ops_text(&fused, &library))
}

#[test]
fn operators_over_arrays_become_one_fused_stage() {
    // Host scalars are filled to the array's element type (`2` becomes a
    // float for an f32 array); `-`, `!` and comparisons are maps too.
    check!(
        r#"
        pipeline p {
            x = map<toF32>(iota(4))
            out y = x * 2 + 1.0
            out z = -x
            out b = x > 1.5 && !(x == 3.0)
        }
        "#,
        @"
            stage 1 [iota → map<toF32> → fill → map<mul> → fill → map<add> → map<neg> → fill → map<gt> → fill → map<eq> → map<not> → map<and>] {
              over 4
              %0 = iota(4)
              x = map<toF32>(%0)
              %13 = fill(4, 2.0)
              %3 = map<mul>(x, %13)
              %14 = fill(4, 1.0)
              y = map<add>(%3, %14)
              z = map<neg>(x)
              %15 = fill(4, 1.5)
              %8 = map<gt>(x, %15)
              %16 = fill(4, 3.0)
              %9 = map<eq>(x, %16)
              %10 = map<not>(%9)
              b = map<and>(%8, %10)
              reads direct: -; indexed: -; uniform: -
              materialises y: f32, z: f32, b: bool
              ends at control flow
            }
            out y = y
            out z = z
            out b = b
            ---
            y = [1.0, 3.0, 5.0, 7.0]
            z = [-0.0, -1.0, -2.0, -3.0]
            b = [false, false, true, false]
        "
    );
}

#[test]
fn host_variables_and_params_are_broadcast() {
    // A host `int` against an f32 array converts with `float`; against a
    // u32 array it fills as it is.
    check!(
        r#"
        param scale = 3
        pipeline p {
            i = iota(5)
            n = len(i)
            out r = map<toF32>(i) / n
            out s = i * scale % 4
        }
        "#,
        @"
            param scale: int = 3
            let scale: int = 3
            stage 1 [iota] {
              over 5
              i = iota(5)
              reads direct: -; indexed: -; uniform: -
              materialises i: u32
              ends at control flow
            }
            let n: int = len(i)
            stage 2 [map<toF32> → fill → map<div> → fill → map<mul> → fill → map<rem>] {
              over 5
              %4 = map<toF32>(i)
              %10 = fill(5, float(n))
              r = map<div>(%4, %10)
              %11 = fill(5, scale)
              %7 = map<mul>(i, %11)
              %12 = fill(5, 4)
              s = map<rem>(%7, %12)
              reads direct: i: u32; indexed: -; uniform: n, scale
              materialises r: f32, s: u32
              ends at control flow
            }
            out r = r
            out s = s
            ---
            r = [0.0, 0.2, 0.4, 0.6, 0.8]
            s = [0, 3, 2, 1, 0]
        "
    );
}

#[test]
fn functors_are_called_by_name_with_their_named_arguments() {
    // `random(i, seed: 7)` is `map<random>(i, seed: 7)`; CSE merges the two.
    check!(
        r#"
        pipeline p {
            i = iota(3)
            out a = random(i, seed: 7)
            out same = map<eq>(a, map<random>(i, seed: 7))
            out m = max(i, 1)
            out f = float(i) + 0.5
        }
        "#,
        @"
            stage 1 [iota → map<random> → map<eq> → fill → map<max> → map<toF32> → fill → map<add>] {
              over 3
              i = iota(3)
              a = map<random>(i, seed: 7)
              same = map<eq>(a, a)
              %12 = fill(3, 1)
              m = map<max>(i, %12)
              %9 = map<toF32>(i)
              %13 = fill(3, 0.5)
              f = map<add>(%9, %13)
              reads direct: -; indexed: -; uniform: -
              materialises a: f32, same: bool, m: u32, f: f32
              ends at control flow
            }
            out a = a
            out same = same
            out m = m
            out f = f
            ---
            a = [0.5025464, 0.6542201, 0.85841614]
            same = [true, true, true]
            m = [1, 1, 2]
            f = [0.5, 1.5, 2.5]
        "
    );
}

#[test]
fn type_errors_point_at_the_operator_and_name_the_operands() {
    check!(
        r#"
        pipeline p {
            counts = iota(3)
            weights = map<toF32>(counts)
            out a = counts + 0.5
            out b = counts * weights
            out c = !weights
            out d = random(weights)
            out e = cos(1.0)
        }
        "#,
        @"
            dpp::expected-array at 8:13 `cos(1.0)`: `cos` is a functor: it applies element by element to arrays, and none of its arguments is one
              help: give it at least one array; host scalars are broadcast
            dpp::type-mismatch at 4:20 `+`: `+` cannot combine an array of u32 and a host float
              help: signature: monoid add   add(a: T0:numeric, b: T0:numeric) -> (out: T0:numeric)
            dpp::type-mismatch at 5:20 `*`: `*` cannot combine an array of u32 and an array of f32
              help: signature: monoid mul   mul(a: T0:numeric, b: T0:numeric) -> (out: T0:numeric)
            dpp::type-mismatch at 6:13 `!weights`: `!` does not apply to an array of f32
              help: signature: map          not(x: bool) -> (out: bool)
            dpp::type-mismatch at 7:13 `random`: `random` does not apply to an array of f32
              help: signature: map          random(x: u32) -> (out: f32) [seed: int = 0]
        "
    );
}

#[test]
fn vectors_meet_f32_arrays_and_swizzle() {
    // `v * x` scales each vector by its f32 (`splat3`), a host vector fills,
    // `vec3(…)` of arrays builds vectors, `.zy` picks components.
    check!(
        r#"
        pipeline p {
            x = map<toF32>(iota(3))
            v = vec3(x, x * 2.0, 1.0)
            out scaled = v * x
            out tint = v * vec3(0.5, 1, 2)
            out zy = v.zy
            out size = length(v.xy)
        }
        "#,
        @"
            stage 1 [iota → map<toF32> → fill → map<mul> → fill → map<vec3> → map<splat3> → map<mul> → fill → map<mul> → map<component> → map<component> → map<vec2> → map<component> → map<vec2> → map<length>] {
              over 3
              %0 = iota(3)
              x = map<toF32>(%0)
              %15 = fill(3, 2.0)
              %3 = map<mul>(x, %15)
              %16 = fill(3, 1.0)
              v = map<vec3>(x, %3, %16)
              %17 = map<splat3>(x)
              scaled = map<mul>(v, %17)
              %18 = fill(3, vec3(0.5, 1, 2))
              tint = map<mul>(v, %18)
              %19 = map<component>(v, index: 2)
              %20 = map<component>(v, index: 1)
              zy = map<vec2>(%19, %20)
              %21 = map<component>(v, index: 0)
              v.xy = map<vec2>(%21, %20)
              size = map<length>(v.xy)
              reads direct: -; indexed: -; uniform: -
              materialises scaled: vec3, tint: vec3, zy: vec2, size: f32
              ends at control flow
            }
            out scaled = scaled
            out tint = tint
            out zy = zy
            out size = size
            ---
            scaled = Vec3([Vec3(0.0, 0.0, 0.0), Vec3(1.0, 2.0, 1.0), Vec3(4.0, 8.0, 2.0)])
            tint = Vec3([Vec3(0.0, 0.0, 2.0), Vec3(0.5, 2.0, 2.0), Vec3(1.0, 4.0, 2.0)])
            zy = Vec2([Vec2(1.0, 0.0), Vec2(1.0, 2.0), Vec2(1.0, 4.0)])
            size = [0.0, 2.236068, 4.472136]
        "
    );
}

#[test]
fn swizzles_stay_within_the_vector() {
    check!(
        r#"
        pipeline p {
            v = vec2(map<toF32>(iota(3)))
            out a = v.z
            out b = v.xq
            out c = v.x.y
        }
        "#,
        @"
            dpp::unknown-field at 3:15 `z`: `.z`: an array of vec2 has no such components
              help: pick up to 4 of its components `x`, `y`, like `.x` or `.yx`
            dpp::unknown-field at 4:15 `xq`: `.xq`: an array of vec2 has no such components
              help: pick up to 4 of its components `x`, `y`, like `.x` or `.yx`
            dpp::type-mismatch at 5:17 `y`: `.y`: an array of f32 has no fields
        "
    );
}
