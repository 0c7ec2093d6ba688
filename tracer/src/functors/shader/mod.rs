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

use crate::functors::{named_f32, scene_diagonal, SurfaceColumns};
use crate::scene::TraceResources;
use crate::shading::MAX_LIGHTS;
use dpp_runtime::{
    ArrayParam, CallContext, Column, ColumnView, ElemType, Functor, FunctorError, FunctorKind,
    HostType, HostValue, NamedParam, RecordId, Signature, TypePattern,
};

pub struct Shader {
    signature: Signature,
}

impl Shader {
    pub fn new(surface: RecordId) -> Shader {
        Shader {
            signature: Signature {
                name: "shader",
                kind: FunctorKind::Map,
                inputs: vec![
                    ArrayParam {
                        name: "surf",
                        ty: TypePattern::Exact(ElemType::Record(surface)),
                    },
                    ArrayParam {
                        name: "occlusion",
                        ty: TypePattern::Exact(ElemType::F32),
                    },
                    ArrayParam {
                        name: "visible",
                        ty: TypePattern::Exact(ElemType::U32),
                    },
                ],
                outputs: vec![ArrayParam {
                    name: "rgb",
                    ty: TypePattern::Exact(ElemType::Vec3),
                }],
                named: vec![
                    NamedParam {
                        name: "ambient",
                        ty: HostType::Float,
                        default: Some(HostValue::Float(0.15)),
                        doc: "strength of the ambient term, scaled by 1 - occlusion",
                    },
                    NamedParam {
                        name: "falloff",
                        ty: HostType::Float,
                        default: Some(HostValue::Float(1.0)),
                        doc: "k in the light attenuation intensity / (1 + k (d / scene.diagonal)^2); 0 turns it off",
                    },
                ],
                doc: "Blinn-Phong: colour-mapped scalar times Kd, ambient scaled by 1 - occlusion, diffuse and specular from the visible lights; times (1 - reflectivity) and the ray weight (miss: background)",
            },
        }
    }
}

impl Functor for Shader {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    fn run_cpu(
        &self,
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
        let occlusion = inputs[1].as_f32();
        let visible = inputs[2].as_u32();
        let colors = outputs[0].as_vec3_mut();
        colors.reserve(surfaces.len());
        for index in 0..surfaces.len() {
            let surface = surfaces.get(index);
            if !surface.hit {
                colors.push(background * surface.weight);
                continue;
            }
            let material = materials.get(surface.material as usize).ok_or_else(|| {
                FunctorError(format!(
                    "shader: surface has material {}, but the scene has {} materials",
                    surface.material,
                    materials.len()
                ))
            })?;
            let base = colormap.linear_at((surface.scalar - low) * inverse_range) * material.kd;
            let open = 1.0 - occlusion[index].clamp(0.0, 1.0);
            let mut local = ambient * open * base;
            let mask = visible[index];
            let normal = surface.normal;
            let sees_viewer = normal.dot(surface.view) > 0.0;
            for (light_index, light) in lights.iter().enumerate() {
                if mask & (1 << light_index) == 0 {
                    continue;
                }
                let to_light = light.position - surface.position;
                let distance = to_light.length();
                let direction = to_light / distance;
                let diffuse = normal.dot(direction);
                // Also false for NaN (a light exactly at the point).
                let in_front = diffuse > 0.0;
                if !in_front {
                    continue;
                }
                let scaled = distance * inverse_diagonal;
                let attenuation = light.intensity / (1.0 + falloff * scaled * scaled);
                let specular = if sees_viewer {
                    let half = (direction + surface.view).normalize_or_zero();
                    normal.dot(half).max(0.0).powf(material.ns)
                } else {
                    0.0
                };
                local += attenuation * light.color * (base * diffuse + material.ks * specular);
            }
            colors.push(local * (1.0 - material.reflectivity) * surface.weight);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::Fixture;
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
            position: Vec3::ZERO,
            normal: Vec3::Z,
            view: Vec3::Z,
            scalar: 1.0,
            material: 0,
            hit: true,
            sample: 0,
            weight: Vec3::ONE,
            depth: 0,
            geometric: Vec3::Z,
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
        assert!(error.0.contains("material 3"), "{error}");
    }
}
