// The WGSL twin of `material` (mod.rs beside this file).
// Buffer tracer_materials: 2 vec4 per material, (Kd, Ns) and (Ks, reflectivity).
// Failure 0: the id names a material the scene does not have.

fn $FUNCTION(index: u32, id: u32) -> Material {
    if (id >= arrayLength(&tracer_materials) / 2u) {
        $FUNCTION_fail(0u);
        return Material(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    }
    let diffuse_and_shininess = tracer_materials[2u * id];
    let specular_and_reflectivity = tracer_materials[2u * id + 1u];
    return Material(diffuse_and_shininess.xyz, diffuse_and_shininess.w, specular_and_reflectivity.xyz, specular_and_reflectivity.w);
}
