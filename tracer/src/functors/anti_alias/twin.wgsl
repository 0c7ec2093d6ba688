// The WGSL twin of `antiAlias` (mod.rs beside this file), a group of `k`
// colours read with `$FUNCTION_src`: their mean, summed in order as the CPU
// does, clamped to [0, 1] (NaN to 0) and sRGB-encoded.
// Failure 0: the group is empty.

// `linear_to_srgb` of tracer/src/shading/srgb.rs for one component in [0, 1]
// (there a series, correctly rounded; `pow` here, within the GPU's precision).
fn $FUNCTION_encode(x: f32) -> f32 {
    if (x <= $SRGB_LINEAR_LIMIT) {
        return x * 12.92f;
    }
    // Exact, where the formula rounds to 0.99999994.
    if (x >= 1.0) {
        return 1.0;
    }
    return 1.055f * pow(x, $SRGB_EXPONENT) - 0.055f;
}

// glam's `max(0)` then `min(1)`, which map NaN to 0.
fn $FUNCTION_unit(x: f32) -> f32 {
    if (x > 0.0 && !tracer_is_nan(x)) {
        return min(x, 1.0);
    }
    return 0.0;
}

fn $FUNCTION(first: u32, k: u32) -> vec3<f32> {
    if (k == 0u) {
        $FUNCTION_fail(0u);
        return vec3<f32>(0.0);
    }
    let scale = 1.0 / f32(k);
    var sum = vec3<f32>(0.0);
    for (var sample = 0u; sample < k; sample = sample + 1u) {
        sum = sum + $FUNCTION_src(first + sample);
    }
    let mean = sum * scale;
    return vec3<f32>(
        $FUNCTION_encode($FUNCTION_unit(mean.x)),
        $FUNCTION_encode($FUNCTION_unit(mean.y)),
        $FUNCTION_encode($FUNCTION_unit(mean.z))
    );
}
