//! `shader(surf: Surface, occlusion: f32, visible: u32) -> (rgb: vec3)
//! [ambient: float = 0.15] [falloff: float = 1.0]`: Blinn–Phong shading in linear
//! RGB (the model is written out in [`crate::shading`]).
//!
//! - ambient: `ambient * (1 - occlusion) * base`, `occlusion` clamped to [0, 1]
//!   (the fraction of blocked ambient-occlusion rays);
//! - per light `j` whose bit is set in `visible` and that lies in front of the
//!   surface (`n·l > 0`, `n` the shading normal): diffuse `base * n·l` and
//!   specular `Ks * max(n·h, 0)^Ns` (none where `n·v <= 0`), both times the
//!   light's colour and the attenuation `intensity / (1 + falloff * (d /
//!   scene.diagonal)^2)`. The triangle's own normal does not gate the light: a
//!   triangle near the terminator of a smooth surface can face slightly away from
//!   a light its interpolated normal faces, and cutting it off there makes the
//!   terminator follow the triangles (whether such a point is shadowed is the
//!   shadow ray's business, which starts off the triangle's own plane);
//! - `base` is the colour map at `(scalar - min) / (max - min)` times `Kd`;
//! - the local colour is scaled by `1 - reflectivity` (the reflection ray carries
//!   the rest) and by `surf.weight`; a miss gives the background times
//!   `surf.weight`.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{
    colormap_module, diagonal_failure, request_resources, surface_module, vector_module, TwinParts,
};
use crate::functors::{named_f32, scene_diagonal, SurfaceColumns};
use crate::scene::TraceResources;
use crate::shading::{PointLight, MAX_LIGHTS};
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, HostValue,
    RecordId, Signature,
};
use glam::Vec3;
use std::sync::Arc;

