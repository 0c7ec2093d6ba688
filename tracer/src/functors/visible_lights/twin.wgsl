// The WGSL twin of `visibleLights` (mod.rs beside this file), a group of `k`
// `blocked` flags read with `$FUNCTION_src`: bit j set when light j is not blocked.
// Failure 0: the group is not 1 to MAX_LIGHTS (32) lights.

fn $FUNCTION(first: u32, k: u32) -> u32 {
    if (k == 0u || k > $MAX_LIGHTS) {
        $FUNCTION_fail(0u);
        return 0u;
    }
    var mask = 0u;
    for (var light = 0u; light < k; light = light + 1u) {
        if (!$FUNCTION_src(first + light)) {
            mask = mask | (1u << light);
        }
    }
    return mask;
}
