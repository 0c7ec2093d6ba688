// The WGSL twin of `volumeMarch` (mod.rs beside this file; the definition in
// functors/volume_render/mod.rs, which this follows operation by operation).
// Buffers: tracer_shading_constants ((min, max, 1 / (max - min), 0) of the
// scalar range, …), tracer_colormap (256 entries (linear r, g, b, opacity));
// the volume through module `tracer_volume`.
// Failure 0: step or unit is not above 0. Failure 1: samples < 1.
// Failure 2: cutoff is not finite.

// `trilinear`: the field at sample coordinates g, clamped into the box.
fn $FUNCTION_trilinear(g_in: vec3<f32>) -> f32 {
    let dims = tracer_volume_dims();
    let last = max(dims, vec3<u32>(1u)) - vec3<u32>(1u);
    let g = clamp(g_in, vec3<f32>(0.0), vec3<f32>(last));
    let cell = min(vec3<u32>(g), max(dims, vec3<u32>(2u)) - vec3<u32>(2u));
    let f = g - vec3<f32>(cell);
    let v000 = tracer_volume_value(cell);
    let v100 = tracer_volume_value(cell + vec3<u32>(1u, 0u, 0u));
    let v010 = tracer_volume_value(cell + vec3<u32>(0u, 1u, 0u));
    let v110 = tracer_volume_value(cell + vec3<u32>(1u, 1u, 0u));
    let v001 = tracer_volume_value(cell + vec3<u32>(0u, 0u, 1u));
    let v101 = tracer_volume_value(cell + vec3<u32>(1u, 0u, 1u));
    let v011 = tracer_volume_value(cell + vec3<u32>(0u, 1u, 1u));
    let v111 = tracer_volume_value(cell + vec3<u32>(1u, 1u, 1u));
    let x00 = v000 + (v100 - v000) * f.x;
    let x10 = v010 + (v110 - v010) * f.x;
    let x01 = v001 + (v101 - v001) * f.x;
    let x11 = v011 + (v111 - v011) * f.x;
    let y0 = x00 + (x10 - x00) * f.y;
    let y1 = x01 + (x11 - x01) * f.y;
    return y0 + (y1 - y0) * f.z;
}

// `gradient`: central differences one sample apart, in world units.
fn $FUNCTION_gradient(g: vec3<f32>) -> vec3<f32> {
    let spacing = bitcast<vec3<f32>>(tracer_volume_grid[2].xyz);
    let x = vec3<f32>(1.0, 0.0, 0.0);
    let y = vec3<f32>(0.0, 1.0, 0.0);
    let z = vec3<f32>(0.0, 0.0, 1.0);
    let differences = vec3<f32>(
        $FUNCTION_trilinear(g + x) - $FUNCTION_trilinear(g - x),
        $FUNCTION_trilinear(g + y) - $FUNCTION_trilinear(g - y),
        $FUNCTION_trilinear(g + z) - $FUNCTION_trilinear(g - z)
    );
    return differences / (2.0 * spacing);
}

// `ColorMap::rgba_at`: colour and opacity at t in [0, 1] (clamped; NaN reads as 0).
fn $FUNCTION_rgba(t: f32) -> vec4<f32> {
    var clamped = 0.0;
    if (!tracer_is_nan(t)) {
        clamped = clamp(t, 0.0, 1.0);
    }
    let entries = arrayLength(&tracer_colormap);
    let x = clamped * f32(entries - 1u);
    let low = min(u32(x), entries - 2u);
    let fraction = x - f32(low);
    let a = tracer_colormap[low];
    let b = tracer_colormap[low + 1u];
    return vec4<f32>(a.xyz + (b.xyz - a.xyz) * fraction, a.w + (b.w - a.w) * fraction);
}

// `corrected_opacity`: 1 - (1 - a)^ratio, exact at 0 and 1.
fn $FUNCTION_corrected(a: f32, ratio: f32) -> f32 {
    if (a <= 0.0) {
        return 0.0;
    }
    if (a >= 1.0) {
        return 1.0;
    }
    return 1.0 - pow(1.0 - a, ratio);
}

fn $FUNCTION(index: u32, march: March, step: f32, unit: f32, samples: i32, cutoff: f32, shade: bool) -> March {
    var m = march;
    if (!(tracer_is_finite(step) && step > 0.0 && tracer_is_finite(unit) && unit > 0.0)) {
        $FUNCTION_fail(0u);
        return m;
    }
    if (samples < 1) {
        $FUNCTION_fail(1u);
        return m;
    }
    if (!tracer_is_finite(cutoff)) {
        $FUNCTION_fail(2u);
        return m;
    }
    let low = tracer_shading_constants[0].x;
    let inverse_range = tracer_shading_constants[0].z;
    let spacing = bitcast<vec3<f32>>(tracer_volume_grid[2].xyz);
    let ratio = step / unit;
    let light = tracer_normalize_or_zero(m.dir * spacing);
    for (var k = 0; k < samples; k = k + 1) {
        if (!(m.t <= m.tEnd)) {
            break;
        }
        let g = m.origin + m.dir * m.t;
        let s = $FUNCTION_trilinear(g);
        let rgba = $FUNCTION_rgba((s - low) * inverse_range);
        var c = rgba.xyz;
        let alpha = $FUNCTION_corrected(rgba.w, ratio);
        if (shade && alpha > 0.0) {
            let n = tracer_normalize_or_zero($FUNCTION_gradient(g));
            if (!tracer_is_zero_vector(n)) {
                c = c * (0.3 + 0.7 * abs(tracer_dot(n, light)));
            }
        }
        let weight = (1.0 - m.alpha) * alpha;
        m.color = m.color + c * weight;
        m.alpha = m.alpha + weight;
        m.t = m.t + step;
        if (m.alpha >= cutoff) {
            m.t = tracer_infinity();
        }
    }
    return m;
}
