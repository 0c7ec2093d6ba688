// The WGSL twin of `transparent` (mod.rs beside this file;
// `ColorMap::transparent_between`): every opacity entry from the one below
// lo's table point to the one above hi's is 0. Buffers:
// tracer_shading_constants ((min, max, 1 / (max - min), 0), …),
// tracer_colormap (256 entries (r, g, b, opacity)).

// The entry below t's point in the table (t clamped to [0, 1]; NaN reads as 0).
fn $FUNCTION_entry(t: f32, entries: u32) -> u32 {
    var clamped = 0.0;
    if (!tracer_is_nan(t)) {
        clamped = clamp(t, 0.0, 1.0);
    }
    return min(u32(clamped * f32(entries - 1u)), entries - 2u);
}

fn $FUNCTION(index: u32, range: vec2<f32>) -> bool {
    let lo = range.x;
    let hi = -range.y;
    if (!(lo <= hi)) {
        return true;
    }
    let low = tracer_shading_constants[0].x;
    let inverse_range = tracer_shading_constants[0].z;
    let entries = arrayLength(&tracer_colormap);
    let first = $FUNCTION_entry((lo - low) * inverse_range, entries);
    let last = $FUNCTION_entry((hi - low) * inverse_range, entries) + 1u;
    for (var i = first; i <= last; i = i + 1u) {
        if (tracer_colormap[i].w != 0.0) {
            return false;
        }
    }
    return true;
}
