// The WGSL twin of `cameraRay` (mod.rs beside this file): ray `ray_index`
// belongs to pixel `tracer_camera_morton_pixels[ray_index / spp]` and sample
// `ray_index % spp`; its direction is `Camera::direction` on the frame the CPU
// computed (buffer `tracer_camera`: (eye, tan(fov/2)), (forward, aspect),
// (right, width), (true up, height)).
// Failure 0: spp is not 1 or 4. Failure 1: the ray index is out of range.

fn $FUNCTION(index: u32, ray_index: u32, spp: i32) -> Ray {
    let dead = Ray(vec3<f32>(0.0), vec3<f32>(0.0, 0.0, 1.0), 0.0, 0u, vec3<f32>(0.0), 0u);
    if (spp != 1 && spp != 4) {
        $FUNCTION_fail(0u);
        return dead;
    }
    let samples = u32(spp);
    let slot = ray_index / samples;
    if (slot >= arrayLength(&tracer_camera_morton_pixels)) {
        $FUNCTION_fail(1u);
        return dead;
    }
    let pixel = tracer_camera_morton_pixels[slot];
    let sample_in_pixel = ray_index % samples;
    // `sample_offset`: the centre for one sample, the 2x2 grid row by row for four.
    var offset = vec2<f32>(0.5, 0.5);
    if (samples != 1u) {
        offset = vec2<f32>(0.25 + 0.5 * f32(sample_in_pixel & 1u), 0.25 + 0.5 * f32(sample_in_pixel >> 1u));
    }
    let eye = tracer_camera[0];
    let forward = tracer_camera[1];
    let right = tracer_camera[2];
    let true_up = tracer_camera[3];
    let half_height = eye.w;
    let aspect = forward.w;
    let width = right.w;
    let height = true_up.w;
    let columns = u32(uniform_camera_width());
    let x = f32(pixel % columns);
    let y = f32(pixel / columns);
    let horizontal = 2.0 * (x + offset.x) / width - 1.0;
    let vertical = 1.0 - 2.0 * (y + offset.y) / height;
    let direction = tracer_normalize(
        forward.xyz + horizontal * half_height * aspect * right.xyz + vertical * half_height * true_up.xyz
    );
    return Ray(eye.xyz, direction, tracer_infinity(), pixel * samples + sample_in_pixel, vec3<f32>(1.0), 0u);
}