pub fn functor(surface: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("shader")
        .input("surf", ElemType::Record(surface))
        .input("occlusion", ElemType::F32)
        .input("visible", ElemType::U32)
        .output("rgb", ElemType::Vec3)
        .named(
            "ambient",
            HostType::Float,
            Some(HostValue::Float(0.15)),
            "strength of the ambient term, scaled by 1 - occlusion",
        )
        .named(
            "falloff",
            HostType::Float,
            Some(HostValue::Float(1.0)),
            "k in the light attenuation intensity / (1 + k (d / scene.diagonal)^2); 0 turns it off",
        )
        .doc("Blinn-Phong: colour-mapped scalar times Kd, ambient scaled by 1 - occlusion, diffuse and specular from the visible lights; times (1 - reflectivity) and the ray weight (miss: background)");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading materials, lights and colour map, built once per shading set-up.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let shading = request_resources::<TraceResources>(request, "shader")?.shading_gpu_buffers();
    Ok(TwinParts {
        constants: vec![("MAX_LIGHTS", format!("{MAX_LIGHTS}u"))],
        modules: vec![vector_module(), surface_module(), colormap_module(&shading)],
        buffers: vec![shading.constants, shading.materials, shading.lights],
        failures: vec![
            "shader: ambient must be a finite number".into(),
            "shader: falloff must be a finite number".into(),
            diagonal_failure("shader"),
            "shader: a surface has a material the scene does not have".into(),
        ],
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let ambient = named_f32(ctx, 0, "shader", "ambient")?;
    let falloff = named_f32(ctx, 1, "shader", "falloff")?;
    let shading = &ctx.resources::<TraceResources>()?.shading;
    let diagonal = scene_diagonal(ctx, "shader")?;
    let inverse_diagonal = 1.0 / diagonal;
    let materials = shading.materials();
    let lights = &shading.lights()[..shading.lights().len().min(MAX_LIGHTS)];
    let colormap = shading.colormap();
    let [low, high] = shading.scalar_range();
    let inverse_range = 1.0 / (high - low);
    let background = shading.background();

    let surfaces = SurfaceColumns::new(&inputs[0]);
    let len = surfaces.len();
    // The same length for every column lets the loop drop its bounds checks.
    let (positions, normals, views) = (
        &surfaces.position[..len],
        &surfaces.normal[..len],
        &surfaces.view[..len],
    );
    let (scalars, material_ids, hits, weights) = (
        &surfaces.scalar[..len],
        &surfaces.material[..len],
        &surfaces.hit[..len],
        &surfaces.weight[..len],
    );
    let occlusion = &inputs[1].as_f32()[..len];
    let visible = &inputs[2].as_u32()[..len];
    // Every material a hit names must exist: checked up front, so that the
    // loop below cannot fail.
    if let Some(index) = (0..len).find(|&i| hits[i] && material_ids[i] as usize >= materials.len())
    {
        return Err(FunctorError::bad_input(format!(
            "shader: surface has material {}, but the scene has {} materials",
            material_ids[index],
            materials.len()
        )));
    }
    let colors = outputs[0].as_vec3_mut();
    colors.reserve(len);
    let mut block = Block::new();
    for start in (0..len).step_by(BLOCK) {
        let end = len.min(start + BLOCK);
        let mut out = [Vec3::ZERO; BLOCK];
        // Misses are the background; hits go to lanes, in order.
        let mut lanes = 0;
        for index in start..end {
            if hits[index] {
                block.index[lanes] = index;
                lanes += 1;
            } else {
                out[index - start] = background * weights[index];
            }
        }
        for lane in 0..lanes {
            let index = block.index[lane];
            let material = &materials[material_ids[index] as usize];
            let base = colormap.linear_at((scalars[index] - low) * inverse_range) * material.kd;
            let open = 1.0 - occlusion[index].clamp(0.0, 1.0);
            block.local[lane] = ambient * open * base;
            block.base[lane] = base;
            let (normal, view) = (normals[index], views[index]);
            block.sees_viewer[lane] = normal.dot(view) > 0.0;
            block.position.set(lane, positions[index]);
            block.normal.set(lane, normal);
            block.view.set(lane, view);
        }
        for (light_index, light) in lights.iter().enumerate() {
            block.light(light, lanes, inverse_diagonal, falloff);
            let bit = 1 << light_index;
            for lane in 0..lanes {
                let index = block.index[lane];
                if visible[index] & bit == 0 {
                    continue;
                }
                let diffuse = block.diffuse[lane];
                // Also false for NaN (a light exactly at the point).
                let in_front = diffuse > 0.0;
                if !in_front {
                    continue;
                }
                let material = &materials[material_ids[index] as usize];
                let specular = if block.sees_viewer[lane] {
                    block.normal_dot_half[lane].max(0.0).powf(material.ns)
                } else {
                    0.0
                };
                block.local[lane] += block.attenuation[lane]
                    * light.color
                    * (block.base[lane] * diffuse + material.ks * specular);
            }
        }
        for lane in 0..lanes {
            let index = block.index[lane];
            let material = &materials[material_ids[index] as usize];
            out[index - start] = block.local[lane] * (1.0 - material.reflectivity) * weights[index];
        }
        colors.extend_from_slice(&out[..end - start]);
    }
    Ok(())
}

/// Surfaces shaded together: the hits of up to `BLOCK` consecutive surfaces
/// become lanes, and each light's geometry (the square roots and divisions)
/// is computed for all lanes in loops the compiler turns into SIMD. The
/// arithmetic is the per-surface formula's, operation for operation.
const BLOCK: usize = 64;

/// `BLOCK` vectors, one array per component.
struct Lanes {
    x: [f32; BLOCK],
    y: [f32; BLOCK],
    z: [f32; BLOCK],
}

impl Lanes {
    fn new() -> Lanes {
        Lanes {
            x: [0.0; BLOCK],
            y: [0.0; BLOCK],
            z: [0.0; BLOCK],
        }
    }

    #[inline(always)]
    fn set(&mut self, lane: usize, v: Vec3) {
        (self.x[lane], self.y[lane], self.z[lane]) = (v.x, v.y, v.z);
    }
}

/// The lanes of a block: the hits' surfaces, their shading so far, and one
/// light's geometry at a time.
struct Block {
    /// The surface of each lane.
    index: [usize; BLOCK],
    position: Lanes,
    normal: Lanes,
    view: Lanes,
    base: [Vec3; BLOCK],
    sees_viewer: [bool; BLOCK],
    /// The colour so far.
    local: [Vec3; BLOCK],
    /// `normal·direction`, the attenuation, and `normal·half` for the current light.
    diffuse: [f32; BLOCK],
    attenuation: [f32; BLOCK],
    normal_dot_half: [f32; BLOCK],
}

impl Block {
    fn new() -> Block {
        Block {
            index: [0; BLOCK],
            position: Lanes::new(),
            normal: Lanes::new(),
            view: Lanes::new(),
            base: [Vec3::ZERO; BLOCK],
            sees_viewer: [false; BLOCK],
            local: [Vec3::ZERO; BLOCK],
            diffuse: [0.0; BLOCK],
            attenuation: [0.0; BLOCK],
            normal_dot_half: [0.0; BLOCK],
        }
    }

    /// `diffuse`, `attenuation` and `normal_dot_half` of the first `lanes`
    /// lanes for `light`, as `Vec3` arithmetic computes them: `to_light =
    /// light - position`, `distance = to_light.length()`, `direction = to_light
    /// / distance`, `half = (direction + view).normalize_or_zero()`.
    #[inline(always)]
    fn light(&mut self, light: &PointLight, lanes: usize, inverse_diagonal: f32, falloff: f32) {
        let (p, n, v) = (&self.position, &self.normal, &self.view);
        for lane in 0..lanes.min(BLOCK) {
            let tx = light.position.x - p.x[lane];
            let ty = light.position.y - p.y[lane];
            let tz = light.position.z - p.z[lane];
            let distance = (tx * tx + ty * ty + tz * tz).sqrt();
            let (dx, dy, dz) = (tx / distance, ty / distance, tz / distance);
            let (nx, ny, nz) = (n.x[lane], n.y[lane], n.z[lane]);
            self.diffuse[lane] = nx * dx + ny * dy + nz * dz;
            let scaled = distance * inverse_diagonal;
            self.attenuation[lane] = light.intensity / (1.0 + falloff * scaled * scaled);
            let (hx, hy, hz) = (dx + v.x[lane], dy + v.y[lane], dz + v.z[lane]);
            let rcp = 1.0 / (hx * hx + hy * hy + hz * hz).sqrt();
            let unit = rcp.is_finite() && rcp > 0.0;
            let (hx, hy, hz) = if unit {
                (hx * rcp, hy * rcp, hz * rcp)
            } else {
                (0.0, 0.0, 0.0)
            };
            self.normal_dot_half[lane] = nx * hx + ny * hy + nz * hz;
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::{surface_hit, Fixture};
    use crate::functors::SurfaceRecord;
    use crate::shading::{MaterialSpec, PointLight};
    use dpp_runtime::{Column, HostValue};
    use glam::Vec3;

    /// One light at `light`, the grey colour map over [0, 1] (so a scalar of 1
    /// gives base colour 1), default material (Kd 1, Ks 0.3, Ns 32).
    fn fixture(light: Vec3) -> Fixture {
        let mut fixture = Fixture::new();
        fixture.set_shading(|shading| {
            shading
                .set_lights(vec![PointLight::new(light, 1.0)])
                .unwrap();
            shading.set_colormap("grey").unwrap();
            shading.set_scalar_range(0.0, 1.0).unwrap();
        });
        fixture
    }

    fn lit_point() -> SurfaceRecord {
        SurfaceRecord {
            scalar: 1.0,
            ..surface_hit(Vec3::ZERO, Vec3::Z, 0)
        }
    }

    fn shade(
        fixture: &Fixture,
        surfaces: &[SurfaceRecord],
        occlusion: &[f32],
        visible: &[u32],
        named: &[HostValue],
    ) -> Vec<Vec3> {
        let surfaces = fixture.surfaces(surfaces);
        let occlusion = Column::F32(occlusion.to_vec());
        let visible = Column::U32(visible.to_vec());
        let out = fixture
            .run(
                "shader",
                named,
                0,
                &[surfaces.view(), occlusion.view(), visible.view()],
            )
            .unwrap();
        out[0].view().as_vec3().to_vec()
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).abs().max_element() < 1e-5
    }

    #[test]
    fn a_light_behind_the_surface_gives_only_ambient() {
        let fixture = fixture(Vec3::new(0.0, 0.0, -5.0));
        let rgb = shade(
            &fixture,
            &[lit_point(); 3],
            &[0.0, 1.0, 0.5],
            &[1, 1, 1],
            &[],
        );
        assert!(close(rgb[0], Vec3::splat(0.15)), "{}", rgb[0]);
        // Occlusion 1 removes the ambient term.
        assert_eq!(rgb[1], Vec3::ZERO);
        assert!(close(rgb[2], Vec3::splat(0.075)), "{}", rgb[2]);
        let rgb = shade(
            &fixture,
            &[lit_point()],
            &[0.0],
            &[1],
            &[HostValue::Float(0.5)],
        );
        assert!(close(rgb[0], Vec3::splat(0.5)), "{}", rgb[0]);
    }

    #[test]
    fn a_visible_light_adds_diffuse_and_specular_a_blocked_one_does_not() {
        let fixture = fixture(Vec3::new(0.0, 0.0, 5.0));
        let diagonal = fixture.resources.scene.bounds.diagonal();
        let attenuation = 1.0 / (1.0 + (5.0 / diagonal).powi(2));
        // Head-on: n·l = 1, n·h = 1, so diffuse 1 and specular Ks = 0.3.
        let rgb = shade(&fixture, &[lit_point(); 2], &[0.0, 0.0], &[1, 0], &[]);
        assert!(
            close(rgb[0], Vec3::splat(0.15 + attenuation * 1.3)),
            "{}",
            rgb[0]
        );
        assert!(close(rgb[1], Vec3::splat(0.15)), "{}", rgb[1]);
        // falloff 0: no attenuation.
        let rgb = shade(
            &fixture,
            &[lit_point()],
            &[0.0],
            &[1],
            &[HostValue::Float(0.15), HostValue::Float(0.0)],
        );
        assert!(close(rgb[0], Vec3::splat(1.45)), "{}", rgb[0]);
        // At 60 degrees from the normal, viewed head-on: diffuse cos 60 = 0.5, and
        // the half vector at 30 degrees gives cos(30)^32.
        let light = Vec3::new(5.0 * 3f32.sqrt() / 2.0, 0.0, 2.5);
        let fixture = self::fixture(light);
        let attenuation = 1.0 / (1.0 + (5.0 / diagonal).powi(2));
        let specular = 0.3 * (30f32.to_radians().cos()).powf(32.0);
        let rgb = shade(&fixture, &[lit_point()], &[0.0], &[1], &[]);
        assert!(
            close(rgb[0], Vec3::splat(0.15 + attenuation * (0.5 + specular))),
            "{}",
            rgb[0]
        );
    }

    #[test]
    fn colour_map_material_reflectivity_weight_and_misses() {
        let mut fixture = fixture(Vec3::new(0.0, 0.0, -5.0));
        fixture.set_shading(|shading| {
            shading
                .set_material(
                    "default",
                    &MaterialSpec {
                        kd: Some(crate::shading::ColorSpec::Rgb([1.0, 0.5, 0.0])),
                        reflectivity: Some(0.25),
                        ..Default::default()
                    },
                )
                .unwrap();
            shading.set_background([1.0, 1.0, 1.0]).unwrap();
        });
        let mut dim = lit_point();
        dim.scalar = 0.0; // black end of the grey map
        let mut weighted = lit_point();
        weighted.weight = Vec3::new(0.5, 1.0, 2.0);
        let miss = SurfaceRecord::miss(0, Vec3::new(0.5, 0.25, 0.0), 1);
        let rgb = shade(
            &fixture,
            &[lit_point(), dim, weighted, miss],
            &[0.0; 4],
            &[0; 4],
            &[],
        );
        let local = 0.15 * Vec3::new(1.0, 0.5, 0.0) * 0.75;
        assert!(close(rgb[0], local), "{}", rgb[0]);
        assert_eq!(rgb[1], Vec3::ZERO);
        assert!(
            close(rgb[2], local * Vec3::new(0.5, 1.0, 2.0)),
            "{}",
            rgb[2]
        );
        assert_eq!(rgb[3], Vec3::new(0.5, 0.25, 0.0));
    }

    /// The shading of one surface, written out per surface as the shader
    /// computed it before it shaded blocks of lanes: the reference its block
    /// arithmetic must match bit for bit.
    fn reference(fixture: &Fixture, s: &SurfaceRecord, occlusion: f32, mask: u32) -> Vec3 {
        let (ambient, falloff) = (0.2, 0.7);
        let shading = &fixture.resources.shading;
        let diagonal = fixture
            .uniforms
            .get("scene", "diagonal")
            .and_then(|d| d.as_f32())
            .unwrap();
        let inverse_diagonal = 1.0 / diagonal;
        let [low, high] = shading.scalar_range();
        let inverse_range = 1.0 / (high - low);
        if !s.hit {
            return shading.background() * s.weight;
        }
        let material = &shading.materials()[s.material as usize];
        let base = shading
            .colormap()
            .linear_at((s.scalar - low) * inverse_range)
            * material.kd;
        let open = 1.0 - occlusion.clamp(0.0, 1.0);
        let mut local = ambient * open * base;
        let sees_viewer = s.normal.dot(s.view) > 0.0;
        for (light_index, light) in shading.lights().iter().enumerate() {
            if mask & (1 << light_index) == 0 {
                continue;
            }
            let to_light = light.position - s.position;
            let distance = to_light.length();
            let direction = to_light / distance;
            let diffuse = s.normal.dot(direction);
            // Also false for NaN (a light exactly at the point).
            let in_front = diffuse > 0.0;
            if !in_front {
                continue;
            }
            let scaled = distance * inverse_diagonal;
            let attenuation = light.intensity / (1.0 + falloff * scaled * scaled);
            let specular = if sees_viewer {
                let half = (direction + s.view).normalize_or_zero();
                s.normal.dot(half).max(0.0).powf(material.ns)
            } else {
                0.0
            };
            local += attenuation * light.color * (base * diffuse + material.ks * specular);
        }
        local * (1.0 - material.reflectivity) * s.weight
    }

    #[test]
    fn blocks_of_lanes_shade_bit_for_bit_as_one_surface_at_a_time() {
        let lights = [
            Vec3::new(0.0, 0.0, 5.0),
            Vec3::new(-3.0, 2.0, 1.0),
            // Exactly at a surface below: distance 0, a NaN direction.
            Vec3::new(0.5, 0.5, 0.0),
            // Far beyond the scene: strongly attenuated.
            Vec3::new(40.0, 30.0, 20.0),
        ];
        let mut fixture = fixture(lights[0]);
        fixture.set_shading(|shading| {
            let mut all: Vec<PointLight> =
                lights.iter().map(|&p| PointLight::new(p, 0.7)).collect();
            all[1].color = Vec3::new(1.0, 0.5, 0.25);
            shading.set_lights(all).unwrap();
            shading.set_colormap("viridis").unwrap();
            shading.set_scalar_range(-1.0, 2.0).unwrap();
            shading
                .set_material(
                    "default",
                    &MaterialSpec {
                        ns: Some(7.5),
                        reflectivity: Some(0.3),
                        ..Default::default()
                    },
                )
                .unwrap();
        });
        let mut state = 0x9e37_79b9u32;
        let mut random = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32
        };
        let unit = |random: &mut dyn FnMut() -> f32| {
            Vec3::new(random() - 0.5, random() - 0.5, random() - 0.5).normalize_or_zero()
        };
        let (mut surfaces, mut occlusion, mut visible) = (Vec::new(), Vec::new(), Vec::new());
        // Several blocks and a partial one.
        for i in 0..300u32 {
            let mut s = lit_point();
            s.position = 3.0 * unit(&mut random);
            s.normal = unit(&mut random);
            s.view = unit(&mut random);
            s.scalar = 4.0 * random() - 1.5;
            s.weight = Vec3::new(random(), random(), 1.0);
            s.hit = i % 5 != 3;
            s.sample = i;
            match i % 7 {
                // A half vector of length 0: the view opposite the light.
                0 => s.view = -(lights[1] - s.position).normalize(),
                1 => s.position = lights[2],
                2 => s.normal = s.view,
                _ => {}
            }
            surfaces.push(s);
            occlusion.push(match i % 11 {
                0 => f32::NAN,
                1 => -0.5,
                2 => 1.5,
                _ => random(),
            });
            visible.push(if i % 3 == 0 { u32::MAX } else { i % 16 });
        }
        let named = [HostValue::Float(0.2), HostValue::Float(0.7)];
        let rgb = shade(&fixture, &surfaces, &occlusion, &visible, &named);
        for (i, s) in surfaces.iter().enumerate() {
            let expected = reference(&fixture, s, occlusion[i], visible[i]);
            assert_eq!(
                rgb[i].to_array().map(f32::to_bits),
                expected.to_array().map(f32::to_bits),
                "surface {i}: {} != {expected}",
                rgb[i]
            );
        }
    }

    #[test]
    fn unknown_material_is_an_error() {
        let fixture = fixture(Vec3::Z);
        let mut surface = lit_point();
        surface.material = 3;
        let surfaces = fixture.surfaces(&[surface]);
        let (occlusion, visible) = (Column::F32(vec![0.0]), Column::U32(vec![1]));
        let error = fixture
            .run(
                "shader",
                &[],
                0,
                &[surfaces.view(), occlusion.view(), visible.view()],
            )
            .unwrap_err();
        assert!(error.message.contains("material 3"), "{error}");
    }
}
